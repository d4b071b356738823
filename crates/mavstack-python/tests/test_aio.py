"""mavstack.aio, the asyncio API: against the simulated vehicle (`mavstack vehicle`, as
ArduPilot and as PX4, clean and through 20 % loss each way), a served component answered by
pymavlink and by mavstack.aio itself, cancellation, timeouts and closing."""

import asyncio
import builtins
import faulthandler
import os
import socket
import subprocess
import sys
import threading

import pytest

import mavstack.aio as aio
from conftest import Lossy, Vehicle, free_port

HOME = (-353632610, 1491652300)


@pytest.fixture(autouse=True)
def hang_guard():
    """A test that hangs (a result that never reaches the loop) dumps every thread's stack and
    ends the process after 120 s, instead of blocking the run."""
    faulthandler.dump_traceback_later(120, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


def run(coro, timeout=40):
    """Runs `coro` on a fresh loop; exceptions the loop saw outside the tasks (a future
    settled after it was cancelled, say) fail the test."""
    seen = []

    async def main():
        asyncio.get_running_loop().set_exception_handler(lambda _loop, ctx: seen.append(ctx))
        result = await asyncio.wait_for(coro, timeout)
        # Let late completions of abandoned operations arrive before looking.
        for _ in range(5):
            await asyncio.sleep(0.05)
        return result

    result = asyncio.run(main())
    assert seen == [], seen
    return result


def plan(n):
    """Home, then n-1 waypoints."""
    items = [aio.MissionItem(16, frame=0, x=HOME[0], y=HOME[1], z=584.0)]
    items += [aio.MissionItem(16, x=HOME[0] + 100 * i, y=HOME[1] + 50 * i, z=10.0 + i, param1=float(i % 3))
              for i in range(1, n)]
    return items


def same_plan(sent, back, autopilot):
    assert len(back) == len(sent)
    for a, b in list(zip(sent, back))[1:]:
        assert (a.command, a.x, a.y, a.z, a.param1, a.autocontinue) == (b.command, b.x, b.y, b.z, b.param1, b.autocontinue)
        # PX4 answers with the _INT frames.
        assert b.frame in ((a.frame,) if autopilot == "ardupilot" else (a.frame, 6))


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_a_ground_station_session(autopilot):
    port = free_port()

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            assert gcs.identity == (255, 190)
            vehicle = await gcs.vehicle(timeout=10)
            assert (vehicle.system, vehicle.autopilot) == (1, 3 if autopilot == "ardupilot" else 12)
            assert (1, vehicle.component, vehicle.autopilot, vehicle.mav_type) in gcs.systems()

            params = await vehicle.params.get_all()
            assert vehicle.params.last_via == "ftp"  # the vehicle offers @PARAM/param.pck
            assert params["MAV_SYS_ID" if autopilot == "px4" else "MAV_SYSID"] == 1
            told = []
            listed = await vehicle.params.get_all(via="list", progress=lambda d, t: told.append((d, t)))
            assert listed == params
            assert told[-1] == (len(params), len(params)) and told == sorted(told), told
            name, value = ("MPC_XY_CRUISE", 7.5) if autopilot == "px4" else ("RTL_ALT", 3456)
            assert await vehicle.params.set(name, value) == value
            assert await vehicle.params.get(name) == value
            assert isinstance(await vehicle.params.get(name), type(value))

            sent = plan(8)
            told = []
            await vehicle.mission.upload(sent, progress=lambda done, total: told.append((done, total)))
            n = 8 if autopilot == "ardupilot" else 7  # PX4 stores no home
            assert told[-1] == (n, n) and told == sorted(told), told
            told.clear()
            back = await vehicle.mission.download(progress=lambda done, total: told.append((done, total)))
            assert told[-1] == (n, n) and told == sorted(told), told
            same_plan(sent, back, autopilot)
            raw = await vehicle.mission.download(plan=False)
            assert len(raw) == (8 if autopilot == "ardupilot" else 7)
            await vehicle.mission.upload([i.to_dict() for i in sent])  # dicts do too
            await vehicle.mission.clear()
            assert await vehicle.mission.download(plan=False) == ([] if autopilot == "px4" else raw[:1])

            armed = await vehicle.arm()
            assert str(armed) == "ACCEPTED" and armed and armed.command == "COMPONENT_ARM_DISARM"
            mode = await vehicle.set_mode("GUIDED" if autopilot == "ardupilot" else "Hold")
            assert str(mode) == "ACCEPTED"
            with pytest.raises(aio.UnknownModeError, match="one of") as e:
                await vehicle.set_mode("NO_SUCH_MODE")
            assert isinstance(e.value, ValueError)
            assert str(await vehicle.command("MAV_CMD_COMPONENT_ARM_DISARM", 0)) == "ACCEPTED"
            assert str(await vehicle.command("REQUEST_MESSAGE", 148)) == "ACCEPTED"
            with pytest.raises(ValueError, match="NO_SUCH"):
                await vehicle.command("NO_SUCH")

            attitude = vehicle.telemetry("ATTITUDE", rate_hz=20)
            got = []
            async for m in attitude:
                assert m.get_type() == "ATTITUDE" and m.get_srcSystem() == 1
                got.append(m)
                if len(got) == 10:
                    break
            attitude.close()
            # Closing ends the iterators that are waiting.
            heartbeats = vehicle.telemetry("HEARTBEAT")
            first = await heartbeats.__anext__()
            assert first.get_type() == "HEARTBEAT"
            rest = asyncio.ensure_future(_count(heartbeats))
        # out of `async with`: closed
        assert gcs.closed
        await rest
        with pytest.raises(aio.ConnectionClosed):
            await vehicle.params.get(name)

    with Vehicle("udpout:127.0.0.1:%d" % port, "--autopilot", autopilot):
        run(session())


async def _count(stream):
    n = 0
    async for _ in stream:
        n += 1
    return n


def test_a_refusal_carries_the_statustext_that_explains_it():
    port = free_port()

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            result = await vehicle.arm()
            assert not result.accepted and str(result) in ("FAILED", "DENIED", "TEMPORARILY_REJECTED")
            assert any("PreArm" in line for line in result.statustext), result.statustext
            assert "PreArm" in repr(result)

    with Vehicle("udpout:127.0.0.1:%d" % port, "--estimator-settle", "120"):
        run(session())


@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_params_and_a_50_item_mission_through_20_percent_loss(autopilot):
    port = free_port()

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            clean = await vehicle.params.get_all(via="list")
            assert len(clean) > 20
            assert await vehicle.params.get_all() == clean
            sent = plan(50)
            await vehicle.mission.upload(sent)
            same_plan(sent, await vehicle.mission.download(), autopilot)

    with Lossy(port) as relay_port, Vehicle("udpout:127.0.0.1:%d" % relay_port, "--autopilot", autopilot):
        run(session(), timeout=50)


def test_no_vehicle_is_a_timeout_error_of_both_kinds():
    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % free_port()) as gcs:
            with pytest.raises(aio.TimeoutError, match="no vehicle heard") as e:
                await gcs.vehicle(timeout=0.2)
            assert isinstance(e.value, builtins.TimeoutError) and isinstance(e.value, aio.Error)
    run(session())


