"""ZX-L amplifier driver against a replay port (as PyMeasure's expected_protocol): each write must be exactly
the expected command bytes, the given reply bytes are then readable, and at the end every expected exchange
and every reply byte must have been consumed. Frames are written out by hand; BCCs worked out in comments
('0' = 0x30, '1' = 0x31, 'C' = 0x43, 'F' = 0x46, ETX = 0x03; pairs of equal characters cancel)."""

from __future__ import annotations

import math
import socket
from collections.abc import Iterator
from dataclasses import replace

import pytest

from drivers.compowayf import errors
from drivers.compowayf.amplifier import (
    AmplifierConfig,
    CountUnit,
    MeasuredArea,
    MeasuredValueConfig,
    ZxlAmplifier,
)
from drivers.compowayf.rate import RateMeter
from drivers.compowayf.transport import CompowayFPort, LinkSettings
from drivers.compowayf.urls import SerialSettings, parse_device_url

# Node 01 reads variable area C0, address 0000, 1 element: '0' x16, '1' x4 cancel; 0x43 ^ 0x03 = 0x40
READ_ONE = b"\x02" + b"01" + b"00" + b"0" + b"0101" + b"C0" + b"0000" + b"00" + b"0001" + b"\x03" + b"\x40"
# Reply -1000 counts (FFFFFC18): '0' x11 -> 0x30, 'F' x5 -> 0x46, '1' x4, 0x43, 0x38, 0x03 -> 0x0E
REPLY_MINUS_1000 = b"\x02" + b"01" + b"00" + b"00" + b"0101" + b"0000" + b"FFFFFC18" + b"\x03" + b"\x0e"
# Reply out-of-range marker 7FFFFFFF: '0' x11 -> 0x30, 'F' x7 -> 0x46, '1' x3 -> 0x31, '7' 0x37, ETX:
# 0x30^0x46 = 0x76, ^0x31 = 0x47, ^0x37 = 0x70, ^0x03 = 0x73
REPLY_OUT_OF_RANGE = b"\x02" + b"01" + b"00" + b"00" + b"0101" + b"0000" + b"7FFFFFFF" + b"\x03" + b"\x73"
# Node 01 reads 2 elements: "01" "00" "0" "0101" "C0" "0000" "00" "0002": '0' x16 -> 0, '1' x3 -> 0x31,
# 'C' 0x43, '2' 0x32, ETX: 0x31^0x43 = 0x72, ^0x32 = 0x40, ^0x03 = 0x43
READ_TWO = b"\x02" + b"01" + b"00" + b"0" + b"0101" + b"C0" + b"0000" + b"00" + b"0002" + b"\x03" + b"\x43"
# Reply newest first: 1000 (000003E8) then -1000 (FFFFFC18): '0' x16, '1' x4, '8' x2 cancel; 'F' x5 -> 0x46,
# '3' 0x33, 'E' 0x45, 'C' 0x43, ETX: 0x46^0x33 = 0x75, ^0x45 = 0x30, ^0x43 = 0x73, ^0x03 = 0x70
REPLY_TWO = (
    b"\x02" + b"01" + b"00" + b"00" + b"0101" + b"0000" + b"000003E8" + b"FFFFFC18" + b"\x03" + b"\x70"
)
# Parameter area read C000/0000, 1 element (8001): "01" "00" "0" "0201" "C000" "0000" "8001" ETX:
# '0' x15 -> 0x30, '1' x3 -> 0x31, '2' 0x32, 'C' 0x43, '8' 0x38: 0x30^0x31 = 0x01, ^0x32 = 0x33, ^0x43 = 0x70,
# ^0x38 = 0x48, ^0x03 = 0x4B
PARAM_READ = b"\x02" + b"01" + b"00" + b"0" + b"0201" + b"C000" + b"0000" + b"8001" + b"\x03" + b"\x4b"
# Reply echoes the request, value 00000064 (100 counts): "01" "00" "00" "0201" "0000" "C000" "0000" "8001"
# "00000064": '0' x26 -> 0, '1' x3 -> 0x31, '2' 0x32, 'C' 0x43, '8' 0x38, '6' 0x36, '4' 0x34, ETX:
# 0x31^0x32 = 0x03, ^0x43 = 0x40, ^0x38 = 0x78, ^0x36 = 0x4E, ^0x34 = 0x7A, ^0x03 = 0x79
PARAM_REPLY = (
    b"\x02"
    + b"01"
    + b"00"
    + b"00"
    + b"0201"
    + b"0000"
    + b"C000"
    + b"0000"
    + b"8001"
    + b"00000064"
    + b"\x03"
    + b"\x79"
)
# Model read, node 01: "01" "00" "0" "0503" ETX: '0' x6 -> 0, '1' 0x31, '5' 0x35, '3' 0x33:
# 0x31^0x35 = 0x04, ^0x33 = 0x37, ^0x03 = 0x34
MODEL = b"\x02" + b"01" + b"00" + b"0" + b"0503" + b"\x03" + b"\x34"
# Reply model "ZX-LDA11-N" and buffer size 00D9 (217 bytes): "01" "00" "00" "0503" "0000" "ZX-LDA11-N"
# "00D9" ETX: '0' x13 -> 0x30, '1' x3 -> 0x31, '5' 0x35, '3' 0x33, '-' x2 -> 0, 'Z' 0x5A, 'X' 0x58,
# 'L' 0x4C, 'D' x2 -> 0, 'A' 0x41, 'N' 0x4E, '9' 0x39, ETX: 0x30^0x31 = 0x01, ^0x35 = 0x34, ^0x33 = 0x07,
# ^0x5A = 0x5D, ^0x58 = 0x05, ^0x4C = 0x49, ^0x41 = 0x08, ^0x4E = 0x46, ^0x39 = 0x7F, ^0x03 = 0x7C
MODEL_REPLY = (
    b"\x02" + b"01" + b"00" + b"00" + b"0503" + b"0000" + b"ZX-LDA11-N" + b"00D9" + b"\x03" + b"\x7c"
)
# Zero reset (placeholder code 01/00), node 01: "01" "00" "0" "3005" "0100": '0' x9 -> 0x30, '1' x2 -> 0,
# '3' 0x33, '5' 0x35: 0x30^0x33 = 0x03, ^0x35 = 0x36, ^0x03 = 0x35
ZERO_RESET = b"\x02" + b"01" + b"00" + b"0" + b"3005" + b"0100" + b"\x03" + b"\x35"
# Reply "01" "00" "00" "3005" "0000": '0' x11 -> 0x30, '1' 0x31, '3' 0x33, '5' 0x35: 0x30^0x31 = 0x01,
# ^0x33 = 0x32, ^0x35 = 0x07, ^0x03 = 0x04
ZERO_RESET_REPLY = b"\x02" + b"01" + b"00" + b"00" + b"3005" + b"0000" + b"\x03" + b"\x04"
# Variable read reply with response code 1101 (area type error), no data: "01" "00" "00" "0101" "1101":
# '0' x8 -> 0, '1' x6 -> 0, so BCC = ETX = 0x03 (a BCC equal to ETX must not confuse the reader)
REPLY_1101 = b"\x02" + b"01" + b"00" + b"00" + b"0101" + b"1101" + b"\x03" + b"\x03"


