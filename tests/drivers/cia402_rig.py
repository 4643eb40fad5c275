"""The CiA 402 test rig: the simulated drive and the back end on one virtual CAN channel, supervision and
the back end's waits on the simulated clock (its sleeps advance it: nothing sleeps, nothing is flaky)."""

from __future__ import annotations

import asyncio
import time
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import Any

from drivers.exciter import cia402_objects as objects
from drivers.exciter.cia402 import Cia402Exciter
from drivers.exciter.cia402_objects import DriveState
from estimator.sweep import SweepSettings
from simulators.devices.cia402_exciter import SimulatedCia402Exciter
from simulators.plate import EmptyPlate

SWEEP = SweepSettings(start_Hz=0.0, stop_Hz=20.0, amplitude_m=0.004, duration_s=20.0)
REPLY_TIMEOUT_S = 0.2
NODE = 5
HALT = objects.CW_ENABLE_OPERATION | objects.CW_HALT
START = objects.CW_ENABLE_OPERATION | objects.CW_START_SWEEP


def fresh_channel() -> str:
    return f"cia402-test-{uuid.uuid4().hex}"


def sim_sleep(sim: SimulatedCia402Exciter) -> Callable[[float], Awaitable[None]]:
    """The back end's wait between polls: simulated time passes (the drive ticks), nothing sleeps."""

    async def sleep(dt_s: float) -> None:
        sim.advance(dt_s)
        await asyncio.sleep(0)

    return sleep


@asynccontextmanager
async def rig(
    drive: dict[str, Any] | None = None, **exciter_kwargs: Any
) -> AsyncIterator[tuple[SimulatedCia402Exciter, Cia402Exciter]]:
    """Simulated drive (`drive`: its keyword arguments) and back end on one virtual channel, supervision
    and waits on the simulated clock."""
    bench = EmptyPlate()
    channel = fresh_channel()
    with SimulatedCia402Exciter(bench, channel=channel, node_id=NODE, **(drive or {})) as sim:
        exciter = Cia402Exciter(
            "virtual",
            channel,
            node_id=NODE,
            reply_timeout_s=REPLY_TIMEOUT_S,
            clock=bench.clock.now_s,
            sleep=sim_sleep(sim),
            **exciter_kwargs,
        )
        async with exciter:
            yield sim, exciter


def entered_at(sim: SimulatedCia402Exciter, state: DriveState) -> float:
    """When the drive last entered `state` (its own timeline)."""
    return max(time_s for time_s, entered in sim.timeline if entered is state)


def states(sim: SimulatedCia402Exciter) -> list[DriveState]:
    return [state for _, state in sim.timeline]


def wait_until(condition: Callable[[], bool], what: str, timeout_s: float = 2.0) -> None:
    """Poll with a deadline for something the drive's reader thread does."""
    deadline_s = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline_s, f"timed out waiting for {what}"
        time.sleep(0.001)


def stored(sim: SimulatedCia402Exciter, index: int, subindex: int = 0) -> int:
    """A value the host wrote into the drive's object dictionary."""
    entry = sim.node.sdo[index]
    value = (entry[subindex] if subindex else entry).raw
    assert isinstance(value, int)
    return value
