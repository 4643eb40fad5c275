"""Driver for an OMRON ZX-L-N laser displacement amplifier (ZX-LDA) speaking CompoWay/F, directly over
RS-485 or through the ZX-SF11 interface unit (RS-232C).

Where the measured value lives (variable or parameter area, type, address, buffer length), how its counts
scale to metres and which count value means "out of range" are configuration (`MeasuredValueConfig`),
because OMRON's address maps differ between amplifier generations. The simulated amplifier uses the same
dataclasses, so driver and simulator agree by construction; check the defaults against the communication
manual of the actual amplifier before trusting a real reading.

Sign: the driver reports what the amplifier reports, scaled to metres. The simulator's convention (see
simulators/devices/sensor_heads.py) is positive toward the head.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field
from enum import Enum, StrEnum

from drivers.compowayf.codec import (
    Service,
    StatusReport,
    decode_values,
    encode_operation_command,
    encode_parameter_area_read,
    encode_parameter_area_write,
    encode_variable_area_read,
    parameter_element_width,
    variable_element_width,
)
from drivers.compowayf.errors import (
    CompowayFError,
    DeviceUrlError,
    MeasurementOutOfRangeError,
    UnexpectedResponseError,
)
from drivers.compowayf.rate import RateMeter, ReadRate
from drivers.compowayf.transport import CompowayFPort, LinkSettings, Opener
from drivers.compowayf.urls import SerialSettings, parse_device_url


class MeasuredArea(StrEnum):
    """Which CompoWay/F area holds the measured value: variable area (read with 0101) or parameter area
    (read with 0201)."""

    VARIABLE = "variable"
    PARAMETER = "parameter"


class CountUnit(Enum):
    """Length of one count of the measured value, in metres."""

    NANOMETRE = 1e-9
    TENTH_MICROMETRE = 1e-7

    @property
    def metres(self) -> float:
        return float(self.value)


@dataclass(frozen=True)
class MeasuredValueConfig:
    """Where and how an amplifier exposes its measured value.

    area / area_type / address: the area, its type code (variable type, 2 hex digits, e.g. 0xC0 for a
        double-word area; or parameter type, 4 hex digits, e.g. 0xC000) and the first element's address.
        Defaults (variable area C0, address 0000) are an assumption, not taken from a ZX-L manual.
    buffer_length: how many consecutive elements from `address` hold samples, newest first (1 = only the
        current value; N = the current value and the N-1 before it).
    count_unit: metres per count (signed 32-bit counts for double-word areas); OMRON's ZS/ZX-L send nm.
    out_of_range_counts: count values that mean "no valid measurement" (OMRON uses 7FFFFFFx-style
        markers); the first one is what the simulator sends.
    sample_period_s: the amplifier's own sampling period when it samples on its own clock and buffers
        (None: it holds only the value at the moment of the read, which the host then timestamps).
    counter_address: with sample_period_s, the address of a sample counter (samples taken since the
        amplifier started, modulo 2**31) directly before the newest sample (address - 1), so that one
        read returns the counter and the newest samples together: the counter is the device clock
        (time = counter * sample_period_s) and tells how many samples are new since the last read.
    """

    area: MeasuredArea = MeasuredArea.VARIABLE
    area_type: int = 0xC0
    address: int = 0x0000
    buffer_length: int = 1
    count_unit: CountUnit = CountUnit.NANOMETRE
    out_of_range_counts: tuple[int, ...] = (0x7FFFFFFF,)
    sample_period_s: float | None = None
    counter_address: int | None = None

    def __post_init__(self) -> None:
        if self.buffer_length < 1:
            raise ValueError(f"buffer_length must be >= 1, got {self.buffer_length}")
        if self.sample_period_s is not None and not (
            math.isfinite(self.sample_period_s) and self.sample_period_s > 0
        ):
            raise ValueError(f"sample_period_s must be positive, got {self.sample_period_s}")
        if self.counter_address is not None:
            if self.sample_period_s is None:
                raise ValueError("a sample counter needs the sample_period_s it counts")
            if self.counter_address != self.address - 1:
                raise ValueError(
                    f"the sample counter must sit directly before the newest sample (address "
                    f"0x{self.address - 1:04X}), got 0x{self.counter_address:04X}"
                )
        if not self.out_of_range_counts:
            raise ValueError("at least one out-of-range marker is needed")
        type_max = 0xFF if self.area is MeasuredArea.VARIABLE else 0xFFFF
        if not 0 <= self.area_type <= type_max:
            raise ValueError(f"area_type 0x{self.area_type:X} does not fit a {self.area} area")

    @property
    def element_width(self) -> int:
        """Hex characters per element in the reply."""
        if self.area is MeasuredArea.VARIABLE:
            return variable_element_width(self.area_type)
        return parameter_element_width(self.area_type)

    @property
    def out_of_range_marker(self) -> int:
        return self.out_of_range_counts[0]

    def is_out_of_range(self, counts: int) -> bool:
        return counts in self.out_of_range_counts

    def counts_to_m(self, counts: int) -> float:
        """Metres for a count value; NaN for an out-of-range marker."""
        return math.nan if self.is_out_of_range(counts) else counts * self.count_unit.metres

    def m_to_counts(self, value_m: float) -> int:
        return round(value_m / self.count_unit.metres)

    @property
    def is_streaming(self) -> bool:
        """True when the amplifier samples on its own clock and exposes a sample counter."""
        return self.counter_address is not None


COUNTER_MODULUS = 2**31
"""The sample counter wraps here (a non-negative signed double word)."""

STREAM_BUFFER_LENGTH = 256
"""Samples a streaming amplifier keeps by default: 256 ms at 1 kHz, so a host may pause that long between
reads without losing a sample."""


def streaming_measured_config(
    sample_period_s: float = 0.001, buffer_length: int = STREAM_BUFFER_LENGTH
) -> MeasuredValueConfig:
    """The layout of an amplifier that samples on its own clock: the sample counter at variable area C0
    address 0000, the newest sample at 0001, older ones after it. An assumed layout (no ZX-L manual was at
    hand); the simulated amplifier serves exactly this."""
    return MeasuredValueConfig(
        address=0x0001, buffer_length=buffer_length, sample_period_s=sample_period_s, counter_address=0x0000
    )


@dataclass(frozen=True)
class StreamRead:
    """One read of a streaming amplifier: the sample counter and the newest samples.

    counter: samples taken since the amplifier started, modulo COUNTER_MODULUS; the newest sample is
        number counter - 1. counts: raw counts, newest first (markers included).
    """

    counter: int
    counts: list[int]


@dataclass(frozen=True)
class OperationCodes:
    """Command code + related information of the operation commands (3005) the driver sends.

    The defaults are placeholders (OMRON assigns codes per amplifier generation); the simulator honours
    whatever is configured here.
    """

    zero_reset: tuple[int, int] = (0x01, 0x00)
    zero_reset_cancel: tuple[int, int] = (0x01, 0x01)


@dataclass(frozen=True)
class AmplifierConfig:
    """Everything that describes one amplifier on the line besides its node number."""

    measured: MeasuredValueConfig = field(default_factory=MeasuredValueConfig)
    operations: OperationCodes = field(default_factory=OperationCodes)


class ZxlAmplifier:
    """One ZX-L amplifier (one CompoWay/F node) on a CompowayFPort.

    Several instances may share a port (RS-485 multi-drop); the one created by `open` owns its port and
    closes it on close(). Every measured-value read is timed for `read_rate()`.
    """

    def __init__(self, port: CompowayFPort, node: int, config: AmplifierConfig | None = None) -> None:
        if not 0 <= node <= 99:
            raise ValueError(f"CompoWay/F node number must be 0..99, got {node}")
        self.port = port
        self.node = node
        self.config = config or AmplifierConfig()
        self._rate = RateMeter()
        self._owns_port = False

    @classmethod
    def open(
        cls,
        url: str,
        *,
        node: int | None = None,
        config: AmplifierConfig | None = None,
        serial_settings: SerialSettings | None = None,
        link: LinkSettings | None = None,
        opener: Opener | None = None,
    ) -> ZxlAmplifier:
        """Open a port for `url` and return the amplifier at `node` (argument, else the URL's node=)."""
        url_node = parse_device_url(url).node
        node = node if node is not None else url_node
        if node is None:
            raise DeviceUrlError(f"no node number: pass node= or put ?node=N in {url!r}")
        port = CompowayFPort(url, serial_settings=serial_settings, link=link, opener=opener)
        amplifier = cls(port, node, config)
        amplifier._owns_port = True
        return amplifier

    def close(self) -> None:
        if self._owns_port:
            self.port.close()

    def __enter__(self) -> ZxlAmplifier:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- services --------------------------------------------------------------------------------------

    def _request(self, service: Service, data: str = "") -> str:
        return self.port.request(self.node, service, data).data

    def read_variable_area(self, variable_type: int, start_address: int, count: int) -> list[int]:
        """0101: `count` signed elements from a variable area."""
        request = encode_variable_area_read(variable_type, start_address, count)
        data = self._request(Service.VARIABLE_AREA_READ, request)
        return decode_values(data, variable_element_width(variable_type), count)

    def read_parameter_area(self, parameter_type: int, start_address: int, count: int) -> list[int]:
        """0201: `count` signed elements from a parameter area (the reply echoes type, address, count)."""
        request = encode_parameter_area_read(parameter_type, start_address, count)
        data = self._request(Service.PARAMETER_AREA_READ, request)
        if data[:12].upper() != request:
            raise UnexpectedResponseError(f"parameter read echoed {data[:12]!r}, asked {request!r}")
        return decode_values(data[12:], parameter_element_width(parameter_type), count)

    def write_parameter_area(self, parameter_type: int, start_address: int, values: list[int]) -> None:
        """0202: write consecutive elements of a parameter area."""
        request = encode_parameter_area_write(parameter_type, start_address, values)
        self._request(Service.PARAMETER_AREA_WRITE, request)

    def read_model(self) -> str:
        """0503: the amplifier's model name."""
        return self._request(Service.MODEL_READ).strip()

    def read_status(self) -> StatusReport:
        """0601: operating status and related information (raw bytes; meaning is model specific)."""
        return StatusReport.decode(self._request(Service.STATUS_READ))

    def echo(self, text: str) -> str:
        """0801: send `text` (printable ASCII) and check that it comes back unchanged."""
        echoed = self._request(Service.ECHO_BACK, text)
        if echoed != text:
            raise UnexpectedResponseError(f"echo-back returned {echoed!r} for {text!r}")
        return echoed

    def operation_command(self, command_code: int, related_info: int = 0) -> None:
        """3005: an operation command (command code + related information)."""
        self._request(Service.OPERATION_COMMAND, encode_operation_command(command_code, related_info))

    def zero_reset(self) -> None:
        """Make the present reading the amplifier's zero (operation command from the configuration)."""
        self.operation_command(*self.config.operations.zero_reset)

    def zero_reset_cancel(self) -> None:
        self.operation_command(*self.config.operations.zero_reset_cancel)

    # --- measured value --------------------------------------------------------------------------------

    def _read_measured(self, address: int, count: int, samples: int) -> list[int]:
        """`count` elements of the measured area from `address`, timed for read_rate() as `samples`."""
        measured = self.config.measured
        started_s = self._rate.clock()
        ok = False
        try:
            if measured.area is MeasuredArea.VARIABLE:
                values = self.read_variable_area(measured.area_type, address, count)
            else:
                values = self.read_parameter_area(measured.area_type, address, count)
            ok = True
            return values
        finally:
            self._rate.record(started_s, self._rate.clock(), samples, ok)

    def _check_count(self, count: int) -> None:
        length = self.config.measured.buffer_length
        if not 1 <= count <= length:
            raise ValueError(f"count must be 1..{length} (buffer_length), got {count}")

    def read_counts(self, count: int = 1) -> list[int]:
        """The newest `count` samples as raw counts, newest first, as the amplifier holds them (markers
        included). Timed for read_rate(); count may not exceed the configured buffer_length."""
        self._check_count(count)
        return self._read_measured(self.config.measured.address, count, count)

    def read_stream(self, count: int) -> StreamRead:
        """Counter and newest `count` samples in one request (streaming layout only, count <= buffer_length).
        Timed for read_rate() like read_counts."""
        counter_address = self.config.measured.counter_address
        if counter_address is None:
            raise ValueError("this amplifier's configuration has no sample counter (not a streaming layout)")
        self._check_count(count)
        values = self._read_measured(counter_address, count + 1, count)
        if not 0 <= values[0] < COUNTER_MODULUS:
            raise UnexpectedResponseError(f"node {self.node:02d}: sample counter {values[0]} out of range")
        return StreamRead(values[0], values[1:])

    def read_position_m(self) -> float:
        """The current measured value in metres. Raises MeasurementOutOfRangeError on the marker."""
        counts = self.read_counts(1)[0]
        if self.config.measured.is_out_of_range(counts):
            raise MeasurementOutOfRangeError(
                f"node {self.node:02d}: out of measuring range (marker 0x{counts & 0xFFFFFFFF:08X})"
            )
        return self.config.measured.counts_to_m(counts)

    def read_samples_m(self, count: int) -> list[float]:
        """The newest `count` buffered samples in metres, oldest first (chronological); NaN where the
        amplifier reported out of range."""
        return [self.config.measured.counts_to_m(c) for c in reversed(self.read_counts(count))]

    # --- rate ------------------------------------------------------------------------------------------

    def read_rate(self) -> ReadRate:
        """Rate and latency of the measured-value reads since the last reset."""
        return self._rate.report()

    def reset_read_rate(self) -> None:
        self._rate.reset()

    def measure_read_rate(self, n_reads: int, count: int = 1) -> ReadRate:
        """Reset the meter, do n_reads back-to-back reads of `count` samples and report. Failed reads are
        counted (failures) but do not stop the measurement."""
        if n_reads < 1:
            raise ValueError("n_reads must be >= 1")
        self.reset_read_rate()
        for _ in range(n_reads):
            with contextlib.suppress(CompowayFError):
                self.read_counts(count)
        return self.read_rate()
