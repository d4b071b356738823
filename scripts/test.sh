#!/usr/bin/env bash
# The whole test suite, exactly what CI runs (.ci/run calls this script):
# peers, formatting, lints, every test and doctest, every fuzz target for a few seconds, docs,
# and a small feature matrix.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
last_step=$SECONDS
step() {
    printf '\n== %s   (previous step: %d s; %d s in all)\n' "$*" $((SECONDS - last_step)) "$SECONDS"
    last_step=$SECONDS
}
# A clean CI checkout builds everything once: incremental compilation would only add work.
if [ "${CI:-}" = "true" ]; then
    export CARGO_INCREMENTAL=0
fi

step "system packages (chromium, chromium-driver, fonts-dejavu-core, mosquitto, openssl, libssl-dev, nodejs, g++)"
bash scripts/setup-system.sh

step "peers (pymavlink 2.4.50 in .venv)"
MAVSTACK_PYTHON="$(scripts/setup-peers.sh)"
export MAVSTACK_PYTHON
echo "python: $MAVSTACK_PYTHON"

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (all targets, all features, -D warnings)"
cargo clippy --workspace --all-targets --all-features --locked -- -D warnings

# Some builds run in the background while steps that mostly wait (on simulated vehicles flying
# in real time, on the peers) run, so the compiler takes the idle processor: the wheel and the
# fuzz targets in target directories of their own (cargo locks a target directory for a whole
# `cargo test`, running included), the feature matrix in target/debug once the tests are done,
# the fleet test's program once the wheel is built.
# Each writes its log under target/; its step awaits it and shows the log on a failure. A run
# that stops early stops them too.
trap 'kill $(jobs -p) 2>/dev/null || true' EXIT
# await NAME PID LOG: waits for a background build; on a failure shows its log and stops.
await() {
    if ! wait "$2"; then
        cat "$3" >&2
        echo "$1 failed ($3 above)" >&2
        exit 1
    fi
}

# The Python package's wheel (a release build), awaited before the Python tests.
rm -f target/wheels/mavstack-*.whl
CARGO_TARGET_DIR="$root/target/wheel-build" "$(dirname "$MAVSTACK_PYTHON")/maturin" build \
    --release --locked -q -m crates/mavstack-python/Cargo.toml -o target/wheels \
    >target/wheel-build.log 2>&1 &
wheel_build=$!

step "cargo test: build (workspace, all features)"
cargo test --workspace --all-features --locked --no-run

# The fuzz targets (nightly, in fuzz/target) are built while the tests run.
FUZZ_SANITIZER=none FUZZ_BUILD_ONLY=1 bash scripts/fuzz.sh 1 >target/fuzz-build.log 2>&1 &
fuzz_build=$!

step "cargo test: run (workspace, all features)"
# Six test threads on two cores: most tests wait on processes and sockets (simulated vehicles
# flying in real time, the peers), not on the processor (the command's test binary, with the
# MAVSDK sessions: 320 s with three threads, 188 s with six, one core busy on average); counts,
# never timings, are what the tests check, so a busier machine only makes them slower.
cargo test --workspace --all-features --locked --no-fail-fast -- --test-threads=6

# The feature matrix is type-checked (no codegen: what a feature combination can break is
# whether it compiles) while the Python package is tested, in target/debug, where clippy has
# already checked the dependencies (the examples' builds after it wait for its lock).
(
    cargo check -p mavstack --locked
    cargo check -p mavstack-core --no-default-features --locked
    cargo check -p mavstack-dialects --no-default-features --features minimal --locked
    cargo check -p mavstack-bridge --no-default-features --features zenoh --locked
    cargo check -p mavstack-bridge --locked
    cargo test -p mavstack-dialects --no-default-features --features common --locked --doc
) >target/feature-matrix.log 2>&1 &
matrix=$!

step "Python package: maturin builds the wheel, installed in .venv, pytest"
# The same build as `pip install crates/mavstack-python` (release, abi3), then the package's
# tests against pymavlink, pyarrow, polars and pandas in the test venv.
await "the Python wheel's build" "$wheel_build" target/wheel-build.log
"$MAVSTACK_PYTHON" -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps \
    target/wheels/mavstack-*-abi3-*.whl
# The fleet test's program is built meanwhile, in the wheel's target directory: the release
# builds of the dependencies they share are reused.
CARGO_TARGET_DIR="$root/target/wheel-build" cargo build --release --locked -q -p mavstack-bridge \
    --example fleet >target/fleet-build.log 2>&1 &
