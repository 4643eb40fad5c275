"""CAN back end on python-can's virtual bus: the DBC frame set, the sweep and keep-alive as frames, heartbeat
supervision, bus errors, the drive's refusals, reader failures. What every back end promises (start, sweep,
stops, watchdog, drive faults, silence): test_exciter_contract.py."""

from __future__ import annotations

import asyncio
import threading
import uuid
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import can
import pytest
from can.interfaces.virtual import VirtualBus

from drivers.exciter import can_frames as frames
from drivers.exciter.can_bus import CanExciter
from drivers.exciter.can_frames import CanResult, ExciterFrames, canopen_conflicts
from drivers.exciter.codes import CommandCode, ExciterState, LawCode, StateCode
from drivers.exciter.errors import (
    ExciterBusError,
    ExciterConfigError,
    ExciterConnectionLostError,
    ExciterDeviceExceptionError,
    ExciterDeviceFaultError,
    ExciterEncodingError,
    ExciterHeartbeatLostError,
)
from drivers.exciter.urls import CanTarget, open_exciter, parse_exciter_url
from estimator.sweep import SweepLaw, SweepSettings
from simulators.devices.can_exciter import SimulatedCanExciter
from simulators.plate import EmptyPlate

SWEEP = SweepSettings(start_Hz=0.0, stop_Hz=20.0, amplitude_m=0.004, duration_s=20.0)
REPLY_TIMEOUT_S = 0.2


def fresh_channel() -> str:
    """A virtual CAN channel of its own, so tests never hear each other."""
    return f"exciter-test-{uuid.uuid4().hex}"


@asynccontextmanager
async def can_rig(**sim_kwargs: object) -> AsyncIterator[tuple[SimulatedCanExciter, CanExciter]]:
    """Simulated drive and driver on one virtual channel, the driver supervising on the simulated clock."""
    bench = EmptyPlate()
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
    assert msg.arbitration_id == 0x688 and len(msg.data) == 8
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


def test_default_frame_ids_avoid_canopen_and_a_base_id_moves_the_whole_set() -> None:
    default = ExciterFrames().frame_ids
    assert default == {
        frames.COMMAND: 0x680,
        frames.SWEEP_FREQUENCIES: 0x681,
        frames.SWEEP_SHAPE: 0x682,
        frames.HOST_KEEPALIVE: 0x683,
        frames.STATUS: 0x688,
        frames.HEARTBEAT: 0x689,
    }
    assert canopen_conflicts(default) == {}
    # the first frame set's ids were node 1's TPDO1, RPDO1 and heartbeat: the check names them
    assert canopen_conflicts({"old status": 0x181, "old sweep": 0x201, "old heartbeat": 0x701}) == {
        "old status": "PDOs",
        "old sweep": "PDOs",
        "old heartbeat": "NMT error control (heartbeat)",
    }
    moved = ExciterFrames(base_id=0x6A0)
    assert moved.frame_ids == {name: frame_id - 0x680 + 0x6A0 for name, frame_id in default.items()}
    msg = moved.encode(frames.COMMAND, {"Command": CommandCode.START, "Sequence": 3})
    assert msg.arbitration_id == 0x6A0
    assert moved.decode(msg) == (frames.COMMAND, {"Command": 1.0, "Sequence": 3.0})
    assert ExciterFrames().decode(msg) is None  # the default set does not know 0x6A0
    with pytest.raises(ExciterConfigError, match=r"0x7FC\.\.0x805"):
        ExciterFrames(base_id=0x7FC)


def test_can_urls() -> None:
    assert parse_exciter_url("can://virtual/vcan0") == CanTarget("virtual", "vcan0")
    assert parse_exciter_url("can://socketcan/can0?bitrate=500000&timeout=0.1&heartbeat_timeout=0.3") == (
        CanTarget("socketcan", "can0", 500000, 0.1, 0.3)
    )
    assert parse_exciter_url("can://virtual/vcan0?base_id=0x6a0").base_id == 0x6A0  # type: ignore[union-attr]
    assert parse_exciter_url("can://virtual/vcan0?base_id=1700").base_id == 1700  # type: ignore[union-attr]
    with pytest.raises(ExciterConfigError, match="base_id must be a CAN id such as 0x680, got 'x'"):
        parse_exciter_url("can://virtual/vcan0?base_id=x")
    with pytest.raises(ExciterConfigError, match="base_id must be an 11-bit CAN id"):
        parse_exciter_url("can://virtual/vcan0?base_id=0x800")
    with pytest.raises(ExciterConfigError, match="can://<python-can interface>/<channel>"):
        parse_exciter_url("can://virtual")
    with pytest.raises(ExciterConfigError, match=r"unknown parameter\(s\) \['baud'\]"):
        parse_exciter_url("can://virtual/vcan0?baud=1")


# ---- sweeps as frames --------------------------------------------------------------------------------------


def test_the_sweep_and_the_keepalive_go_out_as_the_dbc_frames_on_a_bus_opened_from_a_url() -> None:
    """The frame set's side of a sweep (the cycle itself: test_exciter_contract.py)."""

    async def scenario() -> None:
        bench = EmptyPlate()
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
                for _ in range(4):
                    sim.advance(0.25)
                    status = await exciter.status()
                assert status.state is ExciterState.RUNNING
                assert exciter.heartbeat_counter == (sim.heartbeats_sent - 1) & 0xFF
                assert any(name == "EXC_HostKeepAlive" for name, _ in sim.received)
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
            sim.exciter.clock.advance(0.7)  # time passes, no tick: no heartbeat goes out
            with pytest.raises(ExciterHeartbeatLostError):
                await exciter.status()
            sim.tick()
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


