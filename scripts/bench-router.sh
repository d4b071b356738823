#!/usr/bin/env bash
# Routers side by side on loopback UDP, in one run of a router benchmark harness: a sender
# fans a telemetry mix out to two receivers through each router (rate ladder, CPU per frame,
# added latency at 1 k frames/s). The harness is not part of this repository: $ROUTER_BENCH
# names its router_bench.py, a Python program run with the test venv's python that takes
# `--router 'NAME=COMMAND with {in} {out1} {out2}'`, `--preset mavproxy|mavrouter|mavlink-routerd`
# (with `--python`, `--mavrouter`, `--mavlink-routerd` naming the programs), `--ref NAME`,
# `--out FILE.json`, `--md FILE.md` and `--quick`. Measured:
#   mavstack         mavstack router, plain links (one frame per datagram, like every router)
#   mavstack-pack    the same with pack=true (frames already waiting for a peer share a datagram)
#   mavstack-v1      pack=true, and output 1 is a version=1 link: every frame converted to MAVLink 1
#   mavstack-signed  pack=true, the input trusted=true and output 1 a key= link: every frame signed
#   mavproxy         MAVProxy 1.8.75 (PyPI, .venv) --out
#   mavrouter        mavrouter 0.1.6 (crates.io, installed into $ROUTER_TOOLS)
#   mavlink-routerd  when MAVLINK_ROUTERD names a binary (built by hand: not on a registry)
# The harness counts a frame delivered only when its bytes are identical to what was sent;
# the converting and signing variants change the bytes on output 1 by design, so
# scripts/router_bench_summary.py also counts frames that arrived converted (their
# correctness is checked by tests-interop/router_interop.py against pymavlink).
#
#   ROUTER_BENCH=/path/to/router_bench.py bash scripts/bench-router.sh           # 3 rounds (about 25 minutes)
#   ROUTER_BENCH=/path/to/router_bench.py bash scripts/bench-router.sh --quick   # 1 round of 1 s steps (about 6 minutes)
# Results: target/router-bench/{results.json,results.md}.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bench="${ROUTER_BENCH:-}"
[ -f "$bench" ] || { echo "bench-router: set ROUTER_BENCH to the harness's router_bench.py (not part of this repository)" >&2; exit 1; }
py="$(scripts/setup-peers.sh)"
cargo build --release --locked -p mavstack-cli >&2
tools="${ROUTER_TOOLS:-$root/target/router-tools}"
if [ ! -x "$tools/bin/mavrouter" ]; then
    cargo install mavrouter --version 0.1.6 --locked --root "$tools" >&2
fi
out="$root/target/router-bench"
mkdir -p "$out"
bin="$root/target/release/mavstack"
key="$(printf '42%.0s' $(seq 32))"
in='udpin:127.0.0.1:{in}'
o1='udpout:127.0.0.1:{out1}'
o2='udpout:127.0.0.1:{out2}'
args=(
    --router "mavstack=$bin router $in $o1 $o2"
    --router "mavstack-pack=$bin router $in $o1?pack=true $o2?pack=true"
    --router "mavstack-v1=$bin router $in '$o1?version=1&pack=true' $o2?pack=true"
    --router "mavstack-signed=$bin router '$in?trusted=true' '$o1?key=$key&pack=true' $o2?pack=true"
    --preset mavproxy --python "$root/.venv/bin/python"
    --preset mavrouter --mavrouter "$tools/bin/mavrouter"
)
if [ -n "${MAVLINK_ROUTERD:-}" ]; then
    args+=(--preset mavlink-routerd --mavlink-routerd "$MAVLINK_ROUTERD" --ref mavlink-routerd)
else
    args+=(--ref mavrouter)
fi
"$py" "$bench" "${args[@]}" --out "$out/results.json" --md "$out/results.md" "$@"
"$py" scripts/router_bench_summary.py "$out/results.json" | tee -a "$out/results.md"
