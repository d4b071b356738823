#!/usr/bin/env bash
# Runs the fuzz targets (fuzz/fuzz_targets) on nightly with cargo-fuzz.
#
#   scripts/fuzz.sh SECONDS [TARGET...]     every target (or the ones named), SECONDS each
#
# - Installs cargo-fuzz if it is missing; needs the nightly toolchain (`rustup toolchain list`).
# - Each target starts from its committed seeds (fuzz/corpus/TARGET, only read) and from what
#   earlier runs on this machine found (fuzz/work/TARGET, not committed); it runs for SECONDS.
# - A crash (a panic: a broken property or an unexpected failure) is kept under
#   fuzz/artifacts/TARGET, minimised with `cargo fuzz tmin` and kept as a regression seed,
#   fuzz/corpus/TARGET/regress-<hash>, which the ordinary tests replay on stable from then
#   on; the script then fails.
# - Prints a line per target as it ends (executions, executions per second, corpus size,
#   crashes), and appends the same as a JSON line to fuzz/work/summary.jsonl.
#
# Environment: FUZZ_JOBS (targets run at once; default: the number of cores),
# FUZZ_SANITIZER (address, the default, or none: faster to build and run, for CI),
# FUZZ_WORK (default fuzz/work), FUZZ_BUILD_ONLY=1 (build the targets, run none: CI builds
# them while the tests run; SECONDS is then still required but unused).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root/fuzz"

usage() {
    sed -n '2,4p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//' >&2
    exit 2
}
[ $# -ge 1 ] || usage
seconds="$1"
shift
[[ "$seconds" =~ ^[0-9]+$ ]] && [ "$seconds" -gt 0 ] || {
    echo "fuzz.sh: SECONDS must be a whole number above 0, got \"$seconds\"" >&2
    exit 2
}
all_targets=$(sed -n 's/^name = "\(.*\)"$/\1/p' Cargo.toml | grep -v '^mavstack-fuzz$')
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets <<<"$all_targets"
fi
for t in "${targets[@]}"; do
    grep -qx "$t" <<<"$all_targets" || {
        echo "fuzz.sh: no fuzz target \"$t\"; there are: $(echo $all_targets)" >&2
        exit 2
    }
done

rustup toolchain list | grep -q '^nightly' || {
    echo "fuzz.sh: the nightly toolchain is missing (rustup toolchain install nightly)" >&2
    exit 1
}
if ! command -v cargo-fuzz >/dev/null; then
    echo "fuzz.sh: installing cargo-fuzz"
    cargo install cargo-fuzz --locked --quiet
fi

sanitizer="${FUZZ_SANITIZER:-address}"
jobs="${FUZZ_JOBS:-$(nproc)}"
work="${FUZZ_WORK:-$root/fuzz/work}"
mkdir -p "$work"
# Words without spaces, split where used (the function below runs in a child bash).
flags="--sanitizer $sanitizer --debug-assertions"

echo "fuzz.sh: building (sanitizer $sanitizer)"
started=$(date +%s)
# `cargo fuzz build T` builds one target; without a name, all of them.
# shellcheck disable=SC2086
cargo +nightly fuzz build $flags $([ ${#targets[@]} -eq 1 ] && echo "${targets[0]}")
echo "fuzz.sh: built in $(($(date +%s) - started)) s"
if [ "${FUZZ_BUILD_ONLY:-}" = "1" ]; then
    exit 0
fi

# One target: run it, and on a crash keep the minimised input as a regression seed.
# shellcheck disable=SC2086
run_one() {
    local t="$1" log="$work/$1.log" out
    mkdir -p "$work/$t" "$root/fuzz/artifacts/$t"
    local before
    before=$(find "$work/$t" -type f | wc -l)
    local status=0
    cargo +nightly fuzz run $flags "$t" "$work/$t" "corpus/$t" -- \
        -max_total_time="$seconds" -print_final_stats=1 -timeout=10 -rss_limit_mb=2048 \
        -artifact_prefix="$root/fuzz/artifacts/$t/" >"$log" 2>&1 || status=$?
    local execs rate after crashes=0
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    after=$(find "$work/$t" -type f | wc -l)
    if [ "$status" -ne 0 ]; then
        for crash in "$root/fuzz/artifacts/$t"/crash-* "$root/fuzz/artifacts/$t"/oom-* "$root/fuzz/artifacts/$t"/timeout-*; do
            [ -f "$crash" ] || continue
            crashes=$((crashes + 1))
            local min="$root/fuzz/artifacts/$t/min-$(basename "$crash")"
            cargo +nightly fuzz tmin $flags "$t" "$crash" -- -exact_artifact_path="$min" \
                >>"$log" 2>&1 || true
            [ -f "$min" ] || min="$crash"
            local seed="corpus/$t/regress-$(sha1sum "$min" | cut -c1-12)"
            cp "$min" "$seed"
            echo "fuzz.sh: $t crashed; regression seed $seed (log: $log)" >&2
            mv "$crash" "$(dirname "$crash")/seeded-$(basename "$crash")"
        done
        [ "$crashes" -gt 0 ] || { echo "fuzz.sh: $t failed without a crash input (log: $log):" >&2; tail -20 "$log" >&2; }
    fi
    out=$(printf '{"target":"%s","seconds":%s,"executions":%s,"executions_per_second":%s,"corpus_before":%s,"corpus_after":%s,"crashes":%s,"status":%s}' \
        "$t" "$seconds" "${execs:-0}" "${rate:-0}" "$before" "$after" "$crashes" "$status")
    echo "$out" >>"$work/summary.jsonl"
    printf '%-14s %12s execs %9s/s  corpus %5s -> %-5s crashes %s\n' \
        "$t" "${execs:-0}" "${rate:-0}" "$before" "$after" "$crashes"
    [ "$status" -eq 0 ]
}
export -f run_one
export seconds work flags root

echo "fuzz.sh: ${#targets[@]} targets x ${seconds} s, ${jobs} at once"
failed=0
printf '%s\n' "${targets[@]}" | xargs -P "$jobs" -I{} bash -c 'run_one "$1"' _ {} || failed=1
if [ "$failed" -ne 0 ]; then
    echo "fuzz.sh: a target crashed or failed (see above); its regression seed is under fuzz/corpus" >&2
    exit 1
fi
echo "fuzz.sh: no crashes"
