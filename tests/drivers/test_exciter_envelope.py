"""Safety envelope: limits, hard limits, and refusal before anything reaches the drive (Modbus and CAN)."""

from __future__ import annotations

import asyncio
import math
import uuid

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.exciter.can_bus import CanExciter
from drivers.exciter.envelope import DEFAULT_HARD_LIMITS, EnvelopeLimits, SafetyEnvelope
from drivers.exciter.errors import EnvelopeViolationError, ExciterConfigError, ExciterEncodingError
from drivers.exciter.modbus import ModbusExciter, ModbusTcpLink
from estimator.sweep import SweepLaw, SweepSettings
from simulators.devices.can_exciter import SimulatedCanExciter
from simulators.devices.modbus_exciter import SimulatedModbusExciter
from simulators.plate import EmptyPlate

VIOLATIONS = [
    pytest.param(SweepSettings(amplitude_m=0.0041), "amplitude_m", "max_amplitude_m", id="amplitude"),
    pytest.param(SweepSettings(start_Hz=26.0, stop_Hz=5.0), "start_Hz", "max_frequency_Hz", id="start"),
    pytest.param(SweepSettings(stop_Hz=25.01), "stop_Hz", "max_frequency_Hz", id="stop"),
    pytest.param(SweepSettings(amplitude_m=math.nan), "amplitude_m", "max_amplitude_m", id="nan-amplitude"),
    pytest.param(SweepSettings(stop_Hz=math.inf), "stop_Hz", "max_frequency_Hz", id="inf-frequency"),
    pytest.param(SweepSettings(duration_s=11 * 86400.0), "duration_s", "max_duration_s", id="11-days"),
    pytest.param(SweepSettings(duration_s=300.001), "duration_s", "max_duration_s", id="just-too-long"),
    pytest.param(SweepSettings(duration_s=math.inf), "duration_s", "max_duration_s", id="inf-duration"),
    pytest.param(
        SweepSettings(start_Hz=1.0, stop_Hz=30.0, law=SweepLaw.LOGARITHMIC),
        "stop_Hz",
        "max_frequency_Hz",
        id="log-stop",
    ),
]


def test_default_envelope_accepts_the_bench_standard_sweep() -> None:
    envelope = SafetyEnvelope()
    envelope.check(SweepSettings())  # 0-20 Hz, 4 mm
    envelope.check(SweepSettings(start_Hz=25.0, stop_Hz=25.0, amplitude_m=0.004))
    assert envelope.limits == EnvelopeLimits(0.004, 25.0)


@pytest.mark.parametrize(("settings", "field", "limit_name"), VIOLATIONS)
def test_violation_names_field_and_limit(settings: SweepSettings, field: str, limit_name: str) -> None:
    with pytest.raises(EnvelopeViolationError) as info:
        SafetyEnvelope().check(settings)
    assert info.value.field == field
    assert info.value.limit_name == limit_name
    assert field in str(info.value) and limit_name in str(info.value)


def test_bench_may_lower_limits() -> None:
    envelope = SafetyEnvelope(EnvelopeLimits(max_amplitude_m=0.002, max_frequency_Hz=15.0))
    with pytest.raises(EnvelopeViolationError, match=r"max_amplitude_m=0\.002"):
        envelope.check(SweepSettings(stop_Hz=10.0, amplitude_m=0.003))
    with pytest.raises(EnvelopeViolationError, match=r"max_frequency_Hz=15\.0"):
        envelope.check(SweepSettings(amplitude_m=0.001))


@pytest.mark.parametrize(
    ("bench", "field"),
    [
        (EnvelopeLimits(max_amplitude_m=0.005), "max_amplitude_m"),
        (EnvelopeLimits(max_frequency_Hz=30.0), "max_frequency_Hz"),
    ],
)
def test_bench_cannot_raise_limits_above_hard_limits(bench: EnvelopeLimits, field: str) -> None:
    with pytest.raises(ExciterConfigError, match=f"above the hard limit {field}="):
        SafetyEnvelope(bench)


def test_configured_hard_limits_bound_the_bench() -> None:
    hard = EnvelopeLimits(max_amplitude_m=0.006, max_frequency_Hz=30.0)
    SafetyEnvelope(EnvelopeLimits(0.006, 30.0), hard).check(SweepSettings(stop_Hz=30.0, amplitude_m=0.006))
    with pytest.raises(ExciterConfigError, match=r"max_frequency_Hz=30\.0"):
        SafetyEnvelope(EnvelopeLimits(0.004, 31.0), hard)
    low_hard = EnvelopeLimits(max_amplitude_m=0.003, max_frequency_Hz=20.0)
    assert SafetyEnvelope(hard_limits=low_hard).limits == low_hard  # defaults clamp to the hard limits
    assert EnvelopeLimits(0.004, 25.0, 3600.0) == DEFAULT_HARD_LIMITS  # duration: an hour, benches 300 s


def test_limits_from_config_table() -> None:
    assert EnvelopeLimits.from_mapping({"max_amplitude_m": 0.003}) == EnvelopeLimits(0.003, 25.0)
    with pytest.raises(ExciterConfigError, match="max_amplitude_mm"):
        EnvelopeLimits.from_mapping({"max_amplitude_mm": 3})
    with pytest.raises(ExciterConfigError, match="max_frequency_Hz"):
        EnvelopeLimits(max_frequency_Hz=-1.0)


