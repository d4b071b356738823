#!/usr/bin/env bash
# The flight-stack scenarios (tests-interop/flight_stacks.py) against ArduPilot copter SITL, PX4
# SITL (SIH) and `mavstack vehicle` in both flavours, then one table of the results.
#
# The flight stacks are not built here (nor is any of their code in this repository): give the
# binaries you built in the environment; a target whose variable is unset is skipped and said so.
#   ARDUPILOT_SITL      ArduPilot's SITL binary (build/sitl/bin/arducopter)
#   ARDUPILOT_DEFAULTS  its defaults file (Tools/autotest/default_params/copter.parm)
#   PX4_SITL_DIR        PX4's build directory (build/px4_sitl_default: bin/px4, etc/)
#   MAVSTACK            the mavstack binary (default: target/release/mavstack, built if missing)
#   FLIGHT              the `flight` example (default: target/release/examples/flight, likewise)
#   SIMS                the simulator's flavours to run (default: "ardupilot px4"; "": none)
#   ONLY                scenarios to run (comma-separated; default: all; `none`: none, e.g. with BENCH)
#   BENCH               1: also tests-interop/flight_bench.py against each target (times beside
#                       MAVProxy and MAVSDK, clean and lossy UDP): target/flight-stacks/bench.md
#   BENCH_TOOLS         the bench's tools (default mavstack,mavproxy,mavsdk); BENCH_LINKS (clean,lossy)
# ArduPilot listens on tcp:127.0.0.1:5760 (SERIAL0) and sends SERIAL1 to udp 127.0.0.1:14561 (the
# bench's UDP link); PX4 sends to udp 127.0.0.1:14550; the simulator runs as `mavstack vehicle
# udpout:127.0.0.1:14550`. Results: target/flight-stacks/.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
py="${MAVSTACK_PYTHON:-$(scripts/setup-peers.sh)}"
bin="${MAVSTACK:-$root/target/release/mavstack}"
if [ ! -x "$bin" ]; then
    cargo build --release --locked -q -p mavstack-cli
fi
bin="$(realpath "$bin")"
flight="${FLIGHT:-$root/target/release/examples/flight}"
if [ ! -x "$flight" ]; then
    cargo build --release --locked -q -p mavstack --features services --example flight
fi
out="$root/target/flight-stacks"
rm -rf "$out"
mkdir -p "$out/bench"
only=()
if [ -n "${ONLY:-}" ]; then
    only=(--only "$ONLY")
fi
# Each target runs from DIR/start.sh (made by make_starter): it ends the instance before (the
# session whose leader's pid is in DIR/pid) and starts the target in a session of its own, under
# a shell that waits for it (ArduPilot SITL exits when its parent does). The restart scenario
# runs it again while a ground station is connected. STARTER=NAME writes DIR/NAME instead
# (the simulator's start-camera.sh: the same vehicle with its camera, for the camera scenario).
starters=()
make_starter() {
    local dir="$1" file="$1/${STARTER:-start.sh}"
    shift
    {
        echo '#!/usr/bin/env bash'
        echo "dir=$(printf %q "$dir")"
        echo 'if [ -s "$dir/pid" ]; then kill -- "-$(cat "$dir/pid")" 2>/dev/null || true; sleep 2; fi'
        echo 'cd "$dir"'
        printf 'setsid bash -c %q wrapper' '"$@"; exit $?'
        printf ' %q' "$@"
        echo ' </dev/null >>"$dir/run.log" 2>&1 &'
        echo 'echo $! >"$dir/pid"'
    } >"$file"
    chmod +x "$file"
    starters+=("$dir")
}
stop_all() {
    for d in "${starters[@]}"; do
        if [ -s "$d/pid" ]; then
            kill -- "-$(cat "$d/pid")" 2>/dev/null || true
            rm -f "$d/pid"
        fi
    done
    starters=()
}
trap stop_all EXIT

# Waits until a HEARTBEAT arrives on CONN (pymavlink), up to 60 s.
wait_heartbeat() {
    "$py" - "$1" <<'PY'
import sys
from pymavlink import mavutil
m = mavutil.mavlink_connection(sys.argv[1])
hb = m.wait_heartbeat(timeout=60)
sys.exit(0 if hb else 1)
PY
}

scenarios() {
    local name="$1" conn="$2" dir="$3"
    shift 3
    [ "${ONLY:-}" = none ] && return 0
    "$py" tests-interop/flight_stacks.py --mavstack "$bin" --flight "$flight" --name "$name" \
        --conn "$conn" --restart "$dir/start.sh" --out "$out/$name.json" "${only[@]}" "$@" || true
}

