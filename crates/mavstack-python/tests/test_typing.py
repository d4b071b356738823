"""The package's types: the generated message stubs (python/mavstack/messages) are what
stubgen.py writes and agree with the extension's dialects (every message and its id,
pymavlink's arguments of ``mav.<name>_send``, the Python type of every field read back), a
type checker rejects what they rule out, and the typed examples run.

mypy is the test venv's (scripts/setup-peers.sh): missing, the tests fail."""

import importlib.util
import inspect
import os
import subprocess
import sys
import textwrap

import pytest

import mavstack
from conftest import Vehicle, free_port
from mavstack import mavutil

HERE = os.path.dirname(os.path.abspath(__file__))
PACKAGE = os.path.dirname(HERE)
ROOT = os.path.abspath(os.path.join(PACKAGE, "..", ".."))
STUBGEN = os.path.join(PACKAGE, "stubgen.py")
EXAMPLES = os.path.join(PACKAGE, "examples")


def stubgen():
    spec = importlib.util.spec_from_file_location("stubgen", STUBGEN)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_committed_stubs_are_what_stubgen_writes():
    p = subprocess.run([sys.executable, STUBGEN, "--check"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr


def test_stubgen_check_fails_on_a_stale_stub(tmp_path):
    out = tmp_path / "messages"
    subprocess.run([sys.executable, STUBGEN, "--out", str(out)], check=True, capture_output=True)
    assert subprocess.run([sys.executable, STUBGEN, "--check", "--out", str(out)]).returncode == 0
    stub = out / "minimal.pyi"
    stub.write_text(stub.read_text().replace("custom_mode: int", "custom_mode: float", 1))
    p = subprocess.run([sys.executable, STUBGEN, "--check", "--out", str(out)],
                       capture_output=True, text=True)
    assert p.returncode == 1 and "minimal.pyi" in p.stderr


def test_every_builtin_dialect_has_stubs():
    gen = stubgen()
    assert gen.dialect_names(os.path.join(ROOT, "definitions")) == sorted(mavstack.dialects())


def value_for(field):
    """An argument for `field` (of its stub type) that reads back recognisably."""
    if field.base == "char":
        return "ab" if field.array is not None else "a"
    scalar = 1.5 if field.base in ("float", "double") else 1
    return scalar if field.array is None else [scalar] * field.array


def check_read_type(field, value):
    t = field.read_type()
    if t == "str":
        return isinstance(value, str)
    if t in ("int", "float"):
        return type(value).__name__ == t
    element = t[len("List["):-1]
    return (isinstance(value, list) and len(value) == field.array
            and all(type(v).__name__ == element for v in value))


@pytest.mark.parametrize("dialect", mavstack.dialects())
def test_stubs_agree_with_the_extension(dialect):
    """Each message of the stubs is the extension's (name and id, none missing, none extra),
    `mav.<name>_send` and `_encode` take the stub's arguments in its order with the same ones
    optional, and every field reads back as the stub's type."""
    gen = stubgen()
    messages, _ = gen.load(os.path.join(ROOT, "definitions"), dialect)
    ids = {name[len("MAVLINK_MSG_ID_"):]: v for name, v in mavstack._native.dialect_constants(dialect)
           if name.startswith("MAVLINK_MSG_ID_")}
    assert {m.name: m.id for m in messages} == ids
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:%d" % free_port(), dialect=dialect)
    try:
        assert isinstance(conn, mavutil.mavlive)
        wrong = []
        for m in messages:
            lower = m.name.lower()
            for suffix, tail in (("_encode", []), ("_send", ["force_mavlink1"])):
                params = list(inspect.signature(getattr(conn.mav, lower + suffix)).parameters.values())
                got = [(p.name, p.default is not inspect.Parameter.empty) for p in params]
                want = [(f.arg_name(), f.optional()) for f in m.fields] + [(t, True) for t in tail]
                if got != want:
                    wrong.append((m.name + suffix, got, want))
            msg = getattr(conn.mav, lower + "_encode")(*[value_for(f) for f in m.fields])
            for f in m.fields:
                if not check_read_type(f, getattr(msg, f.name)):
                    wrong.append((m.name, f.name, f.read_type(), getattr(msg, f.name)))
        assert not wrong, wrong[:5]
    finally:
        conn.close()


def mypy(path):
    return subprocess.run([sys.executable, "-m", "mypy", "--strict", "--no-incremental", str(path)],
                          capture_output=True, text=True, cwd=str(path.parent))


def test_mypy_rejects_what_the_stubs_rule_out(tmp_path):
    good = tmp_path / "good.py"
    good.write_text(textwrap.dedent("""\
        from mavstack import mavutil

        def roll(conn: mavutil.mavlive) -> float:
            conn.mav.attitude_send(1, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0)
            conn.mav.param_set_send(1, 1, b"RTL_ALT", 3000.0, 9)
            m = conn.recv_match(type="ATTITUDE", blocking=True, timeout=1)
            return conn.messages["ATTITUDE"].pitch if m is None else m.roll
        """))
    p = mypy(good)
    assert p.returncode == 0, p.stdout + p.stderr
    bad = tmp_path / "bad.py"
    bad.write_text(textwrap.dedent("""\
        from mavstack import mavutil

        def roll(conn: mavutil.mavlive) -> str:
            conn.mav.attitude_send(1, 0.1, 0.2)
            conn.mav.attitude_sned(1, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0)
            conn.mav.param_set_send(1, 1, b"RTL_ALT", "3000", 9)
            m = conn.recv_match(type="ATTITUDE")
            assert m is not None
            return m.roll

        def latest(conn: mavutil.mavlive) -> str:
            return conn.messages["ATTITUDE"].roll
        """))
    p = mypy(bad)
    out = p.stdout
    assert p.returncode == 1, out + p.stderr
    for line, code in ((4, "call-arg"), (5, "attr-defined"), (6, "arg-type"), (9, "return-value"),
                       (12, "return-value")):
        assert "bad.py:%d: error:" % line in out and "[%s]" % code in out, out


@pytest.fixture(scope="module")
def tlog(tmp_path_factory):
    path = tmp_path_factory.mktemp("examples") / "flight.tlog"
    subprocess.run([sys.executable, os.path.join(ROOT, "tests-interop", "log_tools.py"), "make",
                    "--seconds", "60", "--out", str(path)], check=True, capture_output=True)
    return path


def run_example(name, *args):
    p = subprocess.run([sys.executable, os.path.join(EXAMPLES, name), *args], capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 0, p.stdout + p.stderr
    return p.stdout


def test_log_reading_example(tlog):
    out = run_example("log_reading.py", str(tlog))
    assert "ATTITUDE" in out and "largest |roll|: 0.500 rad" in out and "293 positions" in out


def test_tables_example(tlog):
    out = run_example("tables.py", str(tlog))
    assert "ATTITUDE: 701 rows" in out and "GLOBAL_POSITION_INT: 293 rows" in out


def test_live_link_example():
    port = free_port()
    with Vehicle("udpout:127.0.0.1:%d" % port):
        out = run_example("live_link.py", "udpin:127.0.0.1:%d" % port, "2")
    assert "vehicle 1 " in out and "parameter RTL_ALT = 3000" in out, out
    assert "ATTITUDE, last roll" in out, out


def test_send_arguments_are_pymavlinks():
    """The stubs' `mav.<name>_send` arguments are those of pymavlink's generated module (names,
    order, which are optional), for every message of ardupilotmega that it has."""
    from pymavlink.dialects.v20 import ardupilotmega as apm
    gen = stubgen()
    messages, _ = gen.load(os.path.join(ROOT, "definitions"), "ardupilotmega")
    compared, wrong = 0, []
    for m in messages:
        theirs = getattr(apm.MAVLink, m.name.lower() + "_send", None)
        if theirs is None:
            continue
        params = list(inspect.signature(theirs).parameters.values())[1:]
        got = [(p.name, p.default is not inspect.Parameter.empty) for p in params]
        want = [(f.arg_name(), f.optional()) for f in m.fields] + [("force_mavlink1", True)]
        compared += 1
        if got != want:
            wrong.append((m.name, got, want))
    assert compared > 200 and not wrong, (compared, wrong[:3])
