"""The contract every plate exciter back end keeps, one test per promise, run on each: Modbus TCP, CAN (the
bench's own frame set) and CiA 402 (CANopen), each against its simulated drive on its real transport
(loopback TCP, python-can's virtual bus) and on the drive's simulated clock.

Promised: a written sweep starts, runs as written and is supervised; a controlled stop brings the plate to
rest; an emergency stop halts it at once and holds it; a host that stops supervising is stopped by the
drive's watchdog, which latches a fault; a drive fault refuses a start until reset; a silent drive is a
typed timeout and the link recovers when it answers again; closing with the plate moving stops it.

What only one back end has (register maps, the DBC, heartbeats, CiA 402 state transitions, Modbus exception
codes, reconnection) stays in test_exciter_modbus.py, test_exciter_can.py, test_exciter_cia402.py and
test_exciter_cia402_transitions.py; the envelope and keep-alive logic they share, in
test_exciter_supervision.py.
"""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass

import pytest

from drivers.exciter import cia402_objects as objects
from drivers.exciter.can_bus import CanExciter
from drivers.exciter.codes import FAULT_WATCHDOG, ExciterState, ExciterStatus
from drivers.exciter.errors import ExciterDeviceFaultError, ExciterTimeoutError
from drivers.exciter.interface import PlateExciter
from drivers.exciter.modbus import ModbusExciter, ModbusTcpLink
from drivers.interfaces import Exciter
from estimator.sweep import SweepSettings
from simulators.devices.can_exciter import SimulatedCanExciter
from simulators.devices.modbus_exciter import SimulatedModbusExciter
from simulators.plate import CONTROLLED_STOP_RAMP_S, EmptyPlate
from tests.drivers import cia402_rig

SWEEP = SweepSettings(start_Hz=0.0, stop_Hz=20.0, amplitude_m=0.004, duration_s=20.0)
"""0 to 20 Hz in 20 s: the frequency in Hz is the seconds since the start."""
REPLY_TIMEOUT_S = 0.2
"""The hosts' reply timeout (real time: a silent drive costs the test this long)."""
DRIVE_FAULT = 0x7310
BACKENDS = ["modbus", "can", "cia402"]


@dataclass
class Rig:
    """One back end and its simulated drive, on the plate's simulated clock, seen the same way."""

    exciter: PlateExciter
    plate: EmptyPlate
    advance: Callable[[float], None]
    """Simulated time passes: the drive does its cyclic work (watchdog, heartbeats, the plate moves)."""
    inject_drive_fault: Callable[[int], None]
    silence: Callable[[], None]
    """The drive stops answering (at least the next request)."""
    resume: Callable[[], None]
    watchdog_fault: int
    """The fault code the drive's watchdog latches."""

    def now_s(self) -> float:
        return self.plate.clock.now_s()

    async def run_for(self, duration_s: float, step_s: float = 0.1) -> ExciterStatus:
        """Let duration_s pass in steps, supervising after each as a host cycle does."""
        end_s = self.now_s() + duration_s
        status = await self.exciter.supervise()
        while self.now_s() < end_s - 1e-9:
            self.advance(min(step_s, end_s - self.now_s()))
            status = await self.exciter.supervise()
        return status


def _nothing() -> None:
    """Nothing to undo: a Modbus drive that lost one answer answers the next request again."""


