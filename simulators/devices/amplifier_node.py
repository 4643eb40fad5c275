"""One simulated OMRON ZX-L-N laser amplifier node (SimulatedAmplifier): a `SimulatedHead` bound to a bench
channel, the same `AmplifierConfig` the driver uses, a small parameter area and the zero-reset state, and
its answer to every CompoWay/F command it takes (simulators.devices.laser_amplifier says how it samples
and which protocol limits it keeps; simulators.devices.amplifier_line carries nodes on a line)."""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Mapping

import numpy as np

from drivers.compowayf.codec import (
    CommandFrame,
    Service,
)
from drivers.compowayf.layout import COUNTER_MODULUS, AmplifierConfig, MeasuredArea
from drivers.compowayf.service_data import (
    ControllerAttributes,
    StatusReport,
    decode_parameter_area_request,
    decode_variable_area_read,
    encode_values,
    max_elements_per_read,
    parameter_element_width,
    variable_element_width,
)
from simulators.coupling import PlatePhysics
from simulators.devices.sensor_heads import ZX_LD40, HeadModel, SimulatedHead

BUFFER_SIZE_BYTES = 217
"""The simulated amplifier's communications buffer (reported by 0503): longer command frames get end code 18,
and a reply may not exceed it (response code 110B). 217 (00D9 hex) holds a reply of 25 double words; it is
what the 900-TC controllers (OMRON-built, CompoWay/F) report. No ZX-L value was found."""
PARAMETER_READ_ECHO_CHARS = 12

DEFAULT_PARAMETERS: dict[tuple[int, int], int] = {
    (0xC000, 0x0000): 0,
    (0xC000, 0x0001): 0,
    (0xC000, 0x0002): 0,
}
"""A small writable parameter area (type C000, addresses 0..2) for read/write tests; meaning-free."""


class _RefusalError(Exception):
    """Internal: the service refuses the request with a response code."""

    def __init__(self, response_code: str) -> None:
        super().__init__(response_code)
        self.response_code = response_code