def test_the_drives_own_refusal_in_fault_is_a_typed_fault() -> None:
    """Past the interface's pre-check (test_exciter_contract.py), the drive's own refusal is the same type."""

    async def scenario() -> None:
        async with can_rig() as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            sim.inject_drive_fault(0x0123)
            with pytest.raises(ExciterDeviceFaultError) as info:
                await exciter._send_command(CommandCode.START)
            assert info.value.fault_code == 0x0123

    asyncio.run(scenario())


def test_drive_refusal_without_fault_is_a_device_exception() -> None:
    async def scenario() -> None:
        async with can_rig() as (_, exciter):
            with pytest.raises(ExciterDeviceExceptionError) as info:
                await exciter._send_command(CommandCode.START)  # no sweep written to the drive yet
            assert info.value.exception_code == CanResult.NOT_CONFIGURED
            assert (await exciter.status()).state is ExciterState.IDLE

    asyncio.run(scenario())


def test_moved_frame_set_from_a_url_talks_to_a_drive_on_the_same_base() -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        channel = fresh_channel()
        with SimulatedCanExciter(bench, channel=channel, base_id=0x6C0) as sim:
            sim.tick()
            url = f"can://virtual/{channel}?timeout={REPLY_TIMEOUT_S}&base_id=0x6C0"
            exciter = await open_exciter(url, clock=bench.clock.now_s)
            try:
                assert (await exciter.status()).state is ExciterState.IDLE
                assert sim.received == [(frames.COMMAND, {"Command": 0.0, "Sequence": 1.0})]
            finally:
                await exciter.close()

    asyncio.run(scenario())


# ---- reader failure and reopening ---------------------------------------------------------------------


class _FailingReadBus(VirtualBus):
    """A virtual bus whose reader can be made to fail once, as a socket that goes away would."""

    def __init__(self, channel: str) -> None:
        super().__init__(channel=channel)
        self.fail_next_read = threading.Event()

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.fail_next_read.is_set():
            self.fail_next_read.clear()
            raise can.CanOperationError("interface went down")
        return super()._recv_internal(timeout)


class _RigExciter(CanExciter):
    """A CanExciter on buses the test keeps hold of."""

    def __init__(self, make: type[VirtualBus], *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self._make = make
        self.buses: list[VirtualBus] = []

    def _make_bus(self) -> can.BusABC:
        self.buses.append(self._make(self.channel))
        return self.buses[-1]


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_reader_error_fails_the_call_then_a_new_bus_is_opened() -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        channel = fresh_channel()
        with SimulatedCanExciter(bench, channel=channel) as sim:
            sim.tick()
            exciter = _RigExciter(
                _FailingReadBus, "virtual", channel, reply_timeout_s=REPLY_TIMEOUT_S, clock=bench.clock.now_s
            )
            async with exciter:
                assert (await exciter.status()).state is ExciterState.IDLE
                sim.go_silent()  # the request below stays unanswered until the reader has failed
                exciter.buses[0].fail_next_read.set()
                with pytest.raises(ExciterConnectionLostError, match="reader stopped: interface went down"):
                    await exciter.status()
                sim.resume()
                # the next call reopens: old bus shut down, a new one made, the error cleared
                assert (await exciter.status()).state is ExciterState.IDLE
                assert len(exciter.buses) == 2 and exciter.buses[0]._open is False
                assert exciter._reader_error is None

                exciter.buses[1].fail_next_read.set()
                sim.go_silent()
                with pytest.raises(ExciterConnectionLostError):
                    await exciter.status()
                sim.resume()
                await exciter.open()  # an explicit open() after the error makes a new bus too
                assert len(exciter.buses) == 3 and exciter.buses[1]._open is False
                await exciter.configure_sweep(SWEEP)
                assert sim.exciter._params["duration_s"] == SWEEP.duration_s
                await exciter.open()  # a healthy bus is kept
                assert len(exciter.buses) == 3

    asyncio.run(scenario())


# ---- sending does not block the event loop -----------------------------------------------------------------


class _BlockingSendBus(VirtualBus):
    """A virtual bus whose send blocks until the test releases it (a full transmit queue)."""

    def __init__(self, channel: str) -> None:
        super().__init__(channel=channel)
        self.send_entered = threading.Event()
        self.release = threading.Event()
        self.released_by_test: bool | None = None

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.send_entered.set()
        self.released_by_test = self.release.wait(5.0)  # bounded: a blocked loop fails the test, not hangs
        super().send(msg, timeout)


def test_a_blocked_send_leaves_the_event_loop_running() -> None:
    async def scenario() -> None:
        channel = fresh_channel()
        with can.Bus(interface="virtual", channel=channel) as listener:
            exciter = _RigExciter(_BlockingSendBus, "virtual", channel, keepalive_interval_s=None)
            async with exciter:
                bus = exciter.buses[0]
                keepalive = asyncio.get_running_loop().create_task(exciter._send_keepalive(1))
                await asyncio.to_thread(bus.send_entered.wait, 5.0)
                ticks = 0
                for _ in range(20):  # the loop keeps running other work while the send is blocked
                    await asyncio.sleep(0)
                    ticks += 1
                assert ticks == 20 and not keepalive.done()
                bus.release.set()
                await keepalive
                assert bus.released_by_test is True
            frame = listener.recv(timeout=2.0)
            assert frame is not None
            assert ExciterFrames().decode(frame) == (frames.HOST_KEEPALIVE, {"Counter": 1.0})

    asyncio.run(scenario())
