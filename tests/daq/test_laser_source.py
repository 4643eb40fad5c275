"""Laser sources: over a real transport (TCP) against simulated ZX-L amplifiers on a manual clock, every
sample arrives once with its device time; on in-process mock amplifiers (drivers/mock.py), losses are
counted exactly, failures are counted and recovered, a line's late-reply wait is honoured; and where the
measured value lives, from the bench file to the driver."""

from __future__ import annotations

import re
from collections.abc import Iterator

import numpy as np
import pytest

from daq.bench_config import BenchConfigError, parse_bench_config
from daq.sources.laser_source import LaserSource
from drivers.compowayf.amplifier import CountUnit, MeasuredArea, MeasuredValueConfig, ZxlAmplifier
from drivers.compowayf.errors import AreaTypeError, CompowayFError, MalformedFrameError
from drivers.compowayf.transport import CompowayFPort
from drivers.mock import ManualClock, MockAmplifier
from estimator.sweep import SweepSettings
from service.simulated_bench import SimulatedBench
from simulators.devices.laser_amplifier import SimulatedAmplifier, TcpAmplifierServer
from simulators.excitation import sweep_position_m
from simulators.plate import EmptyPlate
from tests.daq.mock_bench import bench_toml


def _source(bench: SimulatedBench, channel: str) -> LaserSource:
    laser = bench.config.laser_for(channel)
    assert laser is not None
    port = CompowayFPort(laser.url)
    amplifier = ZxlAmplifier(port, laser.device()[1], laser.amplifier_config())
    return LaserSource(laser, amplifier, host_clock=bench.clock.now_s)


@pytest.fixture
def bench() -> Iterator[SimulatedBench]:
    with SimulatedBench(noise_sigma_m=0.0) as started:
        yield started


def _drain(source: LaserSource) -> tuple[np.ndarray, np.ndarray]:
    reader = source.buffer.reader("test", from_oldest=True)
    result = reader.read()
    reader.close()
    return result.timestamps_s, result.values[:, 0]


def test_streaming_source_gets_every_sample_once_with_device_time(bench: SimulatedBench) -> None:
    settings = SweepSettings(duration_s=5.0)
    bench.physics.start_sweep(settings)
    started_s = bench.clock.now_s()
    source = _source(bench, "x_r")
    rng = np.random.default_rng(11)
    source.poll()
    for _ in range(60):  # irregular polls: 1 to 60 ms apart
        bench.clock.advance(float(rng.uniform(0.001, 0.060)))
        bench.tick()
        source.poll()
    times, values = _drain(source)
    amplifier = bench.amplifiers["x_r"]
    assert source.statistics().samples == times.size
    first_number = round(times[0] / 1e-3)  # device time = sample number x period
    assert times.size == amplifier.samples_taken - first_number  # every sample from the first polled on
    np.testing.assert_allclose(np.diff(times), 1e-3, rtol=0, atol=1e-12)  # not one missing or repeated
    assert times[-1] == pytest.approx(bench.clock.now_s(), abs=1e-3)
    truth = sweep_position_m(settings, source.to_host_s(times) - started_s)
    resolution = amplifier.head.model.resolution_m
    assert np.max(np.abs(values - truth)) <= resolution / 2 + 1e-12
    stats = source.statistics()
    assert stats.lost_samples == 0 and stats.failed_reads == 0
    assert stats.achieved_rate_Hz == pytest.approx(1000.0, rel=1e-9)


# ---- the source's bookkeeping, on mock amplifiers ---------------------------------------------------------


def _mock_source(
    *, streaming: bool = True, channel: str = "x_s"
) -> tuple[LaserSource, MockAmplifier, ManualClock]:
    """A source on an in-process mock amplifier (drivers/mock.py) reading 1 mm + 1 µm per sample number."""
    laser = parse_bench_config(bench_toml(streaming=streaming)).laser_for(channel)
    assert laser is not None
    clock = ManualClock()
    amplifier = MockAmplifier(
        laser.amplifier_config(), reading_m=lambda t: 0.001 + round(t * 1e3) * 1e-6, clock=clock.now_s
    )
    return LaserSource(laser, amplifier, host_clock=clock.now_s), amplifier, clock