class SimulatedAmplifier:
    """One ZX-L amplifier (one node) with its head. Thread safe."""

    def __init__(
        self,
        head: SimulatedHead,
        *,
        config: AmplifierConfig | None = None,
        model_name: str = "ZX-LDA11-N",
        parameters: Mapping[tuple[int, int], int] | None = None,
        origin_s: float | None = None,
    ) -> None:
        """origin_s: where a streaming amplifier's sample clock starts (bench seconds; default now)."""
        self.head = head
        self.config = config or AmplifierConfig()
        self.model_name = model_name
        self.parameters = dict(DEFAULT_PARAMETERS if parameters is None else parameters)
        self._lock = threading.RLock()
        self._buffer: deque[int] = deque(maxlen=self.config.measured.buffer_length)
        self._ring = [self.config.measured.out_of_range_marker] * self.config.measured.buffer_length
        self._last_sample_s: float | None = None
        self._last_reading_m: float | None = None
        self._zero_m = 0.0
        self._zero_active = False
        self._last_out_of_range = False
        self._origin_s = head.bench.clock.now_s() if origin_s is None else origin_s
        self._samples_taken = 0

    @classmethod
    def for_channel(
        cls,
        bench: PlatePhysics,
        channel: str,
        model: HeadModel = ZX_LD40,
        *,
        config: AmplifierConfig | None = None,
        seed: int = 0,
        noise_sigma_m: float | None = None,
        static_offset_m: float = 0.0,
        sign: int = 1,
        origin_s: float | None = None,
    ) -> SimulatedAmplifier:
        """An amplifier with a `model` head on `channel` of `bench` (noise from a Generator seeded `seed`)."""
        head = SimulatedHead(
            model,
            bench,
            channel,
            sign=sign,
            static_offset_m=static_offset_m,
            noise_sigma_m=noise_sigma_m,
            seed=seed,
        )
        return cls(head, config=config, origin_s=origin_s)

    # --- measuring -------------------------------------------------------------------------------------

    def _counts_for(self, reading_m: float | None) -> int:
        return self._counts_many(np.array([math.nan if reading_m is None else reading_m]))[0]

    def _counts_many(self, readings_m: np.ndarray) -> list[int]:
        """Counts of readings against the present zero (NaN = out of range); the out-of-range marker where
        there is no reading or the value does not fit the element width."""
        measured = self.config.measured
        bits = 4 * measured.element_width
        marker = measured.out_of_range_marker
        with np.errstate(invalid="ignore"):
            counts = np.round((readings_m - self._zero_m) / measured.count_unit.metres)
            fits = (counts >= -(2 ** (bits - 1))) & (counts < marker - 15)
        return [int(c) if ok else marker for c, ok in zip(counts.tolist(), fits.tolist(), strict=True)]

    def _take(self, at_s: float | None = None) -> None:
        reading_m = self.head.measure_m(at_s)
        self._last_reading_m = reading_m
        self._last_out_of_range = reading_m is None
        self._buffer.appendleft(self._counts_for(reading_m))

    def _catch_up(self, now_s: float) -> None:
        """Streaming: take every sample due by now_s on the amplifier's own clock (only the ones the buffer
        can hold are measured; older ones are counted)."""
        period_s = self.config.measured.sample_period_s
        assert period_s is not None
        due = int((now_s - self._origin_s) / period_s + 1e-9) + 1
        measured = self.config.measured
        first = max(self._samples_taken, due - measured.buffer_length)
        if due > first:
            readings = self.head.measure_many_m(self._origin_s + np.arange(first, due) * period_s)
            for number, counts in zip(range(first, due), self._counts_many(readings), strict=True):
                self._ring[measured.slot_of(number)] = counts
            self._last_reading_m = None if np.isnan(readings[-1]) else float(readings[-1])
            self._last_out_of_range = self._last_reading_m is None
        self._samples_taken = max(self._samples_taken, due)

    @property
    def samples_taken(self) -> int:
        """Streaming: samples taken since the amplifier was created (the device counter, unwrapped)."""
        with self._lock:
            return self._samples_taken

    def sample(self) -> int:
        """Take a sample now (unless one was taken at this simulated time) and return the newest counts.
        A streaming amplifier takes every sample due on its own clock instead."""
        now_s = self.head.bench.clock.now_s()
        with self._lock:
            measured = self.config.measured
            if measured.is_streaming:
                self._catch_up(now_s)
                return self._ring[measured.slot_of(self._samples_taken - 1)]
            if self._last_sample_s != now_s or not self._buffer:
                self._take()
                self._last_sample_s = now_s
            return self._buffer[0]

    def _rezero_newest(self) -> None:
        """Express the newest sample against the new zero, so a zero reset shows at once even when the
        simulated clock has not moved since that sample."""
        measured = self.config.measured
        if measured.is_streaming and self._samples_taken:
            self._ring[measured.slot_of(self._samples_taken - 1)] = self._counts_for(self._last_reading_m)
        elif self._buffer:
            self._buffer[0] = self._counts_for(self._last_reading_m)

    def buffered_counts(self, count: int) -> list[int]:
        """The newest `count` samples, newest first, after sampling now (oldest repeated if not yet full)."""
        with self._lock:
            self.sample()
            return [self._buffer[min(k, len(self._buffer) - 1)] for k in range(count)]

    def zero_reset(self) -> None:
        """Make the present reading zero; refused (2203) when the target is out of range."""
        with self._lock:
            self.sample()
            if self._last_reading_m is None:
                raise _RefusalError("2203")
            self._zero_m, self._zero_active = self._last_reading_m, True
            self._rezero_newest()

    def zero_reset_cancel(self) -> None:
        with self._lock:
            self._zero_m, self._zero_active = 0.0, False
            self._rezero_newest()

    def status(self) -> StatusReport:
        """Operating status 00 (measuring); related info bit 0 = last sample out of range, bit 1 = zero
        reset active. These bit meanings are the simulator's own, not OMRON's."""
        with self._lock:
            return StatusReport(0x00, int(self._last_out_of_range) | int(self._zero_active) << 1)

    # --- services --------------------------------------------------------------------------------------

    def handle(self, command: CommandFrame, *, out_of_range: bool = False) -> tuple[str, str]:
        """(response code, response data) for a command addressed to this node. `out_of_range` replaces
        measured values by the out-of-range marker (fault injection)."""
        try:
            return "0000", self._serve(command, out_of_range)
        except _RefusalError as refusal:
            return refusal.response_code, ""

    @staticmethod
    def _expect_length(data: str, length: int) -> None:
        if len(data) < length:
            raise _RefusalError("1002")
        if len(data) > length:
            raise _RefusalError("1001")

    def _serve(self, command: CommandFrame, out_of_range: bool) -> str:
        service, data = command.service, command.data
        if service == Service.VARIABLE_AREA_READ:
            self._expect_length(data, 12)
            request = decode_variable_area_read(data)
            if request.bit_position != 0 or request.count == 0:
                raise _RefusalError("1100")
            width = variable_element_width(request.area_type)
            if request.count > max_elements_per_read(width, BUFFER_SIZE_BYTES):
                raise _RefusalError("110B")
            values = self._read(
                MeasuredArea.VARIABLE, request.area_type, request.start_address, request.count, out_of_range
            )
            return encode_values(values, variable_element_width(request.area_type))
        if service == Service.PARAMETER_AREA_READ:
            self._expect_length(data, 12)
            request = decode_parameter_area_request(data)
            if request.count == 0:
                raise _RefusalError("1100")
            width = parameter_element_width(request.area_type)
            if request.count > max_elements_per_read(width, BUFFER_SIZE_BYTES, PARAMETER_READ_ECHO_CHARS):
                raise _RefusalError("110B")
            values = self._read(
                MeasuredArea.PARAMETER, request.area_type, request.start_address, request.count, out_of_range
            )
            return data.upper() + encode_values(values, parameter_element_width(request.area_type))
        if service == Service.PARAMETER_AREA_WRITE:
            self._write_parameters(data)
            return ""
        if service == Service.MODEL_READ:
            self._expect_length(data, 0)
            return ControllerAttributes(self.model_name, BUFFER_SIZE_BYTES).encode()
        if service == Service.STATUS_READ:
            self._expect_length(data, 0)
            return self.status().encode()
        if service == Service.ECHO_BACK:
            return data
        if service == Service.OPERATION_COMMAND:
            self._expect_length(data, 4)
            code = (int(data[:2], 16), int(data[2:], 16))
            if code == self.config.operations.zero_reset:
                self.zero_reset()
            elif code == self.config.operations.zero_reset_cancel:
                self.zero_reset_cancel()
            else:
                raise _RefusalError("1100")
            return ""
        raise _RefusalError("0401")

    def _measured_slice(self, area: MeasuredArea, area_type: int, start: int) -> int | None:
        """Offset of `start` in the measured buffer, or None when the address is not part of it."""
        measured = self.config.measured
        if area is measured.area and area_type == measured.area_type:
            offset = start - measured.address
            if 0 <= offset < measured.buffer_length:
                return offset
        return None

    def _read(
        self, area: MeasuredArea, area_type: int, start: int, count: int, out_of_range: bool
    ) -> list[int]:
        measured = self.config.measured
        if measured.is_streaming and area is measured.area and area_type == measured.area_type:
            ring = self._read_ring(start, count, out_of_range)
            if ring is not None:
                return ring
        offset = self._measured_slice(area, area_type, start)
        if offset is not None and not measured.is_streaming:
            if offset + count > measured.buffer_length:
                raise _RefusalError("1104")
            if out_of_range:
                return [measured.out_of_range_marker] * count
            return self.buffered_counts(offset + count)[offset:]
        self._check_parameter_range(area, area_type, start, count)
        with self._lock:
            return [self.parameters[(area_type, address)] for address in range(start, start + count)]

    def _read_ring(self, start: int, count: int, out_of_range: bool) -> list[int] | None:
        """Streaming: counter (at counter_address) and ring slots after it; None for other addresses."""
        measured = self.config.measured
        assert measured.counter_address is not None
        first = start - measured.counter_address  # 0 = the counter, 1.. = ring slots 0..
        if not 0 <= first <= measured.buffer_length:
            return None
        if first + count - 1 > measured.buffer_length:
            raise _RefusalError("1104")
        with self._lock:  # counter and slots from one instant
            self.sample()
            words = [self._samples_taken % COUNTER_MODULUS, *self._ring]
            if out_of_range:
                words[1:] = [measured.out_of_range_marker] * measured.buffer_length
            return words[first : first + count]

    def _check_parameter_range(self, area: MeasuredArea, area_type: int, start: int, count: int) -> None:
        measured = self.config.measured
        known_types = {ptype for ptype, _ in self.parameters} if area is MeasuredArea.PARAMETER else set()
        if area is measured.area:
            known_types.add(measured.area_type)
        if area_type not in known_types:
            raise _RefusalError("1101")
        if (area_type, start) not in self.parameters:
            raise _RefusalError("1103")
        if any((area_type, a) not in self.parameters for a in range(start, start + count)):
            raise _RefusalError("1104")

    def _write_parameters(self, data: str) -> None:
        if len(data) < 12:
            raise _RefusalError("1002")
        request = decode_parameter_area_request(data[:12])
        width = parameter_element_width(request.area_type)
        if (len(data) - 12) % width or (len(data) - 12) // width != request.count:
            raise _RefusalError("1003")
        values = decode_parameter_area_request(data).values
        if self._measured_slice(MeasuredArea.PARAMETER, request.area_type, request.start_address) is not None:
            raise _RefusalError("3003")
        self._check_parameter_range(
            MeasuredArea.PARAMETER, request.area_type, request.start_address, request.count
        )
        with self._lock:
            for address, value in enumerate(values, start=request.start_address):
                self.parameters[(request.area_type, address)] = value
