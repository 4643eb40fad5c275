"""Supervision shared by every exciter back end (drivers/exciter/interface.py), on Modbus and on CAN:
the keep-alive goes out only after a status read that passed its checks, a reported breach of the
envelope gets the driver's own emergency stop, and closing falls back to an emergency stop. Closing with the
plate moving, on every back end: test_exciter_contract.py."""

from __future__ import annotations

import asyncio
import dataclasses
import uuid
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from typing import Literal

import pytest

from drivers.exciter.can_bus import CanExciter
from drivers.exciter.codes import CommandCode, ExciterState
from drivers.exciter.errors import EnvelopeBreachError, ExciterDeviceExceptionError
from drivers.exciter.interface import ExciterStatus, PlateExciter
from drivers.exciter.modbus import ModbusExciter, ModbusTcpLink
from estimator.sweep import SweepSettings
from simulators.devices.can_exciter import SimulatedCanExciter
from simulators.devices.exciter import SimulatedExciter
from simulators.devices.modbus_exciter import SimulatedModbusExciter
from simulators.plate import EmptyPlate

SWEEP = SweepSettings(start_Hz=0.0, stop_Hz=20.0, amplitude_m=0.004, duration_s=20.0)
TIMEOUT_S = 0.3
Backend = Literal["modbus", "can"]
BACKENDS: list[Backend] = ["modbus", "can"]


@dataclasses.dataclass
class Rig:
    """A simulated exciter and a driver on the same simulated clock, whichever protocol."""

    simulated: SimulatedExciter
    exciter: PlateExciter
    advance: Callable[[float], None]
    modbus: SimulatedModbusExciter | None = None


@asynccontextmanager
async def rig(backend: Backend) -> AsyncIterator[Rig]:
    bench = EmptyPlate()
    if backend == "modbus":
        async with SimulatedModbusExciter(bench) as sim:
            exciter = ModbusExciter(
                ModbusTcpLink(sim.host, sim.port), timeout_s=TIMEOUT_S, clock=bench.clock.now_s
            )
            async with exciter:
                yield Rig(sim.exciter, exciter, sim.advance, sim)
        return
    channel = f"supervision-{uuid.uuid4().hex}"
    with SimulatedCanExciter(bench, channel=channel) as can_sim:
        can_sim.tick()
        exciter = CanExciter("virtual", channel, reply_timeout_s=TIMEOUT_S, clock=bench.clock.now_s)
        async with exciter:
            yield Rig(can_sim.exciter, exciter, can_sim.advance)


async def keepalives_received(r: Rig) -> int:
    """Keep-alives the drive has handled. On CAN the keep-alive is a frame without an answer: one plain
    status exchange first (no supervision step), since the bus delivers frames in order."""
    await r.exciter._read_status()
    return r.simulated.keepalives_received


async def running(r: Rig) -> None:
    await r.exciter.configure_sweep(SWEEP)
    await r.exciter.start()
    r.advance(0.25)


@pytest.mark.parametrize("backend", BACKENDS)
def test_keepalive_only_after_a_status_read_that_passed_its_checks(backend: Backend) -> None:
    async def scenario() -> None:
        async with rig(backend) as r:
            await r.exciter.status()  # no sweep running: no keep-alive
            await r.exciter.configure_sweep(SWEEP)
            assert await keepalives_received(r) == 0
            await r.exciter.start()
            assert await keepalives_received(r) == 0  # START arms the watchdog; the first feed comes later
            r.advance(0.25)
            await r.exciter.supervise()
            assert await keepalives_received(r) == 1

            def refuse(status: ExciterStatus) -> None:
                assert status.state is ExciterState.RUNNING  # the check sees the fresh status
                raise RuntimeError("the host's own check failed")

            r.advance(0.25)
            with pytest.raises(RuntimeError, match="own check failed"):
                await r.exciter.supervise(refuse)
            assert await keepalives_received(r) == 1  # refused: nothing fed the watchdog
            r.advance(0.3)  # 0.55 s since the last feed: the watchdog trips
            status = await r.exciter.status()
            assert r.simulated.watchdog_tripped and status.state is ExciterState.STOPPING

    asyncio.run(scenario())


def test_a_failed_status_read_sends_no_keepalive() -> None:
    async def scenario() -> None:
        async with rig("modbus") as r:
            await running(r)
            assert r.modbus is not None
            r.modbus.inject_exception(4)
            with pytest.raises(ExciterDeviceExceptionError):
                await r.exciter.supervise()
            assert await keepalives_received(r) == 0
            assert [address for address, _ in r.modbus.writes].count(1) == 0  # register 1: keep-alive
            await r.exciter.supervise()  # the next good read feeds it again
            assert await keepalives_received(r) == 1

    asyncio.run(scenario())


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_reported_breach_gets_an_emergency_stop_from_the_driver(backend: Backend) -> None:
    async def scenario() -> None:
        async with rig(backend) as r:
            await running(r)
            await r.exciter.supervise()
            honest = r.simulated.status
            r.simulated.status = lambda: dataclasses.replace(honest(), position_m=-0.0045)  # type: ignore[method-assign]
            with pytest.raises(EnvelopeBreachError) as info:
                await r.exciter.supervise()
            assert info.value.quantity == "position_m" and info.value.stopped
            assert "position_m=0.0045" in str(info.value) and "max_amplitude_m=0.004" in str(info.value)
            assert r.simulated.commands[-1] is CommandCode.EMERGENCY_STOP
            assert not r.exciter.supervising
            r.simulated.status = honest  # type: ignore[method-assign]
            fed = await keepalives_received(r)
            r.advance(0.25)
            assert (await r.exciter.supervise()).state is ExciterState.IDLE  # halted
            assert await keepalives_received(r) == fed

    asyncio.run(scenario())


def test_closing_falls_back_to_an_emergency_stop_and_a_stopped_plate_is_left_alone() -> None:
    async def scenario() -> None:
        async with rig("modbus") as r:
            assert r.modbus is not None
            await running(r)
            r.modbus.inject_exception(4)  # the stop command is refused before the drive sees it
            await r.exciter.close()
            assert r.simulated.commands == [CommandCode.START, CommandCode.EMERGENCY_STOP]
            assert r.simulated.bench.plate_status().state == "idle"  # halted at once
        async with rig("modbus") as r:
            await running(r)
            await r.exciter.stop()
            await r.exciter.close()
            assert r.simulated.commands == [CommandCode.START, CommandCode.STOP]  # nothing more on close

    asyncio.run(scenario())
