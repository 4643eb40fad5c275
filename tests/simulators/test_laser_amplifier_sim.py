"""The ZX-L driver against the simulated amplifier over a real pty and real TCP: readings follow the bench
physics in simulated time, every injected fault gives its typed error and the next read recovers.

Most tests share one server and driver per transport (module scope): pyserial's socket:// close() sleeps
0.3 s by design, so opening a fresh TCP driver per test would dominate the run time.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np
import pytest

from drivers.compowayf import errors
from drivers.compowayf.amplifier import AmplifierConfig, MeasuredArea, MeasuredValueConfig, ZxlAmplifier
from drivers.compowayf.codec import build_command, parse_response
from drivers.compowayf.layout import streaming_measured_config
from drivers.compowayf.transport import CompowayFPort, LinkSettings
from estimator.sweep import SweepSettings
from simulators.devices.laser_amplifier import (
    BUFFER_SIZE_BYTES,
    AmplifierLine,
    FaultKind,
    PtyAmplifierServer,
    SimulatedAmplifier,
    TcpAmplifierServer,
)
from simulators.devices.sensor_heads import ZX_LD40, ZX_LD100, SimulatedHead
from simulators.plate import EmptyPlate

FAST = LinkSettings(timeout_s=0.2, late_reply_s=0.2, retries=0)
"""The simulated amplifier answers at once or never: no late reply to wait out after a timeout."""
SWEEP = SweepSettings(start_Hz=1.0, stop_Hz=5.0, amplitude_m=0.004, duration_s=600.0)


def _serve(
    transport: str, amplifiers: dict[int, SimulatedAmplifier], *, echo: bool = False
) -> PtyAmplifierServer | TcpAmplifierServer:
    server_cls = PtyAmplifierServer if transport == "pty" else TcpAmplifierServer
    return server_cls(amplifiers, echo=echo).start()


@pytest.fixture
def bench() -> EmptyPlate:
    return EmptyPlate()


@pytest.fixture(params=["pty", "tcp"])
def transport(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@dataclass
class Rig:
    bench: EmptyPlate
    server: PtyAmplifierServer | TcpAmplifierServer
    driver: ZxlAmplifier


@pytest.fixture(scope="module", params=["pty", "tcp"])
def shared_rig(request: pytest.FixtureRequest) -> Iterator[Rig]:
    """A sweeping plate watched by one noise-free ZX-LD40 on x_r at node 1, served on the transport."""
    bench = EmptyPlate()
    bench.start_sweep(SWEEP)
    server = _serve(str(request.param), {1: SimulatedAmplifier.for_channel(bench, "x_r", noise_sigma_m=0.0)})
    driver = ZxlAmplifier.open(server.device_url(1), link=FAST)
    yield Rig(bench, server, driver)
    driver.close()
    server.stop()


@pytest.fixture
def rig(shared_rig: Rig) -> Iterator[Rig]:
    """The shared rig, reset after each test: faults cleared, fast link without retries, rate reset."""
    yield shared_rig
    shared_rig.server.clear_faults()
    shared_rig.driver.port.link = FAST
    shared_rig.driver.reset_read_rate()


def test_reading_follows_the_plate_in_simulated_time(rig: Rig) -> None:
    bench, driver = rig.bench, rig.driver
    for _ in range(20):
        bench.clock.advance(0.037)
        expected_m = bench.position_m("x_r")
        assert driver.read_position_m() == pytest.approx(expected_m, abs=ZX_LD40.resolution_m / 2 + 1e-12)
        assert driver.read_counts()[0] % 2000 == 0  # quantised to the 2 µm resolution, in nm counts


def test_same_simulated_time_gives_the_same_sample(bench: EmptyPlate, transport: str) -> None:
    amplifier = SimulatedAmplifier.for_channel(bench, "x_r", seed=7)  # with noise
    with (
        _serve(transport, {1: amplifier}) as server,
        ZxlAmplifier.open(server.device_url(1), link=FAST) as driver,
    ):
        first = driver.read_counts()[0]
        assert driver.read_counts()[0] == first
        bench.clock.advance(0.001)
        values = {driver.read_counts()[0] for _ in range(3)}
        assert len(values) == 1


def test_services_model_status_echo(rig: Rig) -> None:
    driver = rig.driver
    assert driver.read_model() == "ZX-LDA11-N"
    assert driver.echo("Hello, bench 01!") == "Hello, bench 01!"
    status = driver.read_status()
    assert (status.operating_status, status.related_info) == (0, 0)


def test_zero_reset_and_cancel(bench: EmptyPlate, transport: str) -> None:
    amplifier = SimulatedAmplifier.for_channel(bench, "x_r", noise_sigma_m=0.0, static_offset_m=0.003)
    with (
        _serve(transport, {1: amplifier}) as server,
        ZxlAmplifier.open(server.device_url(1), link=FAST) as driver,
    ):
        assert driver.read_position_m() == pytest.approx(0.003)
        driver.zero_reset()
        assert driver.read_position_m() == pytest.approx(0.0, abs=1e-12)
        assert driver.read_status().related_info & 0b10
        driver.zero_reset_cancel()
        assert driver.read_position_m() == pytest.approx(0.003)
        with pytest.raises(errors.ParameterError):
            driver.operation_command(0x7E, 0x00)


def test_out_of_range_by_geometry_and_head_choice(bench: EmptyPlate, transport: str) -> None:
    near = SimulatedAmplifier.for_channel(bench, "x_s", ZX_LD40, noise_sigma_m=0.0, static_offset_m=0.012)
    wide = SimulatedAmplifier.for_channel(bench, "x_s", ZX_LD100, noise_sigma_m=0.0, static_offset_m=0.012)
    with (
        _serve(transport, {1: near, 2: wide}) as server,
        CompowayFPort(server.device_url(1), link=FAST) as port,
    ):
        with pytest.raises(errors.MeasurementOutOfRangeError, match="node 01"):
            ZxlAmplifier(port, 1).read_position_m()
        assert ZxlAmplifier(port, 1).read_status().related_info & 0b01
        assert ZxlAmplifier(port, 2).read_position_m() == pytest.approx(0.012)


def test_multidrop_nodes_share_one_line(bench: EmptyPlate, transport: str) -> None:
    amplifiers = {
        1: SimulatedAmplifier.for_channel(bench, "x_r", ZX_LD40, noise_sigma_m=0.0),
        7: SimulatedAmplifier.for_channel(bench, "x_s", ZX_LD100, noise_sigma_m=0.0, static_offset_m=-0.02),
    }
    bench.start_sweep(SWEEP)
    bench.clock.advance(0.3)
    with _serve(transport, amplifiers) as server, CompowayFPort(server.device_url(1), link=FAST) as port:
        x_r, x_s, absent = ZxlAmplifier(port, 1), ZxlAmplifier(port, 7), ZxlAmplifier(port, 3)
        assert x_r.read_position_m() == pytest.approx(bench.position_m("x_r"), abs=1e-6)
        assert x_s.read_position_m() == pytest.approx(-0.02)
        with pytest.raises(errors.ResponseTimeoutError, match="node 03"):
            absent.read_model()
        assert x_r.read_model() == "ZX-LDA11-N"


def test_plain_device_path_on_the_pty(bench: EmptyPlate) -> None:
    amplifier = SimulatedAmplifier.for_channel(bench, "x_r", noise_sigma_m=0.0)
    with (
        PtyAmplifierServer({4: amplifier}) as server,
        ZxlAmplifier.open(f"{server.port_path}?node=4&baudrate=9600", link=FAST) as driver,
    ):
        assert driver.read_position_m() == 0.0


def test_sample_buffer_read_oldest_first(bench: EmptyPlate, transport: str) -> None:
    measured = MeasuredValueConfig(area=MeasuredArea.VARIABLE, area_type=0xC0, address=0, buffer_length=4)
    config = AmplifierConfig(measured=measured)
    amplifier = SimulatedAmplifier.for_channel(bench, "x_r", config=config, noise_sigma_m=0.0)
    bench.start_sweep(SWEEP)
    expected_m = []
    for _ in range(4):
        bench.clock.advance(0.05)
        amplifier.sample()
        expected_m.append(amplifier.head.quantise_m(bench.position_m("x_r")))
    with (
        _serve(transport, {1: amplifier}) as server,
        ZxlAmplifier.open(server.device_url(1), config=config, link=FAST) as driver,
    ):
        assert driver.read_samples_m(4) == pytest.approx(expected_m, abs=1e-12)
        assert driver.read_samples_m(2) == pytest.approx(expected_m[2:], abs=1e-12)
        assert driver.read_rate().samples == 6
        with pytest.raises(errors.EndAddressOutOfRangeError):
            driver.read_variable_area(0xC0, 0x0002, 3)


def test_measured_value_in_parameter_area_and_parameter_services(bench: EmptyPlate, transport: str) -> None:
    measured = MeasuredValueConfig(area=MeasuredArea.PARAMETER, area_type=0xC100, address=0x0010)
    config = AmplifierConfig(measured=measured)
    amplifier = SimulatedAmplifier.for_channel(
        bench, "x_r", config=config, noise_sigma_m=0.0, static_offset_m=1e-3
    )
    with (
        _serve(transport, {1: amplifier}) as server,
        ZxlAmplifier.open(server.device_url(1), config=config, link=FAST) as driver,
    ):
        assert driver.read_position_m() == pytest.approx(1e-3)
        driver.write_parameter_area(0xC000, 0x0001, [-5, 123456])
        assert driver.read_parameter_area(0xC000, 0x0000, 3) == [0, -5, 123456]
        with pytest.raises(errors.ReadOnlyError):
            driver.write_parameter_area(0xC100, 0x0010, [1])
        with pytest.raises(errors.AreaTypeError):
            driver.read_parameter_area(0xD000, 0x0000, 1)
        with pytest.raises(errors.StartAddressOutOfRangeError):
            driver.read_parameter_area(0xC000, 0x0009, 1)
        with pytest.raises(errors.EndAddressOutOfRangeError):
            driver.read_parameter_area(0xC000, 0x0002, 2)
        with pytest.raises(errors.AreaTypeError):
            driver.read_variable_area(0xC0, 0x0000, 1)


@pytest.mark.parametrize(
    ("text", "end_code"),
    [
        (build_command(1, "0101", "C0000000" + "0001")[:-1] + b"\x00", "13"),  # corrupted BCC
        (build_command(1, "0101", "C0000000" + "0001", sub_address="05"), "16"),
        (build_command(1, "0101", "C0 ZZ000" + "0001"), "14"),
        (build_command(1, "0801", "A" * 300), "18"),
    ],
)
def test_amplifier_answers_bad_commands_with_end_codes(bench: EmptyPlate, text: bytes, end_code: str) -> None:
    with (
        PtyAmplifierServer({1: SimulatedAmplifier.for_channel(bench, "x_r")}) as server,
        CompowayFPort(server.device_url(1), link=FAST) as port,
    ):
        response = parse_response(port.exchange(text))
        assert (response.node, response.end_code) == (1, end_code)


def test_model_reply_carries_the_buffer_size(rig: Rig) -> None:
    response = parse_response(rig.driver.port.exchange(build_command(1, "0503")))
    assert response.data == "ZX-LDA11-N" + "00D9"  # 10-character model, 4-hex-digit buffer size (217)
    attributes = rig.driver.read_attributes()
    assert (attributes.model, attributes.buffer_size_bytes) == ("ZX-LDA11-N", BUFFER_SIZE_BYTES)


def test_reads_longer_than_one_reply_are_refused_and_the_driver_splits_them(
    bench: EmptyPlate, transport: str
) -> None:
    measured = MeasuredValueConfig(area=MeasuredArea.VARIABLE, area_type=0xC0, address=0, buffer_length=60)
    config = AmplifierConfig(measured=measured)
    amplifier = SimulatedAmplifier.for_channel(bench, "x_r", config=config, noise_sigma_m=0.0)
    with (
        _serve(transport, {1: amplifier}) as server,
        ZxlAmplifier.open(server.device_url(1), config=config, link=FAST) as driver,
    ):
        for data, limit in (("C0000000" + "001A", 25), ("C0200000" + "8018", 23)):  # 26 DW; 24 DW + echo
            service = "0101" if data.startswith("C00") else "0201"
            response = parse_response(driver.port.exchange(build_command(1, service, data)))
            assert (response.end_code, response.response_code) == ("00", "110B"), limit
        before = server.commands_received
        assert len(driver.read_counts(60)) == 60
        assert server.commands_received - before == 3  # 25 + 25 + 10


def test_the_configured_area_type_and_address_are_served(bench: EmptyPlate, transport: str) -> None:
    measured = MeasuredValueConfig(area=MeasuredArea.VARIABLE, area_type=0xC1, address=0x0100)
    config = AmplifierConfig(measured=measured)
    amplifier = SimulatedAmplifier.for_channel(
        bench, "x_r", config=config, noise_sigma_m=0.0, static_offset_m=2e-3
    )
    with (
        _serve(transport, {1: amplifier}) as server,
        ZxlAmplifier.open(server.device_url(1), config=config, link=FAST) as driver,
        CompowayFPort(server.device_url(1), link=FAST) as other_port,
    ):
        assert driver.read_position_m() == pytest.approx(2e-3)
        with pytest.raises(errors.AreaTypeError):  # the default location (parameter area C020) is not it
            ZxlAmplifier(other_port, 1).read_position_m()


def test_a_null_byte_before_each_reply_is_skipped(rig: Rig) -> None:
    driver = rig.driver
    skipped = driver.port.counters.skipped_bytes
    rig.server.inject_fault(FaultKind.NULL_BEFORE_STX)
    for _ in range(3):
        assert driver.read_position_m() == pytest.approx(rig.bench.position_m("x_r"), abs=1e-6)
    assert driver.port.counters.skipped_bytes == skipped + 3


def test_an_echoing_line_needs_echo_suppression(bench: EmptyPlate, transport: str) -> None:
    """With echo=1 the driver reads back its own frame and every read works. Without it the echoed command
    is taken for a reply: a garbled one for 0503 (a typed error), one that answers nothing for an area read
    (discarded by the request matching)."""
    amplifier = SimulatedAmplifier.for_channel(bench, "x_r", noise_sigma_m=0.0, static_offset_m=1e-3)
    with _serve(transport, {1: amplifier}, echo=True) as server:
        with ZxlAmplifier.open(server.device_url(1) + "&echo=1&timeout_s=0.2") as driver:
            assert driver.port.link.echo
            assert driver.read_model() == "ZX-LDA11-N"
            assert [driver.read_position_m() for _ in range(3)] == pytest.approx([1e-3] * 3)
            assert (driver.port.counters.discarded_frames, driver.port.counters.retries) == (0, 0)
        with ZxlAmplifier.open(server.device_url(1), link=FAST) as driver:
            with pytest.raises(errors.MalformedFrameError):
                driver.read_model()
            assert driver.read_position_m() == pytest.approx(1e-3)
            # the echo of the position request is always discarded; the device's own (late) 0503 reply is
            # either flushed before the next request goes out or read and discarded, as the pty's timing falls
            assert driver.port.counters.discarded_frames in (1, 2)


def test_a_1000_sample_ring_streams_in_requests_of_25(bench: EmptyPlate, transport: str) -> None:
    config = AmplifierConfig(measured=streaming_measured_config(0.001, 1000))
    amplifier = SimulatedAmplifier.for_channel(bench, "x_r", config=config, noise_sigma_m=0.0, origin_s=0.0)
    bench.start_sweep(SWEEP)
    bench.clock.advance(1.5)
    with (
        _serve(transport, {1: amplifier}) as server,
        ZxlAmplifier.open(server.device_url(1), config=config, link=FAST) as driver,
    ):
        before = server.commands_received
        read = driver.read_stream(1000)
        # the counter; the ring from slot 501 (sample 501) to 999, then 0 to 500, in 20 + 21 requests of at
        # most 25; the counter again (every slot was read)
        assert server.commands_received - before == 1 + 20 + 21 + 1
        assert read.counter == amplifier.samples_taken == 1501
        newest_s = (read.counter - 1) * 0.001  # sample k is taken at k ms (origin 0)
        expected = [
            amplifier.head.quantise_m(bench.position_m("x_r", newest_s - k * 0.001)) for k in range(5)
        ]
        assert [c * 1e-9 for c in read.counts[:5]] == pytest.approx(expected, abs=1e-9)
        assert len(set(read.counts)) > 900  # every slot its own sample (the plate moves)


# --- faults --------------------------------------------------------------------------------------------

FAULTS = [
    (FaultKind.NO_REPLY, "", errors.ResponseTimeoutError),
    (FaultKind.GARBAGE, "", errors.MalformedFrameError),
    (FaultKind.BAD_BCC, "", errors.BccMismatchError),
    (FaultKind.OUT_OF_RANGE, "", errors.MeasurementOutOfRangeError),
    (FaultKind.INCOMPLETE, "", errors.IncompleteResponseError),
    *[(FaultKind.END_CODE, code, cls) for code, cls in sorted(errors.END_CODE_ERRORS.items())],
    *[(FaultKind.RESPONSE_CODE, code, cls) for code, cls in sorted(errors.RESPONSE_CODE_ERRORS.items())],
]


@pytest.mark.parametrize(
    ("kind", "code", "error"), FAULTS, ids=[f"{k}-{c}" if c else str(k) for k, c, _ in FAULTS]
)
def test_fault_gives_typed_error_then_clean_recovery(
    rig: Rig, kind: FaultKind, code: str, error: type[errors.CompowayFError]
) -> None:
    bench, server, driver = rig.bench, rig.server, rig.driver
    bench.clock.advance(0.1)
    server.inject_fault(kind, code)
    with pytest.raises(error) as info:
        driver.read_position_m()
    assert "\n" not in str(info.value)
    with pytest.raises(error):  # still there until cleared
        driver.read_position_m()
    server.clear_faults()
    assert driver.read_position_m() == pytest.approx(bench.position_m("x_r"), abs=1e-6)


def test_dropped_tcp_connection_is_port_lost_then_reopened(bench: EmptyPlate) -> None:
    with (
        TcpAmplifierServer({1: SimulatedAmplifier.for_channel(bench, "x_r", noise_sigma_m=0.0)}) as server,
        ZxlAmplifier.open(server.device_url(1), link=FAST) as driver,
    ):
        assert driver.read_position_m() == 0.0
        server.inject_fault(FaultKind.DROP_CONNECTION, count=1)
        with pytest.raises(errors.PortLostError, match="port lost"):
            driver.read_position_m()
        assert driver.read_position_m() == 0.0
        assert driver.port.counters.reopens == 1 and server.connections_accepted == 2


def test_server_gone_is_port_lost(bench: EmptyPlate) -> None:
    server = TcpAmplifierServer({1: SimulatedAmplifier.for_channel(bench, "x_r")}).start()
    driver = ZxlAmplifier.open(server.device_url(1), link=replace(FAST, retries=1))
    driver.read_counts()
    server.stop()
    with pytest.raises(errors.PortLostError, match="re-open failed"):
        driver.read_counts()
    driver.close()


@pytest.mark.parametrize(
    ("kind", "code"),
    [
        (FaultKind.NO_REPLY, ""),
        (FaultKind.GARBAGE, ""),
        (FaultKind.BAD_BCC, ""),
        (FaultKind.INCOMPLETE, ""),
        (FaultKind.END_CODE, "13"),
        (FaultKind.END_CODE, "10"),
    ],
)
def test_retries_hide_a_one_off_fault(rig: Rig, kind: FaultKind, code: str) -> None:
    bench, server, driver = rig.bench, rig.server, rig.driver
    driver.port.link = replace(FAST, retries=2)
    retries_before = driver.port.counters.retries
    bench.clock.advance(0.01)
    server.inject_fault(kind, code, count=1)
    assert driver.read_position_m() == pytest.approx(bench.position_m("x_r"), abs=1e-6)
    assert driver.port.counters.retries == retries_before + 1 and driver.read_rate().failures == 0


def test_dropped_connection_hidden_by_retry(bench: EmptyPlate) -> None:
    with (
        TcpAmplifierServer({1: SimulatedAmplifier.for_channel(bench, "x_r", noise_sigma_m=0.0)}) as server,
        ZxlAmplifier.open(server.device_url(1), link=replace(FAST, retries=1)) as driver,
    ):
        server.inject_fault(FaultKind.DROP_CONNECTION, count=1)
        assert driver.read_position_m() == 0.0
        assert driver.port.counters.reopens == 1


def test_refusal_is_not_retried_by_the_link(rig: Rig) -> None:
    server, driver = rig.server, rig.driver
    driver.port.link = replace(FAST, retries=2)
    server.inject_fault(FaultKind.RESPONSE_CODE, "2204", count=2)
    before = server.commands_received
    with pytest.raises(errors.NotInRunModeError, match="2204"):
        driver.read_position_m()
    assert server.commands_received == before + 1
    with pytest.raises(errors.NotInRunModeError):
        driver.read_position_m()
    driver.read_position_m()


def test_fault_for_one_node_only(bench: EmptyPlate, transport: str) -> None:
    amplifiers = {n: SimulatedAmplifier.for_channel(bench, "x_r", noise_sigma_m=0.0) for n in (1, 2)}
    with _serve(transport, amplifiers) as server, CompowayFPort(server.device_url(1), link=FAST) as port:
        server.inject_fault(FaultKind.OUT_OF_RANGE, node=2)
        assert ZxlAmplifier(port, 1).read_position_m() == 0.0
        with pytest.raises(errors.MeasurementOutOfRangeError):
            ZxlAmplifier(port, 2).read_position_m()
        assert math.isnan(ZxlAmplifier(port, 2).read_samples_m(1)[0])


def test_fault_arguments_are_checked(bench: EmptyPlate) -> None:
    line = AmplifierLine({1: SimulatedAmplifier.for_channel(bench, "x_r")})
    with pytest.raises(ValueError):
        line.inject_fault(FaultKind.END_CODE)
    with pytest.raises(ValueError):
        line.inject_fault(FaultKind.RESPONSE_CODE, "22")
    with pytest.raises(ValueError):
        line.inject_fault(FaultKind.NO_REPLY, count=0)


# --- rate -----------------------------------------------------------------------------------------------


def test_read_rate_is_measured_and_sane(rig: Rig) -> None:
    server, driver = rig.server, rig.driver
    report = driver.measure_read_rate(50)
    assert report.reads == 50 and report.samples == 50 and report.failures == 0
    assert report.reads_per_s > 0 and report.elapsed_s > 0
    assert 0 < report.mean_latency_s <= report.max_latency_s <= report.elapsed_s
    assert report.reads_per_s <= 1.0 / report.mean_latency_s * 1.000001  # no faster than back-to-back latency
    server.inject_fault(FaultKind.NO_REPLY, count=1)
    report = driver.measure_read_rate(10)
    assert (report.reads, report.failures) == (9, 1)
    assert report.max_latency_s < FAST.timeout_s  # failed reads do not count as latency samples


# --- heads ----------------------------------------------------------------------------------------------


def test_head_range_resolution_sign_and_noise(bench: EmptyPlate) -> None:
    bench.start_sweep(SWEEP)
    bench.clock.advance(0.1)
    up_m = bench.position_m("x_r")
    above = SimulatedHead(ZX_LD40, bench, "x_r", noise_sigma_m=0.0)
    below = SimulatedHead(ZX_LD40, bench, "x_r", sign=-1, noise_sigma_m=0.0)
    assert above.measure_m() == pytest.approx(up_m, abs=1e-6) and below.measure_m() == pytest.approx(
        -up_m, abs=1e-6
    )
    assert SimulatedHead(ZX_LD40, bench, "x_s", static_offset_m=0.0101).measure_m() is None
    assert SimulatedHead(ZX_LD100, bench, "x_s", static_offset_m=-0.0399, noise_sigma_m=0.0).measure_m() == (
        pytest.approx(-0.0399, abs=8e-6)
    )
    noisy = [SimulatedHead(ZX_LD40, bench, "x_s", seed=3) for _ in range(2)]
    draws = np.array([[head.measure_m() for _ in range(400)] for head in noisy])
    assert np.array_equal(draws[0], draws[1])  # same seed, same noise
    assert 0.5e-6 < draws[0].std() < 2e-6  # sigma 1 µm, quantised to 2 µm
    assert np.allclose(np.round(draws[0] / 2e-6) * 2e-6, draws[0])
