#!/usr/bin/env bash
# UDP listener throughput of the transport, a benchmark (never part of the test suite):
# a sender pushes HEARTBEATs, one per datagram, at a fixed rate to a `udpin` connection on
# loopback (crates/mavstack-transport/examples/udp_throughput.rs, release build), through
# the blocking API and through the async API on one thread.
#
#   scripts/bench-throughput.sh [RATE [SECONDS]]     default 300000 frames/s for 3 s
#
# Prints one line per API (sent, received, each side's rate, loss) and exits non-zero if a
# paced run lost frames. RATE 0 sends as fast as the sender can and reports the loss.
# Timing depends on the machine's other load: note it with the figures.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
rate="${1:-300000}"
seconds="${2:-3}"
cd "$root"
cargo build --release --locked -q -p mavstack-transport --example udp_throughput
bin="$root/target/release/examples/udp_throughput"
echo "bench-throughput: $(date -u '+%Y-%m-%d %H:%M UTC'), $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)"
lost_any=0
for api in blocking one-thread; do
    line=$("$bin" "$api" "$rate" "$seconds")
    echo "$line"
    lost=$(sed -n 's/.*lost \([0-9]*\).*/\1/p' <<<"$line")
    if [ "$rate" != 0 ] && [ "${lost:-1}" != 0 ]; then
        lost_any=1
    fi
done
[ "$lost_any" -eq 0 ] || { echo "bench-throughput: frames lost at $rate frames/s" >&2; exit 1; }