fleet_build=$!
# Four pytest workers (pytest-xdist): the tests wait on simulated vehicles and sockets far more
# than they compute (about 6 minutes one at a time, 2 with four workers).
(cd crates/mavstack-python && "$MAVSTACK_PYTHON" -m pytest -q -p no:cacheprovider -n 4 tests)
# The bench harness's step timing: a tool's own TimeoutError is a failure, not the caller's timeout.
"$MAVSTACK_PYTHON" -m pytest -q -p no:cacheprovider tests-interop/test_bench_ops.py
# Types: the stubs against the installed extension (stubtest: every module of the package,
# mavstack.aio and the generated mavstack.messages included; stubtest-allowlist.txt says why
# each entry is there), then the typed examples under mypy --strict and pyright in strict mode
# (examples/pyrightconfig.json; pyright's wheel runs the system's node and, told so, asks PyPI
# for no newer version of itself). About 10 s.
(cd crates/mavstack-python && "$MAVSTACK_PYTHON" -m mypy.stubtest mavstack --allowlist stubtest-allowlist.txt)
(cd crates/mavstack-python/examples && "$MAVSTACK_PYTHON" -m mypy --strict . &&
    PYRIGHT_PYTHON_IGNORE_WARNINGS=1 "$(dirname "$MAVSTACK_PYTHON")/pyright" --pythonpath "$MAVSTACK_PYTHON" .)
# Damaged logs: `mavstack decode` and the package return exactly the frames pymavlink's reader
# returns (order, timestamps), once with bit flips of every header field and unknown ids, once
# with inserted garbage and flipped timestamps as well; raw streams lose none pymavlink finds.
"$MAVSTACK_PYTHON" tests-interop/tlog_damage.py --mavstack target/debug/mavstack --python --records 50000 \
    --damage payload,checksum,length_down,length_up,incompat,msgid0,msgid1,msgid2,magic,header,unknown_id
"$MAVSTACK_PYTHON" tests-interop/tlog_damage.py --mavstack target/debug/mavstack --python --records 50000

step "examples, against the in-process simulated vehicle"
# Each example runs and its output must show what it is for.
example() {
    local name="$1"
    shift
    local out
    # Built as the test step built everything (workspace, all features), so nothing is built
    # again but the program itself where the tests built it as a test (vehicle_in_test).
    cargo build -q --locked --workspace --all-features --example "$name"
    out="$("target/debug/examples/$name" ${ARGS:-})"
    for want in "$@"; do
        if ! grep -qF "$want" <<<"$out"; then
            printf '%s example: no "%s" in its output:\n%s\n' "$name" "$want" "$out" >&2
            exit 1
        fi
    done
}
ARGS=4 example ground_station "ATTITUDE roll" "GLOBAL_POSITION_INT -35.36" \
    "HEARTBEAT MAV_TYPE_QUADROTOR MAV_AUTOPILOT_ARDUPILOTMEGA" "link vehicle (2)"
example mission_upload "uploaded 6 items from the built-in plan" "read back 6 items: identical"
example companion "companion ← ATTITUDE from 1/1" "ground station ← MAV_SYS_ID = 1 (through the companion)" \
    "companion link fc" "companion link gcs"
example vehicle_in_test "RTL_ALT set to 3000, arming MAV_RESULT_ACCEPTED"
example offboard "px4 simulator found" "took off: " "offboard: 3 m/s north" \
    "now Hold" "landed and disarmed"

step "fleet test: 1,000 vehicles through their bridges and mosquitto (about 60 s)"
# tests-interop/fleet_test.py --check: every command answered (with telemetry and without),
# nothing lost on the control lane and under 1 % of telemetry while the broker is up, traffic
# again after the broker is killed and restarted. Counts are checked, never timings.
await "the fleet program's build" "$fleet_build" target/fleet-build.log
"$MAVSTACK_PYTHON" tests-interop/fleet_test.py --fleet target/wheel-build/release/examples/fleet --count 1000 \
    --out target/fleet-results.json --check | tail -12

step "fuzz: every target for ${FUZZ_SECONDS:-3} s on nightly (a crash fails, kept as a regression seed)"
# Without the address sanitizer: quicker to build and to run, and the code under test is safe
# Rust (long campaigns by hand use it: scripts/fuzz.sh 480).
# Built while the tests ran; `cargo fuzz build` again here finds nothing to do.
await "the fuzz targets' build" "$fuzz_build" target/fuzz-build.log
grep '^fuzz.sh:' target/fuzz-build.log
FUZZ_SANITIZER=none FUZZ_JOBS=2 bash scripts/fuzz.sh "${FUZZ_SECONDS:-3}"

step "feature matrix (checked while the Python package was tested)"
await "the feature matrix" "$matrix" target/feature-matrix.log
grep -v '^ *\(Checking\|Compiling\)' target/feature-matrix.log

step "cargo doc (-D warnings)"
# The generated dialects are documented with their default set (ardupilotmega and what it
# includes; this also checks that set builds): every dialect of `all` would triple the time.
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --all-features --locked --exclude mavstack-dialects
RUSTDOCFLAGS="-D warnings" cargo doc -p mavstack-dialects --no-deps --locked

step "done: every check passed"