def test_bad_connection_strings_and_ports_in_use_are_named():
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    busy = "udpin:127.0.0.1:%d" % taken.getsockname()[1]

    async def session():
        with pytest.raises(ValueError, match="udpin:nohost"):
            await aio.connect("udpin:nohost")
        with pytest.raises(aio.ConnectionFailed, match=busy) as e:
            await aio.connect(busy)
        assert isinstance(e.value, OSError)
        with pytest.raises(aio.ConnectionFailed, match=busy):
            await aio.serve(busy)
    try:
        run(session())
    finally:
        taken.close()


def test_cancelled_and_timed_out_operations_are_abandoned_cleanly():
    port = free_port()

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            # Cancelled while waiting for a vehicle.
            waiting = asyncio.ensure_future(gcs.vehicle(timeout=30))
            await asyncio.sleep(0)
            waiting.cancel()
            with pytest.raises(asyncio.CancelledError):
                await waiting
            vehicle = await gcs.vehicle(timeout=10)
            # A parameter the vehicle does not have is never answered: wait_for gives up
            # on it, and the vehicle's next operation runs (the first let its lock go).
            with pytest.raises(builtins.TimeoutError):
                await asyncio.wait_for(vehicle.params.get("NO_SUCH_PARAM"), 0.5)
            assert await vehicle.params.get("MAV_SYSID") == 1
            # Several cancelled in a row, then one that completes.
            for _ in range(3):
                t = asyncio.ensure_future(vehicle.params.get_all(via="list"))
                await asyncio.sleep(0)
                t.cancel()
                with pytest.raises(asyncio.CancelledError):
                    await t
            assert len(await vehicle.params.get_all(via="list")) > 20
            # A telemetry reader cancelled while it waits; the stream still reads.
            stream = vehicle.telemetry("HEARTBEAT")
            t = asyncio.ensure_future(stream.__anext__())
            await asyncio.sleep(0)
            t.cancel()
            with pytest.raises(asyncio.CancelledError):
                await t
            assert (await stream.__anext__()).get_type() == "HEARTBEAT"
            # An operation running when the connection closes fails with ConnectionClosed.
            other = asyncio.ensure_future(gcs.vehicle(timeout=30, system=99))
            await asyncio.sleep(0)
            await gcs.close()
            with pytest.raises(aio.ConnectionClosed):
                await other

    with Vehicle("udpout:127.0.0.1:%d" % port):
        run(session())


