"""Driver for an OMRON ZX-L-N laser displacement amplifier (ZX-LDA) speaking CompoWay/F, directly over
RS-485 or through the ZX-SF11 interface unit (RS-232C).

Where the measured value lives (variable or parameter area, type, address, buffer length), how its counts
scale to metres and which count values mean "out of range" are configuration (`MeasuredValueConfig`, in
drivers.compowayf.layout, with its sources and the assumption made for the ZX-L), because OMRON's address
maps differ between amplifier generations. The simulated amplifier uses the same dataclasses, so driver and
simulator agree by construction; check the defaults against the communication manual of the actual
amplifier before trusting a real reading.

One request carries at most 25 double words (OMRON's documented maximum), fewer when the communications
buffer size the amplifier reports in 0503 (`read_attributes`, `read_model`) is smaller; longer reads are
split into several requests.

Sign: the driver reports what the amplifier reports, scaled to metres. The simulator's convention (see
simulators/devices/sensor_heads.py) is positive toward the head.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass

from drivers.compowayf.codec import ResponseFrame, Service
from drivers.compowayf.errors import (
    CompowayFError,
    DeviceUrlError,
    MeasurementOutOfRangeError,
    UnexpectedResponseError,
)
from drivers.compowayf.layout import (
    COUNTER_MODULUS,
    STREAM_BUFFER_LENGTH,
    AmplifierConfig,
    CountUnit,
    MeasuredArea,
    MeasuredValueConfig,
    OperationCodes,
    streaming_measured_config,
)
from drivers.compowayf.rate import RateMeter, ReadRate
from drivers.compowayf.service_data import (
    ControllerAttributes,
    StatusReport,
    decode_values,
    encode_operation_command,
    encode_parameter_area_read,
    encode_parameter_area_write,
    encode_variable_area_read,
    max_elements_per_read,
    parameter_element_width,
    variable_element_width,
)
from drivers.compowayf.transport import CompowayFPort, LinkSettings, Opener
from drivers.compowayf.urls import SerialSettings, parse_device_url

PARAMETER_READ_ECHO_CHARS = 12
"""A parameter area read's reply repeats type, start address and element count before the data."""
STREAM_GUARD_FRACTION = 0.5
"""A streaming read re-reads the counter at the end unless it took less than this fraction of the time the
amplifier needs to overwrite the oldest slot read (see ZxlAmplifier.read_stream)."""


