"""The device interfaces (drivers/interfaces.py) and the in-process mocks (drivers/mock.py): the drivers and
the mocks have every member daq uses; a mock reports what it was scripted to and records what it was
asked; the mock exciter keeps the real envelope and supervision logic of PlateExciter."""

from __future__ import annotations

import asyncio
import inspect
import math
import uuid

import pytest

from drivers.compowayf.amplifier import ZxlAmplifier
from drivers.compowayf.errors import MeasurementOutOfRangeError, ResponseTimeoutError
from drivers.compowayf.layout import COUNTER_MODULUS, AmplifierConfig, streaming_measured_config
from drivers.compowayf.transport import CompowayFPort
from drivers.exciter.can_bus import CanExciter
from drivers.exciter.cia402 import Cia402Exciter
from drivers.exciter.codes import CommandCode, ExciterState, ExciterStatus
from drivers.exciter.errors import EnvelopeBreachError, EnvelopeViolationError, ExciterTimeoutError
from drivers.exciter.modbus import ModbusExciter, ModbusTcpLink
from drivers.interfaces import Exciter, LaserAmplifier, LaserLine, StreamReading
from drivers.mock import ManualClock, MockAmplifier, MockExciter, MockLine
from estimator.sweep import SweepSettings

SWEEP = SweepSettings(start_Hz=0.0, stop_Hz=20.0, amplitude_m=0.004, duration_s=20.0)
STREAMING = AmplifierConfig(measured=streaming_measured_config(0.001, 100))


# ---- the interfaces --------------------------------------------------------------------------------------


def test_the_drivers_and_the_mocks_implement_the_interfaces() -> None:
    with CompowayFPort("loop://") as port:
        assert isinstance(port, LaserLine) and isinstance(ZxlAmplifier(port, 1), LaserAmplifier)
    assert isinstance(MockLine(), LaserLine) and isinstance(MockAmplifier(), LaserAmplifier)
    back_ends = [
        ModbusExciter(ModbusTcpLink("127.0.0.1", 9)),
        CanExciter("virtual", f"interfaces-{uuid.uuid4().hex}"),
        Cia402Exciter("virtual", f"interfaces-{uuid.uuid4().hex}", node_id=5),
        MockExciter(),
    ]
    for exciter in back_ends:
        assert isinstance(exciter, Exciter), type(exciter).__name__
    for name, member in vars(Exciter).items():  # an awaited method is a coroutine function everywhere
        if inspect.iscoroutinefunction(member):
            assert all(inspect.iscoroutinefunction(getattr(e, name)) for e in back_ends), name
    clock = ManualClock(1.0)
    reading = MockAmplifier(STREAMING, clock=clock.now_s).read_stream(5)
    assert isinstance(reading, StreamReading)


# ---- the mock amplifier ------------------------------------------------------------------------------------


def test_a_polled_mock_reads_its_script_at_the_clocks_time_in_its_own_counts() -> None:
    clock = ManualClock()
    amplifier = MockAmplifier(reading_m=lambda t: 0.001 * t, clock=clock.now_s, model="ZX-LDA41-N")
    clock.advance(2.0)
    assert amplifier.read_position_m() == pytest.approx(0.002)
    assert amplifier.read_counts(1) == [2000000]  # nanometres, the default layout's unit
    assert amplifier.read_model() == "ZX-LDA41-N" and amplifier.reads == 2
    amplifier.reading_m = math.nan
    with pytest.raises(MeasurementOutOfRangeError):
        amplifier.read_position_m()
    assert amplifier.config.measured.is_out_of_range(amplifier.read_counts(1)[0])


def test_a_streaming_mock_keeps_the_newest_buffer_length_samples_behind_its_counter() -> None:
    clock = ManualClock()
    amplifier = MockAmplifier(STREAMING, reading_m=lambda t: t * 1e-3, clock=clock.now_s)
    clock.advance(0.0305)  # samples 0..30 taken
    read = amplifier.read_stream(10)
    assert read.counter == 31 and read.counts == [30000 - 1000 * k for k in range(10)]  # newest first, nm
    clock.advance(0.5)  # 500 more: the ring (100) holds only the newest
    read = amplifier.read_stream(100, since=31)
    assert read.counter == 531 and len(read.counts) == 100 and read.counts[-1] == 431000
    assert amplifier.read_stream(100, since=531).counts == []  # nothing new
    clock.advance(COUNTER_MODULUS * 0.001)
    assert amplifier.read_stream(1).counter == 531  # the counter wraps as the amplifier's does
    with pytest.raises(ValueError, match="not a streaming layout"):
        MockAmplifier().read_stream(1)


