"""CompoWay/F frames as bytes: build and parse commands and responses, compute the BCC. No I/O here.

Command frame (host -> amplifier)::

    STX | node (2 decimal) | sub-address "00" | SID "0" | MRC SRC (4) | data (ASCII) | ETX | BCC

Response frame (amplifier -> host)::

    STX | node (2) | sub-address (2) | end code (2) | MRC SRC (4) | MRES SRES (4) | data | ETX | BCC

When the end code is not "00" the amplifier usually answers with the short form (node, sub-address, end
code, ETX, BCC); for end code "0F" it may still append MRC SRC and a response code. Both are parsed.

The BCC is the XOR of every byte after STX up to and including ETX. Text between STX and ETX is printable
ASCII (0x20..0x7E), so the first ETX ends the frame and the single byte after it is the BCC (which may be
any value, even 0x02 or 0x03).

The device side (command parsing, response building) lives here too so the simulated amplifier reuses it.
Its parse errors are the end codes the amplifier answers with: `parse_command` raises the EndCodeError
(13 BCC, 14 format, 16 sub-address, 18 frame length) that the device must reply, and a plain
MalformedFrameError when a real device would stay silent (no STX, no ETX, unreadable node number).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from drivers.compowayf.errors import (
    BccEndCodeError,
    BccMismatchError,
    FormatEndCodeError,
    FrameLengthEndCodeError,
    IncompleteResponseError,
    MalformedFrameError,
    SubAddressEndCodeError,
    UnexpectedResponseError,
    error_for_end_code,
    error_for_response_code,
)
from drivers.compowayf.service_data import is_hex

STX = 0x02
ETX = 0x03
SUB_ADDRESS = "00"
SID = "0"
NORMAL_END = "00"
NORMAL_COMPLETION = "0000"
COMMAND_ERROR_END = "0F"


class Service(StrEnum):
    """MRC+SRC of the CompoWay/F services the ZX-L amplifier driver uses."""

    VARIABLE_AREA_READ = "0101"
    PARAMETER_AREA_READ = "0201"
    PARAMETER_AREA_WRITE = "0202"
    MODEL_READ = "0503"
    STATUS_READ = "0601"
    ECHO_BACK = "0801"
    OPERATION_COMMAND = "3005"


@dataclass(frozen=True)
class CommandFrame:
    """A parsed command: what the host asked of which node."""

    node: int
    service: str
    data: str = ""
    sub_address: str = SUB_ADDRESS
    sid: str = SID


@dataclass(frozen=True)
class ResponseFrame:
    """A parsed response. In the short (error) form service, response_code and data are empty strings."""

    node: int
    end_code: str
    service: str = ""
    response_code: str = ""
    data: str = ""
    sub_address: str = SUB_ADDRESS


def bcc(body: bytes) -> int:
    """XOR of the given bytes: pass everything after STX up to and including ETX."""
    return int(np.bitwise_xor.reduce(np.frombuffer(body, dtype=np.uint8))) if body else 0


_PRINTABLE = re.compile(rb"[\x20-\x7e]*")


def _is_printable(text: bytes) -> bool:
    return _PRINTABLE.fullmatch(text) is not None


def _frame(text: str) -> bytes:
    body = text.encode("ascii") + bytes([ETX])
    return bytes([STX]) + body + bytes([bcc(body)])


def _check_node(node: int) -> None:
    if not 0 <= node <= 99:
        raise ValueError(f"CompoWay/F node number must be 0..99, got {node}")


def _check_text(name: str, text: str) -> None:
    if not text.isascii() or not _is_printable(text.encode("ascii")):
        raise ValueError(f"{name} must be printable ASCII, got {text!r}")


def _check_code(name: str, text: str, length: int) -> None:
    if len(text) != length or not is_hex(text):
        raise ValueError(f"{name} must be {length} hex characters, got {text!r}")


def build_command(node: int, service: str, data: str = "", *, sub_address: str = SUB_ADDRESS) -> bytes:
    """Command frame for `service` (MRC+SRC, e.g. "0101") with ASCII `data` to `node` (0..99)."""
    _check_node(node)
    _check_code("MRC+SRC", service, 4)
    _check_text("command data", data)
    _check_code("sub-address", sub_address, 2)
    return _frame(f"{node:02d}{sub_address}{SID}{service.upper()}{data}")


def build_response(
    node: int,
    service: str,
    response_code: str = NORMAL_COMPLETION,
    data: str = "",
    *,
    end_code: str = NORMAL_END,
) -> bytes:
    """Full response frame (end code, MRC+SRC, response code, data). Used by the simulated amplifier."""
    _check_node(node)
    _check_code("end code", end_code, 2)
    _check_code("MRC+SRC", service, 4)
    _check_code("response code", response_code, 4)
    _check_text("response data", data)
    return _frame(f"{node:02d}{SUB_ADDRESS}{end_code.upper()}{service.upper()}{response_code.upper()}{data}")


def build_end_code_response(node: int, end_code: str, sub_address: str = SUB_ADDRESS) -> bytes:
    """Short response frame: node, sub-address, end code only (how a frame-level error is answered)."""
    _check_node(node)
    _check_code("end code", end_code, 2)
    _check_code("sub-address", sub_address, 2)
    return _frame(f"{node:02d}{sub_address}{end_code.upper()}")


def split_frame(buffer: bytes, *, skip_to_stx: bool = False) -> tuple[bytes | None, bytes]:
    """Cut the first complete frame (up to ETX and the BCC byte after it) off a byte stream.

    Returns (frame, rest); frame is None when no ETX+BCC has arrived yet. Bytes before STX stay in the
    frame (so the parser reports them as malformed) unless skip_to_stx, which drops them first; a device
    uses that to resynchronise on line noise.
    """
    if skip_to_stx:
        start = buffer.find(bytes([STX]))
        if start < 0:
            return None, b""
        buffer = buffer[start:]
    end = buffer.find(bytes([ETX]))
    if end < 0 or end + 1 >= len(buffer):
        return None, buffer
    return buffer[: end + 2], buffer[end + 2 :]


def split_reply(buffer: bytes) -> tuple[bytes | None, bytes, int]:
    """The host's cut of a reply off a byte stream, resynchronising on STX as OMRON's receivers do.

    Returns (frame, rest, skipped): frame is None while no ETX+BCC has arrived. Bytes before the last STX
    that precedes the first ETX are dropped and counted in `skipped` (a 0x00 from an RS-485 line turning
    around, noise, the tail of an older frame): "when STX is received again during reception, reception is
    carried out again from the point where STX was received" (OMRON E5CN/ZEN CompoWay/F manuals). A
    segment ending in ETX+BCC with no STX at all is returned as it is, for the parser to report as
    malformed (something did answer, garbled).
    """
    end = buffer.find(bytes([ETX]))
    if end < 0 or end + 1 >= len(buffer):
        start = buffer.rfind(bytes([STX]))
        if start > 0:  # noise before a reply still arriving: drop it now
            return None, buffer[start:], start
        return None, buffer, 0
    start = buffer.rfind(bytes([STX]), 0, end)
    if start < 0:
        return buffer[: end + 2], buffer[end + 2 :], 0
    return buffer[start : end + 2], buffer[end + 2 :], start


def _unframe(frame: bytes) -> str:
    """Check STX/ETX/BCC of a complete frame and return its text between STX and ETX."""
    if not frame:
        raise IncompleteResponseError("empty reply")
    if frame[0] != STX:
        raise MalformedFrameError(f"frame does not start with STX: {frame[:12]!r}")
    end = frame.find(bytes([ETX]))
    if end < 0 or end + 1 >= len(frame):
        raise IncompleteResponseError(f"reply incomplete (no ETX or BCC): {frame[:24]!r}")
    if end + 2 != len(frame):
        raise MalformedFrameError(f"{len(frame) - end - 2} extra byte(s) after BCC")
    expected = bcc(frame[1 : end + 1])
    if frame[end + 1] != expected:
        raise BccMismatchError(expected, frame[end + 1])
    text = frame[1:end]
    if not _is_printable(text):
        raise MalformedFrameError(f"non-printable byte between STX and ETX: {text[:24]!r}")
    return text.decode("ascii")


def _parse_node(text: str) -> int:
    if len(text) < 2 or not text[:2].isdigit():
        raise MalformedFrameError(f"node number is not 2 decimal digits: {text[:2]!r}")
    return int(text[:2])


def parse_response(frame: bytes) -> ResponseFrame:
    """Parse one complete response frame. Raises only CompowayFError subclasses.

    Does not judge end code or response code (see check_response): the frame itself may be perfectly
    well formed while reporting an error.
    """
    text = _unframe(frame)
    node = _parse_node(text)
    if len(text) < 6:
        raise MalformedFrameError(f"response too short for sub-address and end code: {text!r}")
    sub_address, end_code, rest = text[2:4], text[4:6].upper(), text[6:]
    if not is_hex(end_code):
        raise MalformedFrameError(f"end code is not hex: {end_code!r}")
    if end_code != NORMAL_END and not rest:
        return ResponseFrame(node, end_code, sub_address=sub_address)
    if len(rest) < 8 or not is_hex(rest[:8]):
        raise MalformedFrameError(f"response lacks MRC SRC and response code: {rest[:8]!r}")
    return ResponseFrame(node, end_code, rest[:4].upper(), rest[4:8].upper(), rest[8:], sub_address)


def check_response(response: ResponseFrame, node: int, service: str) -> None:
    """Raise the typed error a response carries, or UnexpectedResponseError if it answers another request.

    Order: wrong node, end code (for "0F" with a response code, that response code's error), other
    service, response code.
    """
    if response.node != node:
        raise UnexpectedResponseError(f"reply from node {response.node:02d}, expected node {node:02d}")
    if response.end_code != NORMAL_END:
        if response.end_code == COMMAND_ERROR_END and response.response_code not in ("", NORMAL_COMPLETION):
            raise error_for_response_code(node, response.service or service, response.response_code)
        raise error_for_end_code(node, response.end_code)
    if response.service != service.upper():
        raise UnexpectedResponseError(f"reply to service {response.service}, expected {service}")
    if response.response_code != NORMAL_COMPLETION:
        raise error_for_response_code(node, service, response.response_code)


def parse_command(frame: bytes, *, max_frame_bytes: int | None = None) -> CommandFrame:
    """Parse a command as an amplifier does. Raises the EndCodeError the amplifier must answer with, or a
    plain MalformedFrameError/IncompleteResponseError/BccMismatchError when it cannot answer at all."""
    try:
        text = _unframe(frame)
    except BccMismatchError:
        # The node number is still needed to answer "13"; without a readable one the device stays silent.
        body = frame[1:3]
        if len(body) == 2 and body.isdigit():
            raise BccEndCodeError(int(body)) from None
        raise
    node = _parse_node(text)
    if max_frame_bytes is not None and len(frame) > max_frame_bytes:
        raise FrameLengthEndCodeError(node)
    sub_address = text[2:4]
    if sub_address != SUB_ADDRESS:
        raise SubAddressEndCodeError(node, "16")
    sid, service, data = text[4:5], text[5:9], text[9:]
    if not sid or len(service) < 4 or not is_hex(sid + service):
        raise FormatEndCodeError(node)
    if service != Service.ECHO_BACK and not is_hex(data):
        raise FormatEndCodeError(node)
    return CommandFrame(node, service.upper(), data, sub_address, sid)


__all__ = [
    "ETX",
    "STX",
    "CommandFrame",
    "ResponseFrame",
    "Service",
    "bcc",
    "build_command",
    "build_end_code_response",
    "build_response",
    "check_response",
    "parse_command",
    "parse_response",
    "split_frame",
    "split_reply",
]