@dataclass(frozen=True)
class StreamRead:
    """One read of a streaming amplifier: the sample counter and the newest samples.

    counter: samples taken since the amplifier started, modulo COUNTER_MODULUS; the newest sample is
        number counter - 1. counts: raw counts, newest first (markers included); fewer than asked when
        the oldest of them were overwritten while the read went on.
    """

    counter: int
    counts: list[int]


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
        self.buffer_size_bytes: int | None = None
        """Communications buffer size from 0503 (None until read_attributes/read_model)."""
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

    def _request(self, service: Service, data: str = "", matches: Matcher | None = None) -> str:
        return self.port.request(self.node, service, data, matches=matches).data

    def _max_elements(self, width: int, echoed_chars: int = 0) -> int:
        limit = max_elements_per_read(width, self.buffer_size_bytes, echoed_chars)
        if limit < 1:
            raise ValueError(
                f"node {self.node:02d}: a {self.buffer_size_bytes}-byte communications buffer holds no "
                f"element of {width} hex characters"
            )
        return limit

    def read_variable_area(self, variable_type: int, start_address: int, count: int) -> list[int]:
        """0101: `count` signed elements from a variable area, in requests of at most 25 double words (or
        what the amplifier's buffer holds)."""
        width = variable_element_width(variable_type)
        values: list[int] = []
        for start, n in _chunks(start_address, count, self._max_elements(width)):
            request = encode_variable_area_read(variable_type, start, n)
            data = self._request(Service.VARIABLE_AREA_READ, request, _data_chars(width * n))
            values += decode_values(data, width, n)
        return values

    def read_parameter_area(self, parameter_type: int, start_address: int, count: int) -> list[int]:
        """0201: `count` signed elements from a parameter area (each reply echoes type, address, count and
        is accepted only with the echo of its own request), split like read_variable_area."""
        width = parameter_element_width(parameter_type)
        values: list[int] = []
        limit = self._max_elements(width, PARAMETER_READ_ECHO_CHARS)
        for start, n in _chunks(start_address, count, limit):
            request = encode_parameter_area_read(parameter_type, start, n)
            data = self._request(Service.PARAMETER_AREA_READ, request, _echoes(request, width * n))
            values += decode_values(data[PARAMETER_READ_ECHO_CHARS:], width, n)
        return values

    def write_parameter_area(self, parameter_type: int, start_address: int, values: list[int]) -> None:
        """0202: write consecutive elements of a parameter area."""
        request = encode_parameter_area_write(parameter_type, start_address, values)
        self._request(Service.PARAMETER_AREA_WRITE, request, _data_chars(0))

    def read_attributes(self) -> ControllerAttributes:
        """0503: model and communications buffer size. The buffer size then bounds every read."""
        attributes = ControllerAttributes.decode(self._request(Service.MODEL_READ))
        self.buffer_size_bytes = attributes.buffer_size_bytes
        return attributes

    def read_model(self) -> str:
        """0503: the amplifier's model name (and, kept for later reads, its buffer size)."""
        return self.read_attributes().model

    def read_status(self) -> StatusReport:
        """0601: operating status and related information (raw bytes; meaning is model specific)."""
        return StatusReport.decode(self._request(Service.STATUS_READ, matches=_data_chars(4)))

    def echo(self, text: str) -> str:
        """0801: send `text` (printable ASCII) and check that it comes back unchanged."""
        echoed = self._request(Service.ECHO_BACK, text, lambda response: response.data == text)
        return echoed

    def operation_command(self, command_code: int, related_info: int = 0) -> None:
        """3005: an operation command (command code + related information)."""
        request = encode_operation_command(command_code, related_info)
        self._request(Service.OPERATION_COMMAND, request, _data_chars(0))

    def zero_reset(self) -> None:
        """Make the present reading the amplifier's zero (operation command from the configuration)."""
        self.operation_command(*self.config.operations.zero_reset)

    def zero_reset_cancel(self) -> None:
        self.operation_command(*self.config.operations.zero_reset_cancel)

    # --- measured value --------------------------------------------------------------------------------

    def _read_area(self, address: int, count: int) -> list[int]:
        measured = self.config.measured
        if measured.area is MeasuredArea.VARIABLE:
            return self.read_variable_area(measured.area_type, address, count)
        return self.read_parameter_area(measured.area_type, address, count)

    def _read_measured(self, address: int, count: int, samples: int) -> list[int]:
        """`count` elements of the measured area from `address`, timed for read_rate() as `samples`."""
        started_s = self._rate.clock()
        ok = False
        try:
            values = self._read_area(address, count)
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
        if self.config.measured.is_streaming:
            return self.read_stream(count).counts
        self._check_count(count)
        return self._read_measured(self.config.measured.address, count, count)

    def _read_counter(self) -> int:
        measured = self.config.measured
        assert measured.counter_address is not None
        counter = self._read_area(measured.counter_address, 1)[0]
        if not 0 <= counter < COUNTER_MODULUS:
            raise UnexpectedResponseError(f"node {self.node:02d}: sample counter {counter} out of range")
        return counter

    def read_stream(self, count: int, since: int | None = None) -> StreamRead:
        """Streaming layout: the sample counter, then the newest samples (at most `count`; with `since`, a
        counter from an earlier read, only those taken after it), newest first. Timed for read_rate().

        The samples are read slot by slot from the ring (split into requests of at most 25 double words),
        after the counter. A slot is overwritten buffer_length samples after it was written, so when the
        read took long enough for that to matter (more than STREAM_GUARD_FRACTION of the time, in host
        seconds, the amplifier needs to overwrite the oldest slot read) the counter is read again and the
        samples overwritten meanwhile are dropped from the oldest end.
        """
        measured = self.config.measured
        if not measured.is_streaming or measured.sample_period_s is None:
            raise ValueError("this amplifier's configuration has no sample counter (not a streaming layout)")
        self._check_count(count)
        length = measured.buffer_length
        started_s = self._rate.clock()
        ok = False
        samples = 0
        try:
            counter = self._read_counter()
            new = count if since is None else min(count, (counter - since) % COUNTER_MODULUS)
            new = min(new, counter)  # none before sample 0 (so a wrap, each 24.8 days at 1 kHz, loses some)
            by_slot: dict[int, int] = {}
            oldest = counter - new  # sample numbers oldest .. counter - 1 (unwrapped arithmetic)
            for start_slot, n in _ring_runs(measured.slot_of(oldest), new, length):
                for offset, value in enumerate(self._read_area(measured.address + start_slot, n)):
                    by_slot[start_slot + offset] = value
            usable = new
            budget_s = STREAM_GUARD_FRACTION * (length - new) * measured.sample_period_s
            if new and self._rate.clock() - started_s >= budget_s:
                taken_since = (self._read_counter() - counter) % COUNTER_MODULUS
                usable = max(0, min(new, length - taken_since))
            counts = [by_slot[measured.slot_of(counter - 1 - k)] for k in range(usable)]
            samples = len(counts)
            ok = True
            return StreamRead(counter, counts)
        finally:
            self._rate.record(started_s, self._rate.clock(), samples, ok)

    def read_position_m(self) -> float:
        """The current measured value in metres. Raises MeasurementOutOfRangeError on a marker."""
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


Matcher = Callable[[ResponseFrame], bool]


def _data_chars(chars: int) -> Matcher:
    """Accept a reply whose data is exactly `chars` characters (the element count asked for)."""
    return lambda response: len(response.data) == chars


def _echoes(request: str, chars: int) -> Matcher:
    """Accept a parameter area reply that repeats `request` and then carries `chars` data characters."""
    return lambda response: (
        response.data[:PARAMETER_READ_ECHO_CHARS].upper() == request
        and len(response.data) == PARAMETER_READ_ECHO_CHARS + chars
    )


def _chunks(start: int, count: int, limit: int) -> list[tuple[int, int]]:
    """(start address, element count) of consecutive requests of at most `limit` elements."""
    return [(start + done, min(limit, count - done)) for done in range(0, count, limit)]


def _ring_runs(first_slot: int, count: int, length: int) -> list[tuple[int, int]]:
    """(first slot, slots) of the contiguous runs covering `count` slots of a ring of `length` from
    `first_slot` on (two runs when they wrap past the last slot)."""
    if count <= 0:
        return []
    head = min(count, length - first_slot)
    runs = [(first_slot, head)]
    if count > head:
        runs.append((0, count - head))
    return runs


__all__ = [
    "COUNTER_MODULUS",
    "STREAM_BUFFER_LENGTH",
    "AmplifierConfig",
    "CountUnit",
    "MeasuredArea",
    "MeasuredValueConfig",
    "OperationCodes",
    "StreamRead",
    "ZxlAmplifier",
    "streaming_measured_config",
]
