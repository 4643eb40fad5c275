"""CAN back end: DBC frame set, full cycle on python-can's virtual bus, heartbeat supervision, faults."""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest

from drivers.exciter import can_frames as frames
from drivers.exciter.can_bus import CanExciter
from drivers.exciter.can_frames import CanResult, ExciterFrames
from drivers.exciter.codes import FAULT_WATCHDOG, CommandCode, ExciterState, LawCode, StateCode
from drivers.exciter.errors import (
    ExciterBusError,
    ExciterConfigError,
    ExciterDeviceExceptionError,
    ExciterDeviceFaultError,
    ExciterEncodingError,
    ExciterHeartbeatLostError,
    ExciterTimeoutError,
)
from drivers.exciter.sweep import SweepLaw, SweepSettings
from drivers.exciter.urls import CanTarget, open_exciter, parse_exciter_url
from simulators.devices.can_exciter import SimulatedCanExciter
from simulators.plate import PlateOnlyBench

SWEEP = SweepSettings(start_Hz=0.0, stop_Hz=20.0, amplitude_m=0.004, duration_s=20.0)
REPLY_TIMEOUT_S = 0.2


def fresh_channel() -> str:
    """A virtual CAN channel of its own, so tests never hear each other."""
    return f"exciter-test-{uuid.uuid4().hex}"


@asynccontextmanager
async def can_rig(**sim_kwargs: object) -> AsyncIterator[tuple[SimulatedCanExciter, CanExciter]]:
    """Simulated drive and driver on one virtual channel, the driver supervising on the simulated clock."""
    bench = PlateOnlyBench()
    channel = fresh_channel()
    with SimulatedCanExciter(bench, channel=channel, **sim_kwargs) as sim:  # type: ignore[arg-type]
        sim.tick()  # first heartbeat
        exciter = CanExciter(
            "virtual",
            channel,
            reply_timeout_s=REPLY_TIMEOUT_S,
            heartbeat_timeout_s=0.5,
            clock=bench.clock.now_s,
        )
        async with exciter:
            yield sim, exciter


# ---- frame set ------------------------------------------------------------------------------------------


def test_dbc_value_tables_match_the_shared_codes() -> None:
    codec = ExciterFrames()
    assert codec.choices(frames.COMMAND, "Command") == {c.value: c.name for c in CommandCode}
    assert codec.choices(frames.STATUS, "State") == {s.value: s.name for s in StateCode}
    assert codec.choices(frames.HEARTBEAT, "State") == {s.value: s.name for s in StateCode}
    assert codec.choices(frames.SWEEP_FREQUENCIES, "Law") == {c.value: c.name for c in LawCode}
    assert codec.choices(frames.STATUS, "Result") == {r.value: r.name for r in CanResult}


def test_frames_round_trip_with_scaling() -> None:
    codec = ExciterFrames()
    signals = {
        "State": 1,
        "Result": 0,
        "Sequence": 9,
        "FaultCode": 0x10,
        "ActualFrequency": 12.34,
        "ActualPosition": -0.003217,
    }
    msg = codec.encode(frames.STATUS, signals)
    assert msg.arbitration_id == 0x181 and len(msg.data) == 8
    name, decoded = codec.decode(msg)  # type: ignore[misc]
    assert name == frames.STATUS
    assert decoded == pytest.approx(signals)
    shape = codec.decode(
        codec.encode(frames.SWEEP_SHAPE, {"Amplitude": 0.004, "Duration": 20.0, "Sequence": 1})
    )
    assert shape == (frames.SWEEP_SHAPE, pytest.approx({"Amplitude": 0.004, "Duration": 20.0, "Sequence": 1}))
    with pytest.raises(ExciterEncodingError, match="StartFrequency"):
        codec.encode(
            frames.SWEEP_FREQUENCIES, {"StartFrequency": 700.0, "StopFrequency": 1, "Law": 0, "Sequence": 0}
        )


def test_can_urls() -> None:
    assert parse_exciter_url("can://virtual/vcan0") == CanTarget("virtual", "vcan0")
    assert parse_exciter_url("can://socketcan/can0?bitrate=500000&timeout=0.1&heartbeat_timeout=0.3") == (
        CanTarget("socketcan", "can0", 500000, 0.1, 0.3)
    )
    with pytest.raises(ExciterConfigError, match="can://<python-can interface>/<channel>"):
        parse_exciter_url("can://virtual")
    with pytest.raises(ExciterConfigError, match=r"unknown parameter\(s\) \['baud'\]"):
        parse_exciter_url("can://virtual/vcan0?baud=1")


# ---- full cycle --------------------------------------------------------------------------------------------


