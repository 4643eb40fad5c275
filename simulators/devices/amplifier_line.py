"""An RS-485 line of simulated amplifier nodes (AmplifierLine): every node answers only its own node
number, commands for absent nodes get no reply, and the faults injected at run time (FaultKind, Fault) spoil
the replies they are set for. The servers (simulators.devices.amplifier_servers) put a line on a pty or a
TCP socket."""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum

from drivers.compowayf.codec import (
    STX,
    CommandFrame,
    build_end_code_response,
    build_response,
    parse_command,
    split_frame,
)
from drivers.compowayf.errors import CompowayFError, EndCodeError
from drivers.compowayf.service_data import (
    is_hex,
)
from simulators.devices.amplifier_node import BUFFER_SIZE_BYTES, SimulatedAmplifier

GARBAGE_REPLY = b"\xff\x00\x7e#GARBAGE#\x03\x5a"
"""What the GARBAGE fault sends: no STX, but an ETX and a byte after it, so it reads as a complete frame."""


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


def next_command(buffer: bytes) -> tuple[bytes | None, bytes]:
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
