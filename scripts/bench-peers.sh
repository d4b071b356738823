#!/usr/bin/env bash
# Side-by-side parse throughput on one corpus, in one run: mavstack, the MAVLink C library
# (mavlink_parse_char + generated decode, gcc -O2) and rust-mavlink 0.21 (typed decode),
# all on pymavlink's 50 MB mixed corpus (ardupilotmega; v1, v2, signed, noise).
# Needs ../shared/peers (set up here: pymavlink, C library, rust-mavlink bench; minutes the
# first time). Prints each peer's line and the ratios: the parse loop as each program times
# itself, then whole processes timed from outside. Never part of the test suite.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
peers="$root/../shared/peers"
[ -d "$peers" ] || { echo "bench-peers: $peers not found" >&2; exit 1; }
corpus="${CORPUS:-/tmp/mavstack-bench/mixed50}"
runs="${RUNS:-5}"
"$peers/setup.sh" >/dev/null
# shellcheck disable=SC1091
source "${PEERS_BUILD:-/tmp/peers-build}/env.sh"
mkdir -p "$(dirname "$corpus")"
if [ ! -f "$corpus.bin" ]; then
    "$PEERS_PY" "$peers/gen_corpus.py" --frames 100000000 --max-bytes 52428800 --seed 1 --no-json --out "$corpus" >/dev/null
fi
(cd "$root" && cargo build --release --locked -q -p mavstack-cli &&
    cargo build --release --locked -q -p mavstack-dialects --example encode_bench)
ours="$root/target/release/mavstack"
ours_encode="$root/target/release/examples/encode_bench"

best() { # best (lowest) seconds of $runs runs of a command printing "... seconds=S" on stdout or stderr
    local s b=""
    for _ in $(seq "$runs"); do
        s=$("$@" 2>&1 >/dev/null | grep -o 'seconds=[0-9.]*' | tail -1 | cut -d= -f2)
        [ -z "$s" ] && s=$("$@" 2>/dev/null | grep -o 'seconds=[0-9.]*' | tail -1 | cut -d= -f2)
        if [ -z "$b" ] || awk "BEGIN{exit !($s < $b)}"; then b=$s; fi
    done
    echo "$b"
}
frames=$("$ours" decode --count --dialect ardupilotmega "$corpus.bin" | sed 's/.*"frames":\([0-9]*\).*/\1/')
t_ours=$(best "$ours" decode --count --time --dialect ardupilotmega "$corpus.bin")
t_c=$(best "$PEERS_C_BENCH" "$corpus.bin" --decode)
t_rust=$(best "$PEERS_RUST_BENCH" "$corpus.bin")
key=000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f
t_ours_key=$(best "$ours" decode --count --time --key "$key" --dialect ardupilotmega "$corpus.bin")
t_c_key=$(best "$PEERS_C_BENCH" "$corpus.bin" --decode --key "$key" --accept-unsigned)
n_enc="${ENCODE_FRAMES:-10000000}"
n_sig=$((n_enc / 4))
e_ours=$(best "$ours_encode" "$n_enc")
e_c=$(best "$PEERS_C_BENCH" --encode "$n_enc")
e_rust=$(best "$PEERS_RUST_BENCH" --encode "$n_enc")
es_ours=$(best "$ours_encode" "$n_sig" --sign)
es_c=$(best "$PEERS_C_BENCH" --encode "$n_sig" --sign)
awk -v n="$n_enc" -v ns="$n_sig" -v o="$e_ours" -v c="$e_c" -v r="$e_rust" -v so="$es_ours" -v sc="$es_c" 'BEGIN {
    printf "encode: %d frames (HEARTBEAT, ATTITUDE, GLOBAL_POSITION_INT in turn; MAVLink 2)\n", n
    printf "%-44s %8.4f s %7.2f M frames/s\n", "mavstack (emit_message)", o, n/o/1e6
    printf "%-44s %8.4f s %7.2f M frames/s\n", "C library (pack_chan + msg_to_send_buffer)", c, n/c/1e6
    printf "%-44s %8.4f s %7.2f M frames/s\n", "rust-mavlink 0.21 (write_v2_msg)", r, n/r/1e6
    printf "%-44s %8.4f s (%d frames)\n", "mavstack signed", so, ns
    printf "%-44s %8.4f s (%d frames)\n", "C library signed", sc, ns
    printf "encode ratios: mavstack/C %.2fx, mavstack/rust-mavlink %.2fx, signed mavstack/C %.2fx\n", c/o, r/o, sc/so
}'
awk -v f="$frames" -v o="$t_ours" -v c="$t_c" -v r="$t_rust" -v ok="$t_ours_key" -v ck="$t_c_key" 'BEGIN {
    printf "corpus: %d frames (best of '"$runs"' runs, parse loop only)\n", f
    printf "%-44s %8.4f s %7.2f M frames/s\n", "mavstack (parse+validate+typed decode)", o, f/o/1e6
    printf "%-44s %8.4f s %7.2f M frames/s\n", "C library (mavlink_parse_char + decode)", c, f/c/1e6
    printf "%-44s %8.4f s %7.2f M frames/s\n", "rust-mavlink 0.21 (read_any_message)", r, f/r/1e6
    printf "%-44s %8.4f s\n", "mavstack with --key (verify signed frames)", ok
    printf "%-44s %8.4f s\n", "C library with --key", ck
    printf "ratios: mavstack/C %.2fx, mavstack/rust-mavlink %.2fx, with signing mavstack/C %.2fx\n", c/o, r/o, ck/ok
}'

# Whole processes, timed from outside (start, read the file, parse, validate, decode, exit):
# what a user waits for. One warm-up run each, then the median of $runs.
whole() { # median wall-clock seconds of $runs runs of a command (after one warm-up)
    local t0 t1 all=()
    "$@" >/dev/null 2>&1
    for _ in $(seq "$runs"); do
        t0=$(date +%s%N)
        "$@" >/dev/null 2>&1
        t1=$(date +%s%N)
        all+=("$(awk -v a="$t0" -v b="$t1" 'BEGIN{printf "%.6f", (b-a)/1e9}')")
    done
    printf '%s\n' "${all[@]}" | sort -n | awk '{v[NR]=$1} END{print v[int((NR+1)/2)]}'
}
w_ours=$(whole "$ours" decode --count --dialect ardupilotmega "$corpus.bin")
w_c=$(whole "$PEERS_C_BENCH" "$corpus.bin" --decode)
w_rust=$(whole "$PEERS_RUST_BENCH" "$corpus.bin")
awk -v o="$w_ours" -v c="$w_c" -v r="$w_rust" -v mb="$(stat -c %s "$corpus.bin")" 'BEGIN {
    printf "whole process, %.1f MB (median of '"$runs"' after a warm-up, wall clock)\n", mb/1e6
    printf "%-44s %8.4f s\n", "mavstack decode --count", o
    printf "%-44s %8.4f s\n", "C library bench (parse + decode)", c
    printf "%-44s %8.4f s\n", "rust-mavlink 0.21 bench", r
    printf "whole-process ratios: mavstack/C %.2fx, mavstack/rust-mavlink %.2fx\n", c/o, r/o
}'