def test_a_pause_longer_than_the_amplifier_buffer_loses_exactly_the_overwritten_samples() -> None:
    source, amplifier, clock = _mock_source()
    buffer_length = amplifier.config.measured.buffer_length
    clock.advance(0.5)
    source.poll()
    clock.advance(0.02)
    source.poll()
    pause = buffer_length + 300  # samples taken meanwhile; the amplifier keeps buffer_length of them
    clock.advance(pause * 1e-3)
    source.poll()
    times, values = _drain(source)
    assert source.statistics().lost_samples == pause - buffer_length
    steps = np.round(np.diff(times) * 1e3).astype(int)
    assert sorted(set(steps)) == [1, pause - buffer_length + 1]  # one hole, exactly as long as the loss
    np.testing.assert_allclose(values, np.round(times * 1e3) * 1e-6, atol=1e-12)  # each value its sample's


def test_failed_reads_are_counted_and_the_next_read_catches_up_without_loss() -> None:
    source, amplifier, clock = _mock_source(channel="x_t")
    source.poll()
    amplifier.fail(MalformedFrameError("no ETX in 40 bytes"))
    clock.advance(0.05)
    with pytest.raises(CompowayFError):
        source.poll()
    clock.advance(0.05)
    source.poll()
    times, _ = _drain(source)
    stats = source.statistics()
    assert stats.failed_reads == 1 and stats.last_error == "MalformedFrameError: no ETX in 40 bytes"
    assert stats.lost_samples == 0
    np.testing.assert_allclose(np.diff(times), 1e-3, atol=1e-12)
    assert times.size == 101  # samples 0 to 100: the first poll found sample 0, nothing was lost after


def test_polled_source_stamps_host_time_and_reports_the_rate_it_got() -> None:
    source, _, clock = _mock_source(streaming=False, channel="x_r")
    assert not source.streaming
    for _ in range(20):
        clock.advance(0.004)  # one read per 4 ms of host time: 250 Hz
        source.poll()
    times, values = _drain(source)
    np.testing.assert_allclose(np.diff(times), 0.004, atol=1e-12)
    np.testing.assert_allclose(values, np.round(times * 1e3) * 1e-6, atol=1e-12)  # reading minus zero_m
    stats = source.statistics()
    assert stats.nominal_rate_Hz is None
    assert stats.achieved_rate_Hz == pytest.approx(250.0)
    assert str(stats.clock) == "host_monotonic"


def test_a_line_waiting_out_a_late_reply_is_not_polled_and_says_why() -> None:
    source, amplifier, clock = _mock_source()
    line = amplifier.port
    failure = "ResponseTimeoutError: node 01: no reply within 0.5 s"
    line.quiet_for_s, line.last_failure = 2.5, failure
    clock.advance(0.05)
    assert source.poll() == 0 and amplifier.reads == 0
    stats = source.statistics()
    assert stats.line_waits == 1 and stats.failed_reads == 0
    assert (
        stats.last_error
        == "its line waits out a late reply after ResponseTimeoutError: node 01: no reply within 0.5 s"
    )
    line.counters.unanswered += 1
    assert source.line_lost_reply_since_data()  # its silence may be the line's wait (daq/sweep/silence.py)
    line.quiet_for_s = 0.0
    assert source.poll() == 1  # the first poll of a stream only finds where the counter stands


def test_an_out_of_range_reading_is_a_nan_and_counted() -> None:
    source, amplifier, clock = _mock_source(streaming=False)
    clock.advance(0.01)
    source.poll()
    amplifier.reading_m = float("nan")
    clock.advance(0.01)
    source.poll()
    _, values = _drain(source)
    assert np.isnan(values).tolist() == [False, True]
    assert source.statistics().out_of_range_samples == 1