# The bench against a vehicle sending UDP to 127.0.0.1:PORT (BENCH=1).
bench() {
    local name="$1" port="$2"
    [ "${BENCH:-}" = 1 ] || return 0
    "$py" tests-interop/flight_bench.py --mavstack "$bin" --name "$name" --port "$port" \
        --tools "${BENCH_TOOLS:-mavstack,mavproxy,mavsdk}" --links "${BENCH_LINKS:-clean,lossy}" \
        --out "$out/bench/$name.json" || true
}

if [ -n "${ARDUPILOT_SITL:-}" ]; then
    dir="$out/ardupilot-run"
    mkdir -p "$dir"
    # SERIAL0 on TCP 5760, listening at once (--serial0 tcp:0 does not wait for a client).
    make_starter "$dir" "$ARDUPILOT_SITL" --model quad \
        --defaults "${ARDUPILOT_DEFAULTS:?ARDUPILOT_DEFAULTS: the copter defaults file}" \
        --serial0 tcp:0 --serial1 udpclient:127.0.0.1:14561 -I0 --home -35.363261,149.165230,584,353
    "$dir/start.sh"
    for _ in $(seq 100); do (exec 3<>/dev/tcp/127.0.0.1/5760) 2>/dev/null && break; sleep 0.2; done
    wait_heartbeat tcp:127.0.0.1:5760
    # SERIAL1 (UDP to 14561) is the second link of the signed_router scenario.
    scenarios ardupilot tcp:127.0.0.1:5760 "$dir" --signed-link udpin:127.0.0.1:14561
    bench ardupilot 14561
    stop_all
    sleep 1
else
    echo "ardupilot: skipped (ARDUPILOT_SITL is not set)" | tee "$out/ardupilot.skipped"
fi

if [ -n "${PX4_SITL_DIR:-}" ]; then
    dir="$out/px4-run"
    mkdir -p "$dir"
    make_starter "$dir" env PX4_SIMULATOR=sihsim PX4_SIM_MODEL=sihsim_quadx PX4_SYS_AUTOSTART=10040 \
        "$PX4_SITL_DIR/bin/px4" -d -i 0 -w "$dir" "$PX4_SITL_DIR/etc"
    "$dir/start.sh"
    wait_heartbeat udpin:127.0.0.1:14550
    scenarios px4 udpin:127.0.0.1:14550 "$dir"
    bench px4 14550
    stop_all
    sleep 1
else
    echo "px4: skipped (PX4_SITL_DIR is not set)" | tee "$out/px4.skipped"
fi

for flavour in ${SIMS-ardupilot px4}; do
    # The simulator as each flavour, refusing PROTOCOL_VERSION and streaming nothing unasked
    # as ArduPilot does for that flavour, with an estimator that settles for 5 s as the flight
    # stacks' do.
    extra=()
    second=()
    if [ "$flavour" = ardupilot ]; then
        # A second link as ArduPilot's SERIAL1, for signed_router.
        extra=(udpout:127.0.0.1:14562 --protocol-version refuse --start-mavlink2 --streams-on-request)
        second=(--signed-link udpin:127.0.0.1:14562)
    fi
    dir="$out/sim-$flavour-run"
    mkdir -p "$dir/camera"
    make_starter "$dir" "$bin" vehicle udpout:127.0.0.1:14550 --autopilot "$flavour" \
        --estimator-settle 5 --secure "${extra[@]}"
    # The same with the simulated camera (component 100), for the camera scenario only: the
    # other scenarios' peers take the first HEARTBEAT heard (pymavlink's wait_heartbeat), which
    # could be the camera's.
    STARTER=start-camera.sh make_starter "$dir" "$bin" vehicle udpout:127.0.0.1:14550 \
        --autopilot "$flavour" --estimator-settle 5 --secure --camera "$dir/camera" "${extra[@]}"
    "$dir/start.sh"
    scenarios "sim-$flavour" udpin:127.0.0.1:14550 "$dir" "${second[@]}" \
        --camera-restart "$dir/start-camera.sh"
    bench "sim-$flavour" 14550
    stop_all
done

if [ "${BENCH:-}" = 1 ] && ls "$out"/bench/*.json >/dev/null 2>&1; then
    "$py" tests-interop/flight_bench.py --combine "$out"/bench/*.json --md "$out/bench.md"
fi

"$py" - "$out" <<'PY'
import glob, json, os, sys
rows = {}
targets = []
for path in sorted(glob.glob(os.path.join(sys.argv[1], "*.json"))):
    for r in json.load(open(path)):
        if r["target"] not in targets:
            targets.append(r["target"])
        rows.setdefault(r["scenario"], {})[r["target"]] = r
print("| scenario | " + " | ".join(targets) + " |")
print("| --- |" + " --- |" * len(targets))
for scenario, by in rows.items():
    cells = []
    for t in targets:
        r = by.get(t)
        cells.append("—" if r is None else "%s: %s" % (r["status"], r["detail"].replace("|", "/")))
    print("| %s | %s |" % (scenario, " | ".join(cells)))
PY