def test_a_served_component_answers_pymavlink():
    """A pymavlink ground station lists and sets the component's parameters and sends it
    commands, answered by an async handler."""
    port = free_port()
    seen = []

    async def handler(request):
        seen.append((request.name, request.params[0], request.sender))
        await asyncio.sleep(0)
        if request.command == 31010:  # MAV_CMD_USER_1 (31000: WAYPOINT_USER_1)
            return "DENIED", 7
        if request.command == 31011:
            raise RuntimeError("handler failure")
        return None

    def ground_station(done):
        os.environ.setdefault("MAVLINK20", "1")
        from pymavlink import mavutil
        m = mavutil.mavlink_connection("udpout:127.0.0.1:%d" % port, source_system=255, dialect="ardupilotmega")
        try:
            out = {}
            m.mav.heartbeat_send(6, 8, 0, 0, 0)
            hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
            out["hb"] = (hb.get_srcSystem(), hb.get_srcComponent(), hb.type) if hb else None
            m.mav.param_request_list_send(7, 100)
            values = {}
            while len(values) < 2:
                v = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=5)
                if v is None:
                    break
                values[v.param_id] = v.param_value
            out["list"] = values
            m.mav.param_set_send(7, 100, b"CAM_MODE", 3, 6)
            v = m.recv_match(type="PARAM_VALUE", blocking=True, timeout=5)
            out["set"] = (v.param_id, v.param_value) if v else None
            acks = []
            for cmd in (31000, 31010, 31011):
                m.mav.command_long_send(7, 100, cmd, 0, 1.5, 0, 0, 0, 0, 0, 0)
                a = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
                acks.append((a.command, a.result, a.result_param2) if a else None)
            out["acks"] = acks
            done.append(out)
        finally:
            m.close()

    async def session():
        params = {"CAM_EXPOSURE": 0.25, "CAM_MODE": 2}
        async with aio.serve("udpin:127.0.0.1:%d" % port, system=7, component=100, params=params,
                             on_command=handler, mav_type=30, encoding="c_cast") as server:
            done = []
            await asyncio.to_thread(ground_station, done)
            assert server.changes() == [("CAM_MODE", 3)]
            assert await server.params() == {"CAM_EXPOSURE": 0.25, "CAM_MODE": 3}
            return done[0]

    out = run(session())
    assert out["hb"] == (7, 100, 30)
    assert out["list"] == {"CAM_EXPOSURE": 0.25, "CAM_MODE": 2.0}
    assert out["set"] == ("CAM_MODE", 3.0)
    # One final ACK each (IN_PROGRESS is never the first answer): accepted, the handler's
    # DENIED with its result_param2, FAILED for the exception.
    assert out["acks"] == [(31000, 0, 0), (31010, 2, 7), (31011, 4, 0)]
    assert seen == [("WAYPOINT_USER_1", 1.5, (255, 0)), ("USER_1", 1.5, (255, 0)), ("USER_2", 1.5, (255, 0))]


