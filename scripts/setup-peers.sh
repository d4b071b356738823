#!/usr/bin/env bash
# Sets up the peers the tests compare against, idempotently (quiet when nothing changes):
#   .venv/ — a Python virtualenv with, from PyPI, pinned:
#     pymavlink 2.4.50   the reference implementation (kept at 2.4.50: constraints file);
#     MAVProxy 1.8.75    ground station, headless: installed without its GUI/map dependencies
#                        (vtk, opencv, matplotlib, wxPython...), plus what its console needs;
#     mavsdk 4.1.0       MAVSDK's native Python binding (ctypes over the bundled libcmavsdk.so);
#     mavsdk-grpc 4.0.5  MAVSDK's gRPC wrapper (import mavsdk_grpc) with its bundled
#                        mavsdk_server binary (mavsdk_grpc/bin/mavsdk_server);
#     for the Python package (crates/mavstack-python): maturin 1.16.0 (builds the wheel),
#     pytest 9.2.0 (with pytest-xdist 3.8.0: the tests in two processes), and the readers of
#     its Arrow tables: pyarrow 26.0.1, polars 2.1.0,
#     pandas 3.1.1, matplotlib 3.11.2 (its README's example); its type checks: mypy 2.4.1
#     (with stubtest) and pyright 1.1.414 (the PyPI wheel carries pyright itself and runs it
#     with the system's node, which scripts/setup-system.sh installs: nothing is fetched when
#     it runs); fasttlogparser 1.1.1 (C++, the tlog benchmark's third reader: PyPI has only its
#     source, built here into a wheel, see below).
# Prints the python to use (also exported by scripts/test.sh as MAVSTACK_PYTHON).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${MAVSTACK_VENV:-$root/.venv}"
want=2.4.50
# name==version of every package we install, dependencies included (nothing floats).
pins=(
    "pymavlink==$want" "lxml==6.1.3" "fastcrc==0.5.0"
    "pyserial==3.5" "pexpect==4.9.0" "ptyprocess==0.7.0" "defusedxml==0.7.1" "pynmeagps==1.1.8"
    "mavsdk==4.1.0"
    "mavsdk-grpc==4.0.5" "grpcio==1.85.1" "protobuf==6.33.6" "typing_extensions==4.16.0"
    "maturin==1.16.0" "pytest==9.2.0" "iniconfig==2.3.1" "pluggy==1.7.0" "packaging==26.4"
    "pytest-xdist==3.8.0" "execnet==2.1.2"
    "Pygments==2.21.0" "pyarrow==26.0.1" "polars==2.1.0" "polars-runtime-32==2.1.0"
    "pandas==3.1.1" "numpy==2.4.6" "python-dateutil==4.0.0" "tzdata==2026.6"
    "matplotlib==3.11.2" "contourpy==1.3.3" "cycler==0.12.1" "fonttools==4.68.0"
    "kiwisolver==1.5.1" "pillow==13.0.0" "pyparsing==3.3.3"
    "paho-mqtt==2.2.0" "eclipse-zenoh==1.10.2"
    "mypy==2.4.1" "mypy_extensions==1.2.0" "pathspec==1.1.1" "librt==0.17.0"
    "ast_serialize==0.13.1" "pyright==1.1.414" "nodeenv==1.12.0"
)
# Built from its source distribution (see below), then installed without dependencies (it has
# none declared; it returns numpy arrays, numpy is pinned above).
built=("fasttlogparser==1.1.1")
# What that build needs, in a throwaway venv of its own.
build_pins=("scikit-build-core==1.1.2" "pybind11==3.1.0" "cmake==4.4.5" "packaging==26.4"
            "pathspec==1.1.1")
nodeps=("MAVProxy==1.8.75")
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
# Which pins are missing or at another version (empty when all are in place).
missing() {
    "$venv/bin/python" - "$@" <<'PY'
import sys
from importlib.metadata import version, PackageNotFoundError
for pin in sys.argv[1:]:
    name, want = pin.split("==")
    try:
        have = version(name)
    except PackageNotFoundError:
        have = None
    if have != want:
        print(pin)
PY
}
if [ -n "$(missing "${pins[@]}" "${nodeps[@]}" "${built[@]}")" ]; then
    pip=("$venv/bin/python" -m pip install --quiet --disable-pip-version-check)
    constraints="$(mktemp)"
    trap 'rm -f "$constraints"' EXIT
    printf '%s\n' "${pins[@]}" > "$constraints"
    "${pip[@]}" -c "$constraints" "${pins[@]}" >&2
    # MAVProxy's declared dependencies pull in the GUI stack and would float pymavlink: its
    # headless needs (pymavlink, pyserial, defusedxml, pynmeagps) are pinned above.
    "${pip[@]}" --no-deps "${nodeps[@]}" >&2
    if [ -n "$(missing "${built[@]}")" ]; then
        # fasttlogparser's build runs pip itself (to fetch pymavlink's generator's needs into
        # its build tree, then generate the C headers with mavgen): pip's isolated build
        # environment has no pip, so it is built without isolation in a venv that has pip
        # and the pinned build tools (a C++ compiler: scripts/setup-system.sh).
        work="$(mktemp -d)"
        trap 'rm -rf "$constraints" "$work"' EXIT
        python3 -m venv "$work/venv"
        "$work/venv/bin/python" -m pip install --quiet --disable-pip-version-check "${build_pins[@]}" >&2
        "$work/venv/bin/python" -m pip wheel --quiet --disable-pip-version-check --no-deps \
            --no-build-isolation -w "$work/wheels" "${built[@]}" >&2
        "${pip[@]}" --no-deps "$work"/wheels/*.whl >&2
    fi
    left="$(missing "${pins[@]}" "${nodeps[@]}" "${built[@]}")"
    if [ -n "$left" ]; then
        echo "setup-peers: not installed as pinned: $left" >&2
        exit 1
    fi
fi
server="$("$venv/bin/python" -c 'import os, mavsdk_grpc.bin as b; print(os.path.join(os.path.dirname(b.__file__), "mavsdk_server"))')"
if [ ! -x "$server" ]; then
    echo "setup-peers: mavsdk-grpc has no executable mavsdk_server at $server" >&2
    exit 1
fi
echo "$venv/bin/python"