@asynccontextmanager
async def rig(backend: str) -> AsyncIterator[Rig]:
    if backend == "modbus":
        plate = EmptyPlate()
        async with SimulatedModbusExciter(plate) as modbus:
            link = ModbusTcpLink(modbus.host, modbus.port)
            async with ModbusExciter(link, timeout_s=REPLY_TIMEOUT_S, clock=plate.clock.now_s) as exciter:
                yield Rig(
                    exciter,
                    plate,
                    modbus.advance,
                    modbus.inject_drive_fault,
                    modbus.drop_responses,
                    _nothing,
                    FAULT_WATCHDOG,
                )
    elif backend == "can":
        plate = EmptyPlate()
        with SimulatedCanExciter(plate, channel=f"contract-{uuid.uuid4().hex}") as can:
            can.tick()  # the first heartbeat
            exciter = CanExciter(
                "virtual", can.channel, reply_timeout_s=REPLY_TIMEOUT_S, clock=plate.clock.now_s
            )
            async with exciter:
                yield Rig(
                    exciter,
                    plate,
                    can.advance,
                    can.inject_drive_fault,
                    can.go_silent,
                    can.resume,
                    FAULT_WATCHDOG,
                )
    else:
        async with cia402_rig.rig() as (cia402, exciter):  # its reply timeout: cia402_rig.REPLY_TIMEOUT_S
            plate = cia402.bench
            assert isinstance(plate, EmptyPlate)
            yield Rig(
                exciter,
                plate,
                cia402.advance,
                cia402.inject_drive_fault,
                cia402.go_silent,
                cia402.resume,
                objects.ERROR_HEARTBEAT,
            )


def on_each(scenario: Callable[[Rig], Awaitable[None]]) -> Callable[[str], None]:
    """A contract test: `scenario` on the back end pytest passes."""

    def test(backend: str) -> None:
        async def main() -> None:
            async with rig(backend) as r:
                assert isinstance(r.exciter, Exciter)  # what daq talks to (drivers/interfaces.py)
                await scenario(r)

        asyncio.run(main())

    test.__doc__ = scenario.__doc__
    return pytest.mark.parametrize("backend", BACKENDS)(test)


async def _started(r: Rig) -> float:
    """Write SWEEP and start it; returns when it started (simulated s)."""
    await r.exciter.configure_sweep(SWEEP)
    await r.exciter.start()
    return r.now_s()


# ---- start, sweep, stop --------------------------------------------------------------------------------


async def _start_sweep_and_stop(r: Rig) -> None:
    """The sweep runs as written, supervision keeps it running, a controlled stop brings the plate to rest."""
    assert (await r.exciter.status()) == ExciterStatus(ExciterState.IDLE, 0, 0.0, 0.0)
    started_s = await _started(r)
    for _ in range(3):
        status = await r.run_for(1.5)  # 4.5 s in all: far past the drive's watchdog timeout
        assert status.state is ExciterState.RUNNING and status.fault_code == 0
        assert status.frequency_Hz == pytest.approx(r.now_s() - started_s, abs=0.01)  # 0-20 Hz in 20 s
        assert status.position_m == pytest.approx(r.plate.position_m("x_r"), abs=1e-6)
    assert r.exciter.supervising
    await r.exciter.stop()
    assert not r.exciter.supervising
    rest = await r.run_for(CONTROLLED_STOP_RAMP_S + 0.1)
    assert (rest.state, rest.fault_code, rest.position_m) == (ExciterState.IDLE, 0, 0.0)
    assert r.plate.plate_status().state == "idle"
    await _started(r)  # and it starts again
    assert (await r.run_for(0.3)).state is ExciterState.RUNNING


test_start_sweep_and_stop = on_each(_start_sweep_and_stop)


async def _emergency_stop(r: Rig) -> None:
    """An emergency stop halts the plate where it is, at once, and holds it there; no fault is latched."""
    await _started(r)
    moving = await r.run_for(0.3)
    assert moving.state is ExciterState.RUNNING and moving.position_m != 0.0
    await r.exciter.emergency_stop()
    halted = await r.exciter.status()
    assert (halted.state, halted.fault_code) == (ExciterState.IDLE, 0) and halted.position_m != 0.0
    held = await r.run_for(0.5)
    assert held.position_m == halted.position_m and held.state is ExciterState.IDLE
    await _started(r)
    assert (await r.run_for(0.3)).state is ExciterState.RUNNING


test_emergency_stop = on_each(_emergency_stop)


# ---- the drive's watchdog ----------------------------------------------------------------------------------