def test_scripted_faults_fail_the_next_requests_then_clear() -> None:
    amplifier = MockAmplifier()
    timeout = ResponseTimeoutError("node 01: no reply within 0.5 s")
    amplifier.fail(timeout, count=2)
    for _ in range(2):
        with pytest.raises(ResponseTimeoutError):
            amplifier.read_counts()
    assert amplifier.read_counts() == [0]
    amplifier.fail(timeout, count=None)  # until cleared
    for _ in range(5):
        with pytest.raises(ResponseTimeoutError):
            amplifier.read_model()
    amplifier.clear_faults()
    assert amplifier.read_model() == "ZX-LDA11-N"
    with pytest.raises(ValueError, match="count must be"):
        amplifier.fail(timeout, count=0)


def test_the_manual_clock_moves_only_forward_and_tells_its_listeners() -> None:
    clock = ManualClock()
    seen: list[float] = []
    clock.on_advance.append(seen.append)
    clock.advance(0.25)
    clock.advance(0.5)
    assert clock.now_s() == 0.75 and seen == [0.25, 0.75] and not clock.realtime
    with pytest.raises(ValueError, match="cannot go back"):
        clock.advance(-0.1)


# ---- the mock exciter: a mock drive under the real PlateExciter logic -------------------------------------


def test_the_mock_exciter_records_what_it_was_asked_and_reports_what_it_was_told() -> None:
    async def scenario() -> None:
        clock = ManualClock()
        exciter = MockExciter(clock=clock.now_s, motion=lambda t: (t, 0.001))
        async with exciter:
            with pytest.raises(EnvelopeViolationError):  # the real envelope: refused before any write
                await exciter.configure_sweep(SweepSettings(amplitude_m=0.01))
            assert exciter.sweeps == []
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            clock.advance(0.25)
            status = await exciter.supervise()
            assert status == ExciterStatus(ExciterState.RUNNING, 0, 0.25, 0.001)
            assert exciter.keepalive_counters == [1]  # fed after a status read that passed its checks
            exciter.inject_fault(0x0042)
            assert (await exciter.status()).is_fault and exciter.keepalive_counters == [1]
            await exciter.reset_fault()
            assert (await exciter.status()).state is ExciterState.IDLE
        assert exciter.commands == [CommandCode.START, CommandCode.RESET_FAULT, CommandCode.STOP]  # closing
        assert exciter.opened and exciter.closed

    asyncio.run(scenario())


def test_a_scripted_status_failure_withholds_the_keepalive_and_a_breach_gets_an_emergency_stop() -> None:
    async def scenario() -> None:
        clock = ManualClock()
        exciter = MockExciter(clock=clock.now_s)
        await exciter.open()
        await exciter.configure_sweep(SWEEP)
        await exciter.start()
        clock.advance(0.25)
        exciter.fail("status", ExciterTimeoutError("no answer within 0.3 s"))
        with pytest.raises(ExciterTimeoutError):
            await exciter.supervise()
        assert exciter.keepalive_counters == []
        exciter.position_m = 0.0045
        with pytest.raises(EnvelopeBreachError) as info:
            await exciter.supervise()
        assert info.value.stopped and exciter.commands[-1] is CommandCode.EMERGENCY_STOP
        assert exciter.keepalive_counters == [] and not exciter.supervising
        await exciter.close()
        assert exciter.commands == [CommandCode.START, CommandCode.EMERGENCY_STOP]  # stopped: left alone

    asyncio.run(scenario())


def test_closing_the_mock_with_the_plate_moving_stops_it_and_falls_back_to_an_emergency_stop() -> None:
    async def scenario() -> None:
        exciter = MockExciter(clock=ManualClock().now_s)
        await exciter.open()
        await exciter.configure_sweep(SWEEP)
        await exciter.start()
        exciter.fail("command", ExciterTimeoutError("no answer within 0.3 s"))  # the STOP is lost
        await exciter.close()
        assert exciter.commands == [CommandCode.START, CommandCode.EMERGENCY_STOP] and exciter.closed

    asyncio.run(scenario())