def test_a_served_component_answers_mavstack_aio_with_a_sync_handler():
    port = free_port()
    calls = []

    def handler(request):
        calls.append(request.command)
        return request.command != 31001

    async def session():
        async with aio.serve("udpin:127.0.0.1:%d" % port, system=9, component=191, params={"X_GAIN": 1.5},
                             on_command=handler, autopilot=0, mav_type=2) as server:
            async with aio.connect("udpout:127.0.0.1:%d" % port, source_system=250) as gcs:
                comp = await gcs.vehicle(timeout=10, system=9)
                assert (comp.system, comp.component) == (9, 191)
                assert await comp.params.get_all(via="list") == {"X_GAIN": 1.5}
                assert await comp.params.set("X_GAIN", 2.25) == 2.25
                assert await server.params() == {"X_GAIN": 2.25}
                assert await server.set_param("X_NEW", 4) == 4
                assert await comp.params.get("X_NEW") == 4
                assert str(await comp.command(31000, 1)) == "ACCEPTED"
                assert str(await comp.command(31001)) == "FAILED"
                # Messages of its own, both ways.
                values = comp.telemetry("NAMED_VALUE_FLOAT")
                gcs_side = asyncio.ensure_future(values.__anext__())
                await asyncio.sleep(0)
                while not gcs_side.done():
                    server.send("NAMED_VALUE_FLOAT", name="TEMP", value=21.5, time_boot_ms=7)
                    await asyncio.wait([gcs_side], timeout=0.2)
                m = gcs_side.result()
                assert (m.name, m.value, m.time_boot_ms, m.get_srcComponent()) == ("TEMP", 21.5, 7, 191)
                with pytest.raises(TypeError, match="no field"):
                    gcs.send("NAMED_VALUE_FLOAT", nope=1)
            with pytest.raises(ConnectionError):
                gcs.send("HEARTBEAT")
            assert calls == [31000, 31001]

    run(session())


def test_many_operations_at_once_complete_in_order():
    """Operations on one vehicle run one after the other; many started together all
    complete, each with its own result."""
    port = free_port()

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            names = ["MAV_SYSID", "RTL_ALT", "FORMAT_VERSION"] * 4
            values = await asyncio.gather(*(vehicle.params.get(n) for n in names))
            assert values[0::3] == [1] * 4 and len(set(values[1::3])) == 1

    with Vehicle("udpout:127.0.0.1:%d" % port):
        run(session())


def test_results_that_come_while_the_loop_drains_are_not_lost():
    """Thousands of operations ending at scattered moments, many while the loop is settling
    others: every one is settled. (The loop once cleared its wake-up flag before reading the
    wake-up byte; a result posted in between swallowed its own byte and every later result
    waited forever: the first round of this test hung.)"""
    import random
    rnd = random.Random(1)

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % free_port()) as gcs:
            async def one(timeout):
                with pytest.raises(aio.TimeoutError):
                    await gcs.vehicle(timeout=timeout)

            for _ in range(20):
                tasks = [asyncio.ensure_future(one(rnd.uniform(0.001, 0.05))) for _ in range(200)]
                done, pending = await asyncio.wait(tasks, timeout=10)
                assert not pending, "%d of 200 operations were never settled" % len(pending)
                for t in done:
                    t.result()

    run(session(), timeout=120)


def test_the_loop_thread_is_the_only_python_thread():
    """No helper thread in Python: results come through the waker the loop watches."""
    port = free_port()

    async def session():
        before = threading.active_count()
        async with aio.connect("udpin:127.0.0.1:%d" % port) as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            await asyncio.gather(*(vehicle.params.get("MAV_SYSID") for _ in range(20)))
            assert threading.active_count() == before

    with Vehicle("udpout:127.0.0.1:%d" % port):
        run(session())


