"""bench_ops.py's timing of one step (`python -m pytest tests-interop/test_bench_ops.py`): no
vehicle, no sockets."""
import asyncio
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_ops import timed  # noqa: E402


def test_a_tools_own_timeout_error_is_a_failure_not_the_callers_timeout():
    # What mavstack.aio raises when a parameter list stays incomplete: a builtins.TimeoutError.
    async def gives_up():
        raise TimeoutError("parameter list: 10 of 20 parameters never arrived")

    out = asyncio.run(timed(gives_up(), 60))
    assert out.startswith("failed after ") and "10 of 20 parameters never arrived" in out, out


def test_a_step_still_running_at_the_timeout_is_timed_out():
    async def never_ends():
        await asyncio.Event().wait()

    assert asyncio.run(timed(never_ends(), 0.01)) == "timed out"


def test_a_step_that_ends_gives_its_seconds():
    async def ends():
        return 1

    assert isinstance(asyncio.run(timed(ends(), 60)), float)
