#!/usr/bin/env bash
# Runs the unit tests of the `no_std` crates (core, channel, router, services) under Miri, the
# interpreter that detects undefined behaviour, on nightly (`rustup +nightly component add miri
# rust-src` if it is missing). Not part of CI (it takes minutes to build); run it by hand
# after changing those crates. Proptest runs 4 cases per property under Miri.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
if ! cargo +nightly miri --version >/dev/null 2>&1; then
    echo "miri.sh: installing the miri component on nightly"
    rustup +nightly component add miri rust-src
fi
# Isolation off: proptest reads the working directory for its failure files.
export MIRIFLAGS="${MIRIFLAGS:--Zmiri-disable-isolation}" PROPTEST_CASES="${PROPTEST_CASES:-4}"
for crate in mavstack-core mavstack-channel mavstack-router mavstack-services; do
    started=$SECONDS
    cargo +nightly miri test -p "$crate" --lib
    echo "miri.sh: $crate passed in $((SECONDS - started)) s"
done