def test_the_example_runs_and_the_interpreter_exits_cleanly():
    """examples/aio_ground_station.py against the vehicle, in a process of its own: its
    output, and exit status 0 (results arriving while the interpreter finalizes must not
    abort it), also for a process that leaves a busy stream and its connection open."""
    port = free_port()
    example = os.path.join(os.path.dirname(__file__), "..", "examples", "aio_ground_station.py")
    left_open = (
        "import asyncio, mavstack.aio as aio\n"
        "async def main():\n"
        "    gcs = await aio.connect('udpin:127.0.0.1:%d')\n"
        "    v = await gcs.vehicle(timeout=10)\n"
        "    s = v.telemetry('ATTITUDE', rate_hz=500)\n"
        "    for _ in range(50):\n"
        "        await s.__anext__()\n"
        "    asyncio.ensure_future(v.params.get_all(via='list'))\n"
        "    print('left open', flush=True)\n"
        "asyncio.run(main())\n" % port)
    with Vehicle("udpout:127.0.0.1:%d" % port):
        p = subprocess.run([sys.executable, example, "udpin:127.0.0.1:%d" % port],
                           capture_output=True, text=True, timeout=60)
        assert p.returncode == 0, (p.returncode, p.stdout, p.stderr)
        lines = p.stdout.splitlines()
        assert lines[0] == "vehicle 1 autopilot 3" and "arm: ACCEPTED" in lines
        assert lines[-1] == "NO_SUCH_PARAM: no answer"
        p = subprocess.run([sys.executable, "-c", left_open], capture_output=True, text=True, timeout=60)
        assert (p.returncode, p.stdout) == (0, "left open\n"), (p.returncode, p.stdout, p.stderr)


def test_a_signed_link_with_the_key_and_without_it():
    """`key=` signs the link: a vehicle that accepts only signed frames answers; with another
    key its frames are refused and it is never found."""
    key = "5c" * 16 + "a3" * 16
    port = free_port()

    async def session():
        async with aio.connect("udpin:127.0.0.1:%d" % port, key=key) as gcs:
            vehicle = await gcs.vehicle(timeout=10)
            assert await vehicle.params.get("MAV_SYSID") == 1
            assert str(await vehicle.command("REQUEST_MESSAGE", 148)) == "ACCEPTED"
        async with aio.connect("udpin:127.0.0.1:%d" % port, key="11" * 32) as gcs:
            with pytest.raises(aio.TimeoutError):
                await gcs.vehicle(timeout=1.5)

    with Vehicle("udpout:127.0.0.1:%d" % port, "--sign-key", key):
        run(session())


def test_a_slow_handler_runs_once_and_its_retries_hear_in_progress():
    """A handler slower than the client's retry timeout: the retries are answered IN_PROGRESS
    by the stack (never handed to the handler again), and the final ACK ends the command.
    The handler waits for an event set only after the client has sent the command again."""
    port = free_port()
    calls = []

    async def session():
        gate = asyncio.Event()

        async def handler(request):
            calls.append(request.command)
            await gate.wait()
            return "ACCEPTED"

        async with aio.serve("udpin:127.0.0.1:%d" % port, system=9, component=191,
                             on_command=handler, autopilot=0, mav_type=2):
            async with aio.connect("udpout:127.0.0.1:%d" % port) as gcs:
                comp = await gcs.vehicle(timeout=10, system=9)
                acks = comp.telemetry("COMMAND_ACK")
                # The raw COMMAND_ACKs the ground station receives, in order.
                command = asyncio.ensure_future(comp.command(31000, 1))
                first = await acks.__anext__()
                gate.set()
                result = await command
                return calls, first, result

    calls_seen, first, result = run(session())
    assert str(result) == "ACCEPTED"
    assert calls_seen == [31000]
    # The first ACK that came was IN_PROGRESS, answering a retry (result 5).
    assert (first.command, first.result) == (31000, 5)


def test_import_mavstack_then_mavstack_aio():
    """`import mavstack` does not import asyncio; `mavstack.aio` is there on first use."""
    code = ("import sys, mavstack\n"
            "assert 'mavstack.aio' not in sys.modules\n"
            "assert mavstack.aio.connect is sys.modules['mavstack.aio'].connect\n"
            "try:\n"
            "    mavstack.nothing\n"
            "except AttributeError as e:\n"
            "    print(e)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30)
    assert (p.returncode, p.stdout) == (0, "module 'mavstack' has no attribute 'nothing'\n"), p.stderr
