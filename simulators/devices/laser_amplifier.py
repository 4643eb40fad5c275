"""Simulated OMRON ZX-L-N laser amplifiers speaking CompoWay/F on a pty or a TCP socket.

Each `SimulatedAmplifier` is one node: a `SimulatedHead` bound to a bench channel, the same
`AmplifierConfig` the driver uses (so both agree on where the measured value lives and how it scales), a
small parameter area and the zero-reset state. A server (`PtyAmplifierServer`, `TcpAmplifierServer`) carries
one or more nodes on one transport, like an RS-485 multi-drop line: every node answers only its own node
number, commands for absent nodes get no reply. One thread per server; frames are parsed and built with
drivers.compowayf.codec, the driver's own codec.

Measured values live where the configuration says (area, type, address; by default the ZS-series
measurement result, parameter area C020 address 3000, see drivers.compowayf.layout). Each read of the
measured area takes a sample at bench.clock.now_s() (unless one was already taken at that simulated time)
and pushes it into a buffer of `buffer_length` samples, newest at the configured address, older ones at the
following addresses. Tests fill the buffer at a chosen rate by advancing the clock and calling `sample()`; a
buffer not yet full repeats its oldest sample.

Streaming amplifiers (a configuration with `sample_period_s` and a sample counter, see
drivers.compowayf.layout.streaming_measured_config) sample on their own clock instead: sample k is taken at
origin + k * sample_period_s, where origin is the bench time at which the amplifier was created, and is
stored in ring slot k % buffer_length after the counter. On every read (and every `sample()`), the samples
due since the last one are taken, at their own instants (the bench keeps a short history of its motion for
this), and the counter says how many have been taken in all. Samples older than the ring are counted but
never measured.

Protocol limits as OMRON documents them: 0503 answers the model and the communications buffer size
(BUFFER_SIZE_BYTES, 217 = 00D9 hex, as the 900-TC controllers report); a command frame longer than the buffer
gets end code 18; a read of more elements than one reply may carry (25 double words, fewer when the buffer
is smaller) gets response code 110B (response too long).

Faults (`inject_fault`, `clear_faults`), switchable at run time, for one node or all, for the next `count`
replies or until cleared: no reply, garbage bytes, bad BCC, a given end code, a given response code,
out-of-range readings, an incomplete reply (no ETX/BCC), a 0x00 byte before the reply's STX (an RS-485 line
turning around) and, on TCP, a dropped connection (on a pty that one behaves as no reply). A line built with
echo=True echoes every byte it receives before answering, as some RS-485 adapters do.
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import selectors
import socket
import threading
import tty
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Self

import numpy as np

from drivers.compowayf.codec import (
    STX,
    CommandFrame,
    ControllerAttributes,
    Service,
    StatusReport,
    build_end_code_response,
    build_response,
    decode_parameter_area_request,
    decode_variable_area_read,
    encode_values,
    is_hex,
    max_elements_per_read,
    parameter_element_width,
    parse_command,
    split_frame,
    variable_element_width,
)
from drivers.compowayf.errors import CompowayFError, EndCodeError
from drivers.compowayf.layout import COUNTER_MODULUS, AmplifierConfig, MeasuredArea
from simulators.coupling import PlatePhysics
from simulators.devices.sensor_heads import ZX_LD40, HeadModel, SimulatedHead

BUFFER_SIZE_BYTES = 217
"""The simulated amplifier's communications buffer (reported by 0503): longer command frames get end code 18,
and a reply may not exceed it (response code 110B). 217 (00D9 hex) holds a reply of 25 double words; it is
what the 900-TC controllers (OMRON-built, CompoWay/F) report. No ZX-L value was found."""
PARAMETER_READ_ECHO_CHARS = 12

GARBAGE_REPLY = b"\xff\x00\x7e#GARBAGE#\x03\x5a"
"""What the GARBAGE fault sends: no STX, but an ETX and a byte after it, so it reads as a complete frame."""

DEFAULT_PARAMETERS: dict[tuple[int, int], int] = {
    (0xC000, 0x0000): 0,
    (0xC000, 0x0001): 0,
    (0xC000, 0x0002): 0,
}
"""A small writable parameter area (type C000, addresses 0..2) for read/write tests; meaning-free."""


class FaultKind(StrEnum):
    NO_REPLY = "no_reply"
    GARBAGE = "garbage"
    BAD_BCC = "bad_bcc"
    END_CODE = "end_code"
    RESPONSE_CODE = "response_code"
    OUT_OF_RANGE = "out_of_range"
    INCOMPLETE = "incomplete"
    DROP_CONNECTION = "drop_connection"
    NULL_BEFORE_STX = "null_before_stx"


@dataclass
class Fault:
    """An injected fault: `code` is the end code (2 hex) or response code (4 hex) where the kind needs one;
    `count` is the number of replies still to spoil (None = until cleared); `node` None = every node."""

    kind: FaultKind
    code: str = ""
    count: int | None = None
    node: int | None = None


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


def _next_command(buffer: bytes) -> tuple[bytes | None, bytes]:
    """Cut the next command frame off the receive buffer, resynchronising on the last STX before ETX."""
    frame, rest = split_frame(buffer, skip_to_stx=True)
    if frame is not None:
        last_stx = frame[:-1].rfind(bytes([STX]))
        frame = frame[last_stx:]
    elif len(rest) > 4 * BUFFER_SIZE_BYTES:
        rest = b""
    return frame, rest


class AmplifierLine:
    """Nodes sharing one transport, fault injection, and the bytes-in/bytes-out logic of both servers."""

    def __init__(self, amplifiers: Mapping[int, SimulatedAmplifier], *, echo: bool = False) -> None:
        """echo: the line echoes every byte the host sends (an RS-485 adapter that hears itself)."""
        for node in amplifiers:
            if not 0 <= node <= 99:
                raise ValueError(f"node numbers are 0..99, got {node}")
        self.amplifiers: dict[int, SimulatedAmplifier] = dict(amplifiers)
        self.echo = echo
        self.commands_received = 0
        self._faults: list[Fault] = []
        self._faults_lock = threading.Lock()

    def inject_fault(
        self, kind: FaultKind, code: str = "", *, count: int | None = None, node: int | None = None
    ) -> Fault:
        """Spoil the next `count` replies (None: until clear_faults) of `node` (None: any node)."""
        needed = {FaultKind.END_CODE: 2, FaultKind.RESPONSE_CODE: 4}.get(kind, 0)
        if len(code) != needed or not is_hex(code):
            raise ValueError(f"fault {kind} needs a code of {needed} hex chars, got {code!r}")
        if count is not None and count < 1:
            raise ValueError("count must be >= 1 (or None for until cleared)")
        fault = Fault(kind, code.upper(), count, node)
        with self._faults_lock:
            self._faults.append(fault)
        return fault

    def clear_faults(self) -> None:
        with self._faults_lock:
            self._faults.clear()

    def _take_fault(self, node: int) -> Fault | None:
        with self._faults_lock:
            for fault in self._faults:
                if fault.node is None or fault.node == node:
                    if fault.count is not None:
                        fault.count -= 1
                        if fault.count == 0:
                            self._faults.remove(fault)
                    return fault
        return None

    def sample_all(self) -> None:
        """Every node takes a sample at the current simulated time (fills the buffers between reads)."""
        for amplifier in self.amplifiers.values():
            amplifier.sample()

    def reply_to(self, frame: bytes) -> tuple[bytes | None, bool]:
        """(reply bytes or None for silence, drop the connection?) for one received command frame."""
        self.commands_received += 1
        try:
            command = parse_command(frame, max_frame_bytes=BUFFER_SIZE_BYTES)
        except EndCodeError as exc:
            if exc.node not in self.amplifiers:
                return None, False
            return self._spoil(exc.node, None, build_end_code_response(exc.node, exc.end_code))
        except CompowayFError:
            return None, False  # no readable node number / no ETX: a real amplifier stays silent
        if command.node not in self.amplifiers:
            return None, False
        return self._spoil(command.node, command, None)

    def _spoil(
        self, node: int, command: CommandFrame | None, reply: bytes | None
    ) -> tuple[bytes | None, bool]:
        """Apply the active fault (if any) to the reply for `command` (or to a ready-made `reply`)."""
        fault = self._take_fault(node)
        kind = fault.kind if fault else None
        if kind is FaultKind.NO_REPLY:
            return None, False
        if kind is FaultKind.DROP_CONNECTION:
            return None, True
        if kind is FaultKind.GARBAGE:
            return GARBAGE_REPLY, False
        if fault is not None and kind is FaultKind.END_CODE:
            return build_end_code_response(node, fault.code), False
        if command is not None:
            if fault is not None and kind is FaultKind.RESPONSE_CODE:
                reply = build_response(node, command.service, fault.code)
            else:
                response_code, data = self.amplifiers[node].handle(
                    command, out_of_range=kind is FaultKind.OUT_OF_RANGE
                )
                reply = build_response(node, command.service, response_code, data)
        assert reply is not None
        if kind is FaultKind.NULL_BEFORE_STX:
            return b"\x00" + reply, False
        if kind is FaultKind.BAD_BCC:
            return reply[:-1] + bytes([reply[-1] ^ 0x5A]), False
        if kind is FaultKind.INCOMPLETE:
            return reply[:-2], False
        return reply, False


class _ServedLine(AmplifierLine):
    """An amplifier line served by one thread: start/stop and the context manager; a transport says how to
    wake its thread (_wake) and what to close (_release)."""

    _thread: threading.Thread

    def start(self) -> Self:
        """Start serving (idempotent)."""
        if not self._thread.is_alive():
            self._thread.start()
        return self

    def stop(self) -> None:
        if self._thread.is_alive():
            self._wake()
            self._thread.join(timeout=2.0)
        self._release()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _wake(self) -> None:
        raise NotImplementedError

    def _release(self) -> None:
        raise NotImplementedError


class PtyAmplifierServer(_ServedLine):
    """Amplifiers on a pseudo-terminal; the driver opens `port_path` (or `device_url(node)`) as a port."""

    def __init__(self, amplifiers: Mapping[int, SimulatedAmplifier], *, echo: bool = False) -> None:
        super().__init__(amplifiers, echo=echo)
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line editing: the line carries binary BCC bytes
        self.port_path = os.ttyname(self._slave)
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(
            target=self._serve, name=f"amplifier-pty {self.port_path}", daemon=True
        )

    def device_url(self, node: int) -> str:
        return f"serial://{self.port_path}?node={node}"

    def _wake(self) -> None:
        os.write(self._wake_w, b"x")

    def _release(self) -> None:
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)

    def _serve(self) -> None:
        buffer = b""
        while True:
            ready, _, _ = select.select([self._master, self._wake_r], [], [])
            if self._wake_r in ready:
                return
            try:
                chunk = os.read(self._master, 4096)
            except OSError:
                return
            if self.echo:
                os.write(self._master, chunk)
            buffer += chunk
            while True:
                frame, buffer = _next_command(buffer)
                if frame is None:
                    break
                reply, _drop = self.reply_to(frame)  # a serial line cannot drop: DROP acts as no reply
                if reply:
                    os.write(self._master, reply)


class TcpAmplifierServer(_ServedLine):
    """Amplifiers behind a TCP socket on 127.0.0.1 (a serial-to-Ethernet converter): the driver connects
    to `url` = socket://127.0.0.1:PORT. Several clients may connect; each is served in turn by one thread."""

    def __init__(
        self,
        amplifiers: Mapping[int, SimulatedAmplifier],
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        echo: bool = False,
    ) -> None:
        super().__init__(amplifiers, echo=echo)
        self._listener = socket.create_server((host, port))
        self._listener.setblocking(False)
        self.host, self.port = self._listener.getsockname()[:2]
        self.connections_accepted = 0
        self._wake_r, self._wake_w = socket.socketpair()
        self._selector = selectors.DefaultSelector()
        self._thread = threading.Thread(target=self._serve, name=f"amplifier-tcp {self.port}", daemon=True)

    @property
    def url(self) -> str:
        return f"socket://{self.host}:{self.port}"

    def device_url(self, node: int) -> str:
        return f"{self.url}?node={node}"

    def _wake(self) -> None:
        self._wake_w.send(b"x")

    def _release(self) -> None:
        for sock in (self._listener, self._wake_r, self._wake_w):
            sock.close()
        self._selector.close()

    def _close_client(self, conn: socket.socket, buffers: dict[socket.socket, bytes]) -> None:
        self._selector.unregister(conn)
        buffers.pop(conn, None)
        conn.close()

    def _serve(self) -> None:
        buffers: dict[socket.socket, bytes] = {}
        self._selector.register(self._listener, selectors.EVENT_READ, "accept")
        self._selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        try:
            while True:
                for key, _ in self._selector.select():
                    if key.data == "wake":
                        return
                    if key.data == "accept":
                        conn, _ = self._listener.accept()
                        conn.setblocking(True)
                        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                        self._selector.register(conn, selectors.EVENT_READ, "client")
                        buffers[conn] = b""
                        self.connections_accepted += 1
                        continue
                    self._serve_client(key.fileobj, buffers)  # type: ignore[arg-type]
        finally:
            for conn in list(buffers):
                self._close_client(conn, buffers)

    def _serve_client(self, conn: socket.socket, buffers: dict[socket.socket, bytes]) -> None:
        try:
            chunk = conn.recv(4096)
        except OSError:
            chunk = b""
        if not chunk:
            self._close_client(conn, buffers)
            return
        if self.echo:
            try:
                conn.sendall(chunk)
            except OSError:
                self._close_client(conn, buffers)
                return
        buffer = buffers[conn] + chunk
        while True:
            frame, buffer = _next_command(buffer)
            if frame is None:
                break
            reply, drop = self.reply_to(frame)
            if drop:
                self._close_client(conn, buffers)
                return
            if reply:
                try:
                    conn.sendall(reply)
                except OSError:
                    self._close_client(conn, buffers)
                    return
        buffers[conn] = buffer