# ---- where the measured value lives: BENCH.toml keys to driver and simulator ------------------------------

BENCH_TEXT = """\
[bench]
name = "b"
model = "quarter-car"

[exciter]
name = "plate"
url = "modbus-tcp://127.0.0.1:5020?unit=1"

[[lasers]]
name = "plate laser"
url = "socket://127.0.0.1:9?node=1"
channel = "x_r"
head = "ZX-LD40"
value_area = "variable"
value_type = 0xC1
value_address = 0x0100
value_unit = "0.1um"

[[lasers]]
name = "default"
url = "socket://127.0.0.1:9?node=2"
channel = "x_s"
head = "ZX-LD40"

[[lasers]]
name = "streaming"
url = "socket://127.0.0.1:9?node=3"
channel = "x_t"
head = "ZX-LD40"
sample_period_s = 0.001
value_address = 0x0200
"""


def test_value_location_keys_reach_the_driver() -> None:
    located, default, streaming = parse_bench_config(BENCH_TEXT).lasers
    assert located.amplifier_config().measured == MeasuredValueConfig(
        area=MeasuredArea.VARIABLE, area_type=0xC1, address=0x0100, count_unit=CountUnit.TENTH_MICROMETRE
    )
    assert default.amplifier_config().measured == MeasuredValueConfig(
        area=MeasuredArea.PARAMETER, area_type=0xC020, address=0x3000, count_unit=CountUnit.NANOMETRE
    )  # the ZS-series measurement result (drivers/compowayf/layout.py)
    measured = streaming.amplifier_config().measured
    assert (measured.area, measured.area_type, measured.counter_address, measured.address) == (
        MeasuredArea.VARIABLE,
        0xC0,
        0x0200,
        0x0201,
    )


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            'value_area = "variable"',
            'value_area = "eeprom"',
            r":14: \[\[lasers\]\] #1 value_area: value_area must",
        ),
        ('value_unit = "0.1um"', 'value_unit = "mm"', r":17: \[\[lasers\]\] #1 value_unit: value_unit must"),
        ("value_type = 0xC1", "value_type = 0x1C1", r".*value_type: measured value location: area_type"),
        ("value_address = 0x0200", "value_address = 0xFFFF", r".*value_type: measured value location: addr"),
        (
            "value_address = 0x0100",
            'value_address = "0100"',
            r":16: \[\[lasers\]\] #1 value_address: .*integer",
        ),
    ],
)
def test_bad_value_location_keys_are_one_located_line(old: str, new: str, message: str) -> None:
    with pytest.raises(BenchConfigError) as info:
        parse_bench_config(BENCH_TEXT.replace(old, new), "bench.toml")
    assert "\n" not in str(info.value)
    assert re.match(r"bench\.toml" + message, str(info.value)), str(info.value)


def test_a_polled_source_reads_where_the_configuration_says() -> None:
    laser = parse_bench_config(BENCH_TEXT).lasers[0]
    bench = EmptyPlate()
    amplifier = SimulatedAmplifier.for_channel(
        bench, "x_r", config=laser.amplifier_config(), noise_sigma_m=0.0, static_offset_m=0.0015
    )
    with TcpAmplifierServer({1: amplifier}) as server:
        port = CompowayFPort(server.url)
        source = LaserSource(
            laser, ZxlAmplifier(port, 1, laser.amplifier_config()), host_clock=bench.clock.now_s
        )
        source.poll()
        with pytest.raises(AreaTypeError):  # the default location is not where this amplifier keeps it
            ZxlAmplifier(port, 1).read_position_m()
        port.close()
    _, values = _drain(source)
    assert values.tolist() == pytest.approx([0.0015])  # read in 0.1 µm counts from variable area C1