@given(
    amplitude_m=st.floats(0.0, 0.01, allow_nan=False),
    start_Hz=st.floats(0.0, 40.0, allow_nan=False),
    stop_Hz=st.floats(0.0, 40.0, allow_nan=False),
)
def test_check_is_exactly_the_limits(amplitude_m: float, start_Hz: float, stop_Hz: float) -> None:
    settings = SweepSettings(start_Hz=start_Hz, stop_Hz=stop_Hz, amplitude_m=amplitude_m)
    inside = amplitude_m <= 0.004 and start_Hz <= 25.0 and stop_Hz <= 25.0
    if inside:
        SafetyEnvelope().check(settings)
    else:
        with pytest.raises(EnvelopeViolationError):
            SafetyEnvelope().check(settings)


# ---- refusal happens before any traffic, on both back ends ---------------------------------------------


@pytest.mark.parametrize(("settings", "field", "limit_name"), VIOLATIONS)
def test_modbus_sends_nothing_for_a_violation(settings: SweepSettings, field: str, limit_name: str) -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        async with SimulatedModbusExciter(bench) as sim:
            exciter = ModbusExciter(ModbusTcpLink(sim.host, sim.port), timeout_s=0.5, clock=bench.clock.now_s)
            async with exciter:
                with pytest.raises(EnvelopeViolationError):
                    await exciter.configure_sweep(settings)
                with pytest.raises(EnvelopeViolationError):  # nor does a start with a refused sweep
                    exciter._sweep = settings
                    await exciter.start()
            assert sim.writes == []
            assert sim.requests == 0
            assert sim.exciter.commands == []

    asyncio.run(scenario())


def test_modbus_value_that_does_not_fit_a_register_is_refused_before_any_write() -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        async with SimulatedModbusExciter(bench) as sim:
            long_sweeps = EnvelopeLimits(max_duration_s=1e7)  # an installation that allows them
            envelope = SafetyEnvelope(long_sweeps, long_sweeps)
            link = ModbusTcpLink(sim.host, sim.port)
            async with ModbusExciter(link, timeout_s=0.5, envelope=envelope) as exciter:
                with pytest.raises(ExciterEncodingError, match="sweep_duration_s"):
                    await exciter.configure_sweep(SweepSettings(duration_s=5e6))  # > u32 milliseconds
            assert sim.writes == []

    asyncio.run(scenario())


@pytest.mark.parametrize(("settings", "field", "limit_name"), VIOLATIONS)
def test_can_sends_nothing_for_a_violation(settings: SweepSettings, field: str, limit_name: str) -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        channel = f"envelope-{uuid.uuid4().hex}"
        with SimulatedCanExciter(bench, channel=channel) as sim:
            sim.tick()
            async with CanExciter(
                "virtual", channel, reply_timeout_s=0.5, clock=bench.clock.now_s
            ) as exciter:
                with pytest.raises(EnvelopeViolationError):
                    await exciter.configure_sweep(settings)
                await exciter.status()  # a later exchange proves the bus works and flushes it in order
            names = [name for name, _ in sim.received]
            assert names == ["EXC_Command"]
            assert sim.received[0][1]["Command"] == 0  # the status request, nothing else
            assert sim.exciter.commands == []

    asyncio.run(scenario())


# ---- what the drive reports while the plate moves ----------------------------------------------------------


def test_default_duration_limit_and_bench_may_shorten_it() -> None:
    SafetyEnvelope().check(SweepSettings(duration_s=300.0))
    envelope = SafetyEnvelope(EnvelopeLimits(max_duration_s=60.0))
    with pytest.raises(EnvelopeViolationError, match=r"duration_s=61\.0.*max_duration_s=60\.0"):
        envelope.check(SweepSettings(duration_s=61.0))
    soak = SafetyEnvelope(EnvelopeLimits(max_duration_s=600.0))  # a bench may lengthen it
    soak.check(SweepSettings(duration_s=600.0))
    with pytest.raises(ExciterConfigError, match="max_duration_s"):
        SafetyEnvelope(EnvelopeLimits(max_duration_s=3601.0))  # above the hard limit


@pytest.mark.parametrize(
    ("frequency_Hz", "position_m", "running_for_s", "expected"),
    [
        (20.0, 0.004, 10.0, None),  # the standard sweep at its peak
        (25.0 * 1.05, -0.004 * 1.05, 20.9, None),  # within the reporting margin, before the overrun margin
        (26.3, 0.0, 1.0, ("frequency_Hz", "max_frequency_Hz")),
        (5.0, -0.0043, 1.0, ("position_m", "max_amplitude_m")),
        (math.nan, 0.0, 1.0, ("frequency_Hz", "max_frequency_Hz")),
        (5.0, math.inf, 1.0, ("position_m", "max_amplitude_m")),
        (5.0, 0.001, 21.1, ("running_s", "sweep duration_s")),  # still RUNNING 1.1 s after a 20 s sweep
        (5.0, 0.001, None, None),  # not reported as RUNNING (stopping): no overrun check
    ],
)
def test_breach_of_reported_values(
    frequency_Hz: float, position_m: float, running_for_s: float | None, expected: tuple[str, str] | None
) -> None:
    breach = SafetyEnvelope().breach(frequency_Hz, position_m, running_for_s, 20.0)
    assert (None if breach is None else (breach[0], breach[2])) == expected