class ReplayPort:
    """A pyserial stand-in that replays a scripted conversation."""

    def __init__(self, exchanges: list[tuple[bytes, bytes]]) -> None:
        self.exchanges = list(exchanges)
        self.timeout: float | None = 0.0
        self.closed = False
        self._rx = bytearray()

    @property
    def in_waiting(self) -> int:
        return len(self._rx)

    def reset_input_buffer(self) -> None:
        assert not self._rx, f"unread reply bytes left over: {bytes(self._rx)!r}"

    def write(self, data: bytes) -> int:
        assert self.exchanges, f"unexpected command {data!r}"
        expected, reply = self.exchanges.pop(0)
        assert data == expected, f"command {data!r}, expected {expected!r}"
        self._rx += reply
        return len(data)

    def read(self, size: int = 1) -> bytes:
        chunk = bytes(self._rx[:size])
        del self._rx[:size]
        return chunk

    def close(self) -> None:
        self.closed = True

    def assert_consumed(self) -> None:
        assert not self.exchanges, f"{len(self.exchanges)} expected exchange(s) never happened"
        assert not self._rx, f"reply bytes never read: {bytes(self._rx)!r}"


@pytest.fixture
def replay() -> Iterator[list[ReplayPort]]:
    """Collects the replay ports a test creates and checks each was consumed completely."""
    ports: list[ReplayPort] = []
    yield ports
    for port in ports:
        port.assert_consumed()


VARIABLE_C0 = MeasuredValueConfig(area=MeasuredArea.VARIABLE, area_type=0xC0, address=0x0000)
"""The frames above read variable area C0 from address 0000 (an E5CC-like layout, not the ZX default)."""


