"""CompoWay/F service data (the PDU inside a frame): element widths, signed hex values, the area read and
write requests, and the replies of 0503 (controller attributes) and 0601 (status). No I/O, no framing
(that is drivers/compowayf/codec.py).

Both sides use it: the driver encodes requests and decodes replies; the simulated amplifier decodes
requests and encodes replies, so the two agree by construction.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from drivers.compowayf.errors import MalformedFrameError

_SIGNED_BIG_ENDIAN = {2: ">i1", 4: ">i2", 8: ">i4"}
"""numpy dtypes of signed elements by their width in hex chars."""
_HEX_TEXT = re.compile("[0-9A-Fa-f]*")


def is_hex(text: str) -> bool:
    """Only hex digits (or nothing). A regular expression: this runs on every byte of every reply."""
    return _HEX_TEXT.fullmatch(text) is not None


def variable_element_width(variable_type: int) -> int:
    """Hex characters per element of a variable area: double words (C0..FF) 8, words (80..BF) 4."""
    return 8 if variable_type >= 0xC0 else 4


def parameter_element_width(parameter_type: int) -> int:
    """Hex characters per element of a parameter area: C000 and up 8, 8000..BFFF 4."""
    return 8 if parameter_type >= 0xC000 else 4


def encode_int(value: int, width: int) -> str:
    """Signed integer as `width` upper-case hex chars, two's complement (width 8: 32 bit, 4: 16 bit)."""
    bits = 4 * width
    if not -(1 << (bits - 1)) <= value < (1 << bits):
        raise ValueError(f"{value} does not fit in {bits} bits")
    return f"{value & ((1 << bits) - 1):0{width}X}"


def decode_int(text: str) -> int:
    """Two's complement hex of any width -> signed int. Raises MalformedFrameError on non-hex text."""
    if not text or not is_hex(text):
        raise MalformedFrameError(f"not a hex number: {text!r}")
    raw, bits = int(text, 16), 4 * len(text)
    return raw - (1 << bits) if raw >= 1 << (bits - 1) else raw


def encode_values(values: list[int] | tuple[int, ...], width: int) -> str:
    return "".join(encode_int(v, width) for v in values)


def decode_values(text: str, width: int, count: int) -> list[int]:
    """`count` signed elements of `width` hex chars each; MalformedFrameError if the length is not exact.
    Elements of 2, 4 or 8 hex chars (the areas' byte, word and double-word types) are converted at once
    with numpy: a streaming read brings hundreds of them."""
    if len(text) != width * count:
        raise MalformedFrameError(f"expected {count} element(s) of {width} hex chars, got {len(text)} chars")
    dtype = _SIGNED_BIG_ENDIAN.get(width)
    if dtype is None or count == 0:
        return [decode_int(text[i : i + width]) for i in range(0, len(text), width)]
    if not is_hex(text):
        bad = next(text[i : i + width] for i in range(0, len(text), width) if not is_hex(text[i : i + width]))
        raise MalformedFrameError(f"not a hex number: {bad!r}")
    values: list[int] = np.frombuffer(bytes.fromhex(text), dtype=dtype).tolist()
    return values


def encode_variable_area_read(variable_type: int, start_address: int, count: int) -> str:
    """0101 request data: type (2 hex) + start address (4 hex) + bit position "00" + element count (4)."""
    if not (0 <= variable_type <= 0xFF and 0 <= start_address <= 0xFFFF and 1 <= count <= 0xFFFF):
        raise ValueError(f"bad variable area read: type {variable_type}, address {start_address}, n {count}")
    return f"{variable_type:02X}{start_address:04X}00{count:04X}"


def encode_parameter_area_read(parameter_type: int, start_address: int, count: int) -> str:
    """0201 request data: type (4 hex) + start address (4) + element count (4, top bit set as OMRON asks)."""
    if not (0 <= parameter_type <= 0xFFFF and 0 <= start_address <= 0xFFFF and 1 <= count <= 0x7FFF):
        raise ValueError(f"bad parameter area: type {parameter_type}, start {start_address}, n {count}")
    return f"{parameter_type:04X}{start_address:04X}{0x8000 | count:04X}"


def encode_parameter_area_write(parameter_type: int, start_address: int, values: list[int]) -> str:
    """0202 request data: the 0201 header for len(values) elements, then the values."""
    header = encode_parameter_area_read(parameter_type, start_address, len(values))
    return header + encode_values(values, parameter_element_width(parameter_type))


def encode_operation_command(command_code: int, related_info: int = 0) -> str:
    """3005 request data: command code (2 hex) + related information (2 hex)."""
    if not (0 <= command_code <= 0xFF and 0 <= related_info <= 0xFF):
        raise ValueError(f"operation command code/info must be bytes: {command_code}, {related_info}")
    return f"{command_code:02X}{related_info:02X}"


@dataclass(frozen=True)
class AreaRequest:
    """The fields of an area read/write request (variable or parameter area)."""

    area_type: int
    start_address: int
    count: int
    bit_position: int = 0
    values: tuple[int, ...] = ()