async def _watchdog(r: Rig) -> None:
    """A host that stops supervising is stopped by the drive: a controlled stop, then a latched fault that
    refuses a start until reset."""
    await _started(r)
    assert (await r.run_for(2.0)).state is ExciterState.RUNNING
    r.advance(0.6)  # the host says nothing for longer than the watchdog's 0.5 s
    status = await r.exciter.status()
    assert (status.state, status.fault_code) == (ExciterState.STOPPING, r.watchdog_fault)
    r.advance(0.6)
    status = await r.exciter.status()
    assert (status.state, status.fault_code, status.position_m) == (ExciterState.FAULT, r.watchdog_fault, 0.0)
    with pytest.raises(ExciterDeviceFaultError):
        await r.exciter.start()
    await r.exciter.reset_fault()
    await r.exciter.start()
    assert (await r.run_for(0.3)).state is ExciterState.RUNNING


test_watchdog = on_each(_watchdog)


# ---- faults ------------------------------------------------------------------------------------------------


async def _drive_fault(r: Rig) -> None:
    """A drive fault is reported (not raised) by a status read, refuses a start, and a reset clears it."""
    await _started(r)
    await r.run_for(0.5)
    r.inject_drive_fault(DRIVE_FAULT)
    status = await r.exciter.status()
    assert (status.state, status.fault_code) == (ExciterState.FAULT, DRIVE_FAULT)
    with pytest.raises(ExciterDeviceFaultError) as info:
        await r.exciter.start()
    assert info.value.fault_code == DRIVE_FAULT
    await r.exciter.reset_fault()
    assert (await r.exciter.status()).fault_code == 0
    await r.exciter.start()
    assert (await r.run_for(0.3)).state is ExciterState.RUNNING


test_drive_fault = on_each(_drive_fault)


async def _drive_refuses_start_in_fault(r: Rig) -> None:
    """A drive that trips after the host's status check refuses START itself; every back end raises that
    as a drive fault with the drive's code (a Modbus drive answers with an exception code, CAN with
    REJECTED_FAULT, CiA 402 shows it in its state), and the plate stays at rest."""
    await r.exciter.configure_sweep(SWEEP)
    healthy = await r.exciter.status()
    r.inject_drive_fault(DRIVE_FAULT)
    read_status, reads = r.exciter.status, []

    async def status_tripping_after_first_read() -> ExciterStatus:
        reads.append(r.now_s())
        return healthy if len(reads) == 1 else await read_status()

    r.exciter.status = status_tripping_after_first_read  # type: ignore[method-assign]
    with pytest.raises(ExciterDeviceFaultError) as info:
        await r.exciter.start()
    assert info.value.fault_code == DRIVE_FAULT and len(reads) >= 1
    r.exciter.status = read_status  # type: ignore[method-assign]
    status = await r.run_for(0.3)
    assert (status.state, status.fault_code, status.position_m) == (ExciterState.FAULT, DRIVE_FAULT, 0.0)


test_drive_refuses_start_in_fault = on_each(_drive_refuses_start_in_fault)


async def _silent_drive(r: Rig) -> None:
    """A drive that does not answer is a timeout, within the heartbeat supervision; then the link recovers."""
    await r.exciter.status()
    r.silence()
    with pytest.raises(ExciterTimeoutError):
        await r.exciter.status()
    r.resume()
    r.advance(0.1)
    assert (await r.exciter.status()).state is ExciterState.IDLE


test_silent_drive = on_each(_silent_drive)


async def _closing_while_moving(r: Rig) -> None:
    """Closing with the plate moving stops it with a controlled stop: the plate ramps down, then rests."""
    await _started(r)
    await r.run_for(0.3)
    assert r.plate.plate_status().state == "running"
    closed_at_s = r.now_s()
    await r.exciter.close()
    while r.plate.plate_status().state != "idle":
        assert r.now_s() - closed_at_s < CONTROLLED_STOP_RAMP_S + 0.1, "the plate did not come to rest"
        r.advance(0.01)
    assert r.now_s() - closed_at_s >= CONTROLLED_STOP_RAMP_S - 0.02  # the ramp down, not an emergency halt


test_closing_while_moving = on_each(_closing_while_moving)