def test_full_cycle_on_the_virtual_bus_opened_from_a_url() -> None:
    async def scenario() -> None:
        bench = PlateOnlyBench()
        channel = fresh_channel()
        with SimulatedCanExciter(bench, channel=channel) as sim:
            sim.tick()
            exciter = await open_exciter(
                f"can://virtual/{channel}?timeout={REPLY_TIMEOUT_S}", clock=bench.clock.now_s
            )
            try:
                assert isinstance(exciter, CanExciter)
                assert (await exciter.status()).state is ExciterState.IDLE
                await exciter.configure_sweep(SWEEP)
                assert [n for n, _ in sim.received] == [
                    "EXC_Command",
                    "EXC_SweepFrequencies",
                    "EXC_SweepShape",
                ]
                await exciter.start()
                for t_s in (1.0, 2.5, 7.5):
                    while bench.clock.now_s() < t_s - 1e-9:
                        sim.advance(0.25)
                        status = await exciter.status()
                    assert status.state is ExciterState.RUNNING
                    assert status.frequency_Hz == pytest.approx(t_s, abs=0.01)
                    assert status.position_m == pytest.approx(bench.position_m("x_r"), abs=1e-6)
                assert not sim.drive.watchdog_tripped
                assert exciter.heartbeat_counter == (sim.heartbeats_sent - 1) & 0xFF
                assert any(name == "EXC_HostKeepAlive" for name, _ in sim.received)

                await exciter.stop()
                sim.advance(0.2)
                assert (await exciter.status()).state is ExciterState.STOPPING
                sim.advance(0.4)
                assert (await exciter.status()).state is ExciterState.IDLE

                await exciter.start()
                sim.advance(0.3)
                await exciter.emergency_stop()
                halted = await exciter.status()
                assert halted.state is ExciterState.IDLE
                sim.advance(0.3)
                assert (await exciter.status()).position_m == halted.position_m
                assert [c.name for c in sim.drive.commands] == ["START", "STOP", "START", "EMERGENCY_STOP"]
            finally:
                await exciter.close()

    asyncio.run(scenario())


def test_logarithmic_sweep_reaches_the_drive() -> None:
    async def scenario() -> None:
        async with can_rig() as (sim, exciter):
            await exciter.configure_sweep(
                SweepSettings(
                    start_Hz=1.0, stop_Hz=16.0, law=SweepLaw.LOGARITHMIC, duration_s=4.0, amplitude_m=0.002
                )
            )
            await exciter.start()
            sim.advance(0.25)
            await exciter.status()
            sim.advance(0.25)
            assert (await exciter.status()).frequency_Hz == pytest.approx(1.41, abs=0.01)  # 16 ** (0.5 / 4)

    asyncio.run(scenario())


# ---- supervision and injected faults -----------------------------------------------------------------------


def test_heartbeat_loss_is_a_typed_fault_then_recovers() -> None:
    async def scenario() -> None:
        async with can_rig() as (sim, exciter):
            sim.advance(0.3)
            await exciter.status()
            sim.go_silent()
            sim.advance(0.6)
            with pytest.raises(ExciterHeartbeatLostError) as info:
                await exciter.status()
            assert info.value.silent_s == pytest.approx(0.6, abs=0.11)
            sim.resume()
            sim.advance(0.1)
            assert (await exciter.status()).state is ExciterState.IDLE

    asyncio.run(scenario())


def test_heartbeat_supervision_needs_no_reply_timeout_when_the_drive_still_answers() -> None:
    """Heartbeats stale by the clock but the drive answers: still a heartbeat fault (it is the liveness
    contract), reported with the answer, no waiting."""

    async def scenario() -> None:
        async with can_rig() as (sim, exciter):
            sim.drive.clock.advance(0.7)  # time passes, no tick: no heartbeat goes out
            with pytest.raises(ExciterHeartbeatLostError):
                await exciter.status()
            sim.tick()
            await exciter.status()

    asyncio.run(scenario())


def test_silent_drive_within_heartbeat_timeout_is_a_reply_timeout() -> None:
    async def scenario() -> None:
        async with can_rig() as (sim, exciter):
            sim.go_silent()
            with pytest.raises(ExciterTimeoutError):
                await exciter.status()
            sim.resume()
            await exciter.status()

    asyncio.run(scenario())


def test_error_frame_is_a_bus_error_then_recovers() -> None:
    async def scenario() -> None:
        async with can_rig() as (sim, exciter):
            sim.inject_error_frame()
            with pytest.raises(ExciterBusError):
                await exciter.status()
            assert (await exciter.status()).state is ExciterState.IDLE

    asyncio.run(scenario())


def test_drive_fault_refuses_start_until_reset() -> None:
    async def scenario() -> None:
        async with can_rig() as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            sim.advance(0.25)
            await exciter.status()
            sim.inject_drive_fault(0x0123)
            status = await exciter.status()
            assert status.state is ExciterState.FAULT and status.fault_code == 0x0123
            with pytest.raises(ExciterDeviceFaultError) as info:
                await exciter.start()
            assert info.value.fault_code == 0x0123
            # the drive's own refusal, past the driver's pre-check, is the same typed fault
            with pytest.raises(ExciterDeviceFaultError):
                await exciter._send_command(CommandCode.START)
            await exciter.reset_fault()
            await exciter.start()
            assert (await exciter.status()).state is ExciterState.RUNNING

    asyncio.run(scenario())


def test_drive_refusal_without_fault_is_a_device_exception() -> None:
    async def scenario() -> None:
        async with can_rig() as (_, exciter):
            with pytest.raises(ExciterDeviceExceptionError) as info:
                await exciter._send_command(CommandCode.START)  # no sweep written to the drive yet
            assert info.value.exception_code == CanResult.NOT_CONFIGURED
            assert (await exciter.status()).state is ExciterState.IDLE

    asyncio.run(scenario())


def test_watchdog_over_can() -> None:
    async def scenario() -> None:
        async with can_rig(watchdog_timeout_s=0.5) as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            sim.advance(0.3)
            await exciter.status()
            sim.advance(0.6)  # the host says nothing
            status = await exciter.status()
            assert (status.state, status.fault_code) == (ExciterState.STOPPING, FAULT_WATCHDOG)
            sim.advance(0.5)
            assert (await exciter.status()).state is ExciterState.FAULT

    asyncio.run(scenario())