def _hex_field(text: str, what: str) -> int:
    if not text or not is_hex(text):
        raise MalformedFrameError(f"{what} is not hex: {text!r}")
    return int(text, 16)


def decode_variable_area_read(data: str) -> AreaRequest:
    """Device side of encode_variable_area_read; the caller checks the length (12 chars) first."""
    return AreaRequest(
        _hex_field(data[0:2], "variable type"),
        _hex_field(data[2:6], "start address"),
        _hex_field(data[8:12], "element count"),
        _hex_field(data[6:8], "bit position"),
    )


def decode_parameter_area_request(data: str) -> AreaRequest:
    """Device side of encode_parameter_area_read/write: header (12 chars) and any values after it."""
    ptype = _hex_field(data[0:4], "parameter type")
    count = _hex_field(data[8:12], "element count") & 0x7FFF
    width = parameter_element_width(ptype)
    values = tuple(decode_int(data[i : i + width]) for i in range(12, len(data), width)) if data[12:] else ()
    return AreaRequest(ptype, _hex_field(data[4:8], "start address"), count, values=values)


MODEL_NAME_CHARS = 10
"""0503 reply: the model name is 10 ASCII characters, padded with spaces."""
MAX_DOUBLE_WORDS_PER_READ = 25
"""Most double-word elements one area read may carry: OMRON's CompoWay/F manuals (E5CN/E5AN "Read Variable
Area": 0001 to 0019 hex; KM-N3: "a maximum of 25 (H'19) are read"); more is refused with 110B."""
MAX_WORDS_PER_READ = 50
"""The same limit for word (4 hex character) elements: 0001 to 0032 hex."""
RESPONSE_FRAME_OVERHEAD_BYTES = 17
"""Bytes of a response frame around its data: STX, node 2, sub-address 2, end code 2, MRC SRC 4, response
code 4, ETX, BCC. With the 25 double words (200 characters) of a full read it gives 217 = 00D9 hex, the
buffer size the 900-TC controllers (OMRON-built, CompoWay/F) report in 0503; the E5CN reports 0028 (40)."""


@dataclass(frozen=True)
class ControllerAttributes:
    """0503 (read controller attributes) reply: the model (10 ASCII characters, space padded) and the
    communications buffer size, 4 hex characters (OMRON: "the communications buffer size is expressed in
    2-byte hexadecimal, and read after being converted to 4-byte ASCII", e.g. 00D9 = 217 bytes)."""

    model: str
    buffer_size_bytes: int

    def encode(self) -> str:
        if not 0 <= self.buffer_size_bytes <= 0xFFFF:
            raise ValueError(f"buffer size must fit 4 hex digits, got {self.buffer_size_bytes}")
        return f"{self.model[:MODEL_NAME_CHARS]:<{MODEL_NAME_CHARS}}{self.buffer_size_bytes:04X}"

    @classmethod
    def decode(cls, data: str) -> ControllerAttributes:
        if len(data) != MODEL_NAME_CHARS + 4:
            raise MalformedFrameError(
                f"controller attributes must be a 10-character model and a 4-hex-digit buffer size, "
                f"got {data!r}"
            )
        return cls(data[:MODEL_NAME_CHARS].rstrip(), _hex_field(data[MODEL_NAME_CHARS:], "buffer size"))


def max_elements_per_read(width: int, buffer_size_bytes: int | None, echoed_chars: int = 0) -> int:
    """Most elements of `width` hex characters one read may ask for: OMRON's documented maximum (25 double
    words, 50 words), lowered to what fits the device's communications buffer (0503) when it is known.
    `echoed_chars`: request fields the reply repeats before the data (12 for a parameter area read)."""
    documented = MAX_DOUBLE_WORDS_PER_READ if width >= 8 else MAX_WORDS_PER_READ
    if buffer_size_bytes is None:
        return documented
    fits = (buffer_size_bytes - RESPONSE_FRAME_OVERHEAD_BYTES - echoed_chars) // width
    return max(0, min(documented, fits))


@dataclass(frozen=True)
class StatusReport:
    """0601 response: operating status and related information bytes (meaning is model specific)."""

    operating_status: int
    related_info: int

    def encode(self) -> str:
        return f"{self.operating_status:02X}{self.related_info:02X}"

    @classmethod
    def decode(cls, data: str) -> StatusReport:
        if len(data) != 4:
            raise MalformedFrameError(f"status read data must be 4 hex chars, got {data!r}")
        return cls(_hex_field(data[:2], "operating status"), _hex_field(data[2:], "related information"))


__all__ = [
    "MAX_DOUBLE_WORDS_PER_READ",
    "MAX_WORDS_PER_READ",
    "MODEL_NAME_CHARS",
    "RESPONSE_FRAME_OVERHEAD_BYTES",
    "AreaRequest",
    "ControllerAttributes",
    "StatusReport",
    "decode_int",
    "decode_parameter_area_request",
    "decode_values",
    "decode_variable_area_read",
    "encode_int",
    "encode_operation_command",
    "encode_parameter_area_read",
    "encode_parameter_area_write",
    "encode_values",
    "encode_variable_area_read",
    "is_hex",
    "max_elements_per_read",
    "parameter_element_width",
    "variable_element_width",
]
