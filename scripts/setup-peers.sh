#!/usr/bin/env bash
# Sets up the peers the tests compare against, idempotently:
#   .venv/ — a Python virtualenv with pymavlink 2.4.50 from PyPI (the reference implementation).
# Prints the python to use (also exported by scripts/test.sh as MAVSTACK_PYTHON).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${MAVSTACK_VENV:-$root/.venv}"
want=2.4.50
if ! command -v python3 >/dev/null; then
    echo "setup-peers: python3 not found (Debian: apt-get install python3 python3-venv)" >&2
    exit 1
fi
if [ ! -x "$venv/bin/python" ]; then
    if ! python3 -m venv "$venv" 2>/dev/null; then
        echo "setup-peers: python3 -m venv failed; installing python3-venv" >&2
        apt-get update -qq && apt-get install -y -qq python3-venv >/dev/null
        python3 -m venv "$venv"
    fi
fi
have="$("$venv/bin/python" -c 'from importlib.metadata import version; print(version("pymavlink"))' 2>/dev/null || true)"
if [ "$have" != "$want" ]; then
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "pymavlink==$want" >&2
fi
echo "$venv/bin/python"