def _amplifier(
    ports: list[ReplayPort],
    exchanges: list[tuple[bytes, bytes]],
    measured: MeasuredValueConfig | None = None,
    retries: int = 0,
) -> ZxlAmplifier:
    port = ReplayPort(exchanges)
    ports.append(port)
    config = AmplifierConfig(measured=measured or VARIABLE_C0)
    link = LinkSettings(timeout_s=0.05, retries=retries, late_reply_s=0.05)
    return ZxlAmplifier.open("loop://?node=1", config=config, link=link, opener=lambda: port)


def test_read_position_m(replay: list[ReplayPort]) -> None:
    amplifier = _amplifier(replay, [(READ_ONE, REPLY_MINUS_1000)])
    assert amplifier.read_position_m() == pytest.approx(-1000e-9)


def test_count_unit_tenth_micrometre(replay: list[ReplayPort]) -> None:
    measured = replace(VARIABLE_C0, count_unit=CountUnit.TENTH_MICROMETRE)
    amplifier = _amplifier(replay, [(READ_ONE, REPLY_MINUS_1000)], measured)
    assert amplifier.read_position_m() == pytest.approx(-1000e-7)


def test_buffer_read_is_returned_oldest_first(replay: list[ReplayPort]) -> None:
    amplifier = _amplifier(
        replay, [(READ_TWO, REPLY_TWO), (READ_TWO, REPLY_TWO)], replace(VARIABLE_C0, buffer_length=2)
    )
    assert amplifier.read_counts(2) == [1000, -1000]  # amplifier order: newest first
    assert amplifier.read_samples_m(2) == pytest.approx([-1e-6, 1e-6])
    with pytest.raises(ValueError, match="buffer_length"):
        amplifier.read_counts(3)


def test_out_of_range_marker(replay: list[ReplayPort]) -> None:
    amplifier = _amplifier(replay, [(READ_ONE, REPLY_OUT_OF_RANGE), (READ_ONE, REPLY_OUT_OF_RANGE)])
    with pytest.raises(errors.MeasurementOutOfRangeError, match="7FFFFFFF"):
        amplifier.read_position_m()
    assert math.isnan(amplifier.read_samples_m(1)[0])


def test_measured_value_in_parameter_area(replay: list[ReplayPort]) -> None:
    measured = MeasuredValueConfig(area=MeasuredArea.PARAMETER, area_type=0xC000, address=0x0000)
    amplifier = _amplifier(replay, [(PARAM_READ, PARAM_REPLY)], measured)
    assert amplifier.read_position_m() == pytest.approx(100e-9)


def test_model_and_zero_reset(replay: list[ReplayPort]) -> None:
    amplifier = _amplifier(replay, [(MODEL, MODEL_REPLY), (ZERO_RESET, ZERO_RESET_REPLY)])
    assert amplifier.read_model() == "ZX-LDA11-N"
    assert amplifier.buffer_size_bytes == 217
    amplifier.zero_reset()


def test_retryable_error_is_retried_then_succeeds(replay: list[ReplayPort]) -> None:
    bad_bcc = REPLY_MINUS_1000[:-1] + b"\x0f"
    amplifier = _amplifier(replay, [(READ_ONE, bad_bcc), (READ_ONE, REPLY_MINUS_1000)], retries=1)
    assert amplifier.read_position_m() == pytest.approx(-1e-6)
    assert amplifier.port.counters.retries == 1


def test_retries_are_bounded_and_raise_the_last_error(replay: list[ReplayPort]) -> None:
    bad_bcc = REPLY_MINUS_1000[:-1] + b"\x0f"
    amplifier = _amplifier(replay, [(READ_ONE, bad_bcc)] * 3, retries=2)
    with pytest.raises(errors.BccMismatchError):
        amplifier.read_position_m()
    assert amplifier.port.counters.failures == 1
    assert amplifier.read_rate().failures == 1


def test_refusal_is_not_retried(replay: list[ReplayPort]) -> None:
    amplifier = _amplifier(replay, [(READ_ONE, REPLY_1101)], retries=2)  # one exchange only
    with pytest.raises(errors.AreaTypeError, match="node 01, service 0101: response code 1101"):
        amplifier.read_position_m()


def test_incomplete_reply_counts_as_timeout(replay: list[ReplayPort]) -> None:
    amplifier = _amplifier(replay, [(READ_ONE, REPLY_MINUS_1000[:-2])])
    with pytest.raises(errors.ResponseTimeoutError, match="incomplete"):
        amplifier.read_position_m()


