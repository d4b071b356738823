#!/usr/bin/env bash
# The whole test suite, exactly what CI runs (.ci/run calls this script):
# peers, formatting, lints, every test and doctest, docs, and a small feature matrix.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
step() { printf '\n== %s\n' "$*"; }

step "peers (pymavlink 2.4.50 in .venv)"
MAVSTACK_PYTHON="$(scripts/setup-peers.sh)"
export MAVSTACK_PYTHON
echo "python: $MAVSTACK_PYTHON"

step "cargo fmt --check"
cargo fmt --all -- --check

step "cargo clippy (all targets, all features, -D warnings)"
cargo clippy --workspace --all-targets --all-features --locked -- -D warnings

step "cargo test (workspace, all features)"
cargo test --workspace --all-features --locked

step "examples, against the in-process simulated vehicle"
gs="$(cargo run -q --locked -p mavstack --features sim --example ground_station -- 4)"
for want in "ATTITUDE roll" "GLOBAL_POSITION_INT -35.36" "HEARTBEAT MAV_TYPE_QUADROTOR MAV_AUTOPILOT_ARDUPILOTMEGA" "link vehicle (2)"; do
    if ! grep -qF "$want" <<<"$gs"; then
        printf 'ground_station example: no "%s" in its output:\n%s\n' "$want" "$gs" >&2
        exit 1
    fi
done

step "feature matrix"
cargo build -p mavstack --locked
cargo build -p mavstack-core --no-default-features --locked
cargo build -p mavstack-dialects --no-default-features --features minimal --locked
cargo build -p mavstack-dialects --locked
cargo test -p mavstack-dialects --no-default-features --features common --locked --doc

step "cargo doc (-D warnings)"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --all-features --locked

step "done: every check passed"