def test_no_reply_is_a_timeout(replay: list[ReplayPort]) -> None:
    amplifier = _amplifier(replay, [(READ_ONE, b"")])
    with pytest.raises(errors.ResponseTimeoutError, match=r"no reply within 0\.05 s"):
        amplifier.read_position_m()


def test_reply_from_another_node_is_discarded_not_returned(replay: list[ReplayPort]) -> None:
    # REPLY_MINUS_1000 with node "02": one '1' becomes '2', so BCC = 0x0E ^ 0x31 ^ 0x32 = 0x0D
    other_node = b"\x02" + b"02" + b"00" + b"00" + b"0101" + b"0000" + b"FFFFFC18" + b"\x03" + b"\x0d"
    amplifier = _amplifier(replay, [(READ_ONE, other_node)])
    with pytest.raises(errors.ResponseTimeoutError, match="no reply"):
        amplifier.read_position_m()
    assert amplifier.port.counters.discarded_frames == 1


def test_rate_meter_with_a_fake_clock() -> None:
    ticks = iter([0.0, 0.01, 0.02, 0.05, 0.06, 0.07])
    meter = RateMeter(clock=lambda: next(ticks))
    for _ in range(3):
        started = meter.clock()
        meter.record(started, meter.clock(), samples=2, ok=True)
    report = meter.report()
    assert (report.reads, report.samples, report.failures) == (3, 6, 0)
    assert report.elapsed_s == pytest.approx(0.07)
    assert report.reads_per_s == pytest.approx(3 / 0.07)
    assert report.mean_latency_s == pytest.approx(0.05 / 3) and report.max_latency_s == pytest.approx(0.03)
    meter.reset()
    assert meter.report().reads == 0 and meter.report().reads_per_s == 0.0


def test_device_urls() -> None:
    url = parse_device_url("serial:///dev/ttyUSB0?baudrate=9600&parity=E&stopbits=2&bytesize=7&node=3")
    assert url.pyserial_url == "/dev/ttyUSB0" and url.node == 3
    assert url.serial == SerialSettings(baudrate=9600, bytesize=7, parity="E", stopbits=2)
    url = parse_device_url("socket://127.0.0.1:9000?node=2&logging=debug&timeout_s=0.3&retries=1")
    assert url.pyserial_url == "socket://127.0.0.1:9000?logging=debug"
    assert (url.node, url.timeout_s, url.retries) == (2, 0.3, 1)
    assert parse_device_url("/dev/pts/4?node=0").pyserial_url == "/dev/pts/4"
    assert parse_device_url("serial://COM3?node=1").pyserial_url == "COM3"
    assert parse_device_url("socket://localhost:1").node is None
    for bad in (
        "serial:///dev/ttyS0?node=100",
        "serial:///dev/ttyS0?foo=1",
        "/dev/ttyS0?baudrate=fast",
        "serial:///dev/ttyS0?parity=Q",
        "serial:///dev/ttyS0?bytesize=9",
        "serial://?node=1",
    ):
        with pytest.raises(errors.DeviceUrlError):
            parse_device_url(bad)


def test_node_is_required() -> None:
    with pytest.raises(errors.DeviceUrlError, match="no node"):
        ZxlAmplifier.open("loop://", opener=lambda: ReplayPort([]))


def test_port_that_will_not_open() -> None:
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        free_port = probe.getsockname()[1]
    with pytest.raises(errors.PortOpenError, match="cannot open"):
        CompowayFPort(f"socket://127.0.0.1:{free_port}?node=1")


def test_closed_port_refuses_requests(replay: list[ReplayPort]) -> None:
    amplifier = _amplifier(replay, [])
    amplifier.close()
    assert replay[0].closed
    with pytest.raises(errors.PortError, match="closed"):
        amplifier.read_position_m()


def test_measured_value_config_checks() -> None:
    config = MeasuredValueConfig()
    assert config.element_width == 8 and config.out_of_range_marker == 0x7FFFFFFF
    assert config.m_to_counts(1.5e-6) == 1500 and config.counts_to_m(1500) == pytest.approx(1.5e-6)
    with pytest.raises(ValueError):
        MeasuredValueConfig(buffer_length=0)
    with pytest.raises(ValueError):
        MeasuredValueConfig(area=MeasuredArea.VARIABLE, area_type=0x1C0)
    with pytest.raises(ValueError):
        MeasuredValueConfig(address=0xFFFF, buffer_length=2)
