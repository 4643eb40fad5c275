"""Typed exceptions for CompoWay/F: one class per way a request can fail.

Every exception raised by the codec, the transport and the amplifier driver derives from `CompowayFError`,
so callers can catch the whole family at once or one failure precisely. Each class says whether a retry can
help (`retryable`): transmission trouble (timeouts, corrupted frames, the amplifier reporting a parity or BCC
error on our command) may go away on a second try; a command the amplifier refuses (address out of range,
area type error, ...) will be refused again, so the transport does not retry it.

End codes (2 ASCII hex chars after the sub-address) describe the frame as the amplifier received it; response
codes (MRES+SRES, 4 chars after MRC+SRC) describe the service's outcome. Names and meanings follow OMRON's
CompoWay/F command references (ZX/ZS/ZFV smart-sensor series, E5@C controllers).
"""

from __future__ import annotations

from typing import ClassVar

from estimator.errors import UserError


class CompowayFError(Exception):
    """Base of every CompoWay/F failure."""

    retryable: ClassVar[bool] = False


# --- link level: what we received (or did not) -------------------------------------------------------------


class ResponseTimeoutError(CompowayFError):
    """No complete reply (STX ... ETX BCC) within the timeout."""

    retryable = True


class IncompleteResponseError(ResponseTimeoutError):
    """Part of a reply arrived but its ETX or BCC did not: counts as a timeout."""


class BccMismatchError(CompowayFError):
    """The BCC byte of a received frame does not match the XOR of its bytes."""

    retryable = True

    def __init__(self, expected: int, received: int) -> None:
        super().__init__(f"BCC mismatch: computed 0x{expected:02X}, frame carries 0x{received:02X}")
        self.expected = expected
        self.received = received


class MalformedFrameError(CompowayFError):
    """A complete frame that does not follow the CompoWay/F layout (no STX, bad fields, bad data)."""

    retryable = True


class UnexpectedResponseError(MalformedFrameError):
    """A well-formed reply that does not answer our request (other node, other service, wrong echo)."""


class MissingEchoError(ResponseTimeoutError):
    """Echo suppression is on (the adapter is said to echo the host's frames) but the frame just sent did
    not come back within the timeout: the adapter does not echo, or the line garbled the echo."""


class PortError(CompowayFError):
    """The serial port / socket itself failed."""


class PortOpenError(PortError):
    """The port could not be opened (absent device, refused connection, bad URL options)."""


class PortLostError(PortError):
    """The open port failed during a request (device unplugged, socket dropped); it is re-opened on retry."""

    retryable = True


class LineQuietError(CompowayFError):
    """Nothing was sent: the line is still in OMRON's wait after an unanswered request (a late reply may
    still come, `LinkSettings.late_reply_s`) and the port was told not to wait itself
    (`CompowayFPort.waits_for_late_replies` off). Not a failure of the line: ask again once
    `CompowayFPort.quiet_s()` is 0."""


class DeviceUrlError(CompowayFError, UserError, ValueError):
    """A device URL that cannot be understood (unknown scheme option, node out of 00..99, bad number)."""


class MeasurementOutOfRangeError(CompowayFError):
    """The amplifier reported its out-of-range marker: no target within the head's measuring range."""


# --- end codes: the amplifier's verdict on the command frame ------------------------------------------------


class EndCodeError(CompowayFError):
    """The reply carries an end code other than "00"."""

    code: ClassVar[str] = "??"
    meaning: ClassVar[str] = "unknown end code"

    def __init__(self, node: int, code: str | None = None) -> None:
        code = code or type(self).code
        super().__init__(f"node {node:02d}: end code {code} ({self.meaning})")
        self.node = node
        self.end_code = code


class CommandEndCodeError(EndCodeError):
    code, meaning = "0F", "command error: the command could not be executed"


class ParityEndCodeError(EndCodeError):
    code, meaning = "10", "parity error in the received command"
    retryable = True


class FramingEndCodeError(EndCodeError):
    code, meaning = "11", "framing error in the received command"
    retryable = True


class OverrunEndCodeError(EndCodeError):
    code, meaning = "12", "overrun error in the received command"
    retryable = True


class BccEndCodeError(EndCodeError):
    code, meaning = "13", "the amplifier received a command with a wrong BCC"
    retryable = True


class FormatEndCodeError(EndCodeError):
    code, meaning = "14", "format error: non-hex command text or missing MRC/SRC"


class SubAddressEndCodeError(EndCodeError):
    code, meaning = "16", "sub-address error"


class FrameLengthEndCodeError(EndCodeError):
    """Not retryable: the same command is as long the second time (OMRON: "the received frame exceeds the
    specified (supported) number of bytes")."""

    code, meaning = "18", "frame length error: the command exceeds the supported length"


END_CODE_ERRORS: dict[str, type[EndCodeError]] = {
    cls.code: cls
    for cls in (
        CommandEndCodeError,
        ParityEndCodeError,
        FramingEndCodeError,
        OverrunEndCodeError,
        BccEndCodeError,
        FormatEndCodeError,
        SubAddressEndCodeError,
        FrameLengthEndCodeError,
    )
}
"""End code (upper-case hex) -> exception class; "00" (normal end) is absent on purpose."""


def error_for_end_code(node: int, end_code: str) -> EndCodeError:
    """The exception for a non-"00" end code (a plain EndCodeError for codes OMRON does not list)."""
    cls = END_CODE_ERRORS.get(end_code.upper(), EndCodeError)
    return cls(node, end_code.upper())


# --- response codes: the service's verdict -----------------------------------------------------------------


class ResponseCodeError(CompowayFError):
    """The reply carries a response code (MRES+SRES) other than "0000"."""

    code: ClassVar[str] = "????"
    meaning: ClassVar[str] = "unknown response code"

    def __init__(self, node: int, service: str, code: str | None = None) -> None:
        code = code or type(self).code
        super().__init__(f"node {node:02d}, service {service}: response code {code} ({self.meaning})")
        self.node = node
        self.service = service
        self.response_code = code


class UnsupportedCommandError(ResponseCodeError):
    code, meaning = "0401", "unsupported command: the amplifier does not offer this service"


class CommandTooLongError(ResponseCodeError):
    code, meaning = "1001", "command too long"


class CommandTooShortError(ResponseCodeError):
    code, meaning = "1002", "command too short"


class ElementCountMismatchError(ResponseCodeError):
    code, meaning = "1003", "number of elements does not match the amount of data"


class ParameterError(ResponseCodeError):
    code, meaning = "1100", "parameter error: bit position not 00, value out of range or bad command code"


class AreaTypeError(ResponseCodeError):
    code, meaning = "1101", "area type error: wrong variable/parameter type"


class StartAddressOutOfRangeError(ResponseCodeError):
    code, meaning = "1103", "start address out of range"


class EndAddressOutOfRangeError(ResponseCodeError):
    code, meaning = "1104", "end address out of range: start address + element count past the area's end"


class ResponseTooLongError(ResponseCodeError):
    code, meaning = "110B", "response too long: too many elements for one request"


class OperationError(ResponseCodeError):
    code, meaning = "2203", "operation error: unit error or the operation cannot be executed now"


class NotInRunModeError(ResponseCodeError):
    code, meaning = "2204", "operation error: the sensor is not in RUN mode"


class InvalidCommandError(ResponseCodeError):
    code, meaning = "2205", "operation error: command invalid in the present state"


class ReadOnlyError(ResponseCodeError):
    code, meaning = "3003", "read-only: the area cannot be written"


RESPONSE_CODE_ERRORS: dict[str, type[ResponseCodeError]] = {
    cls.code: cls
    for cls in (
        UnsupportedCommandError,
        CommandTooLongError,
        CommandTooShortError,
        ElementCountMismatchError,
        ParameterError,
        AreaTypeError,
        StartAddressOutOfRangeError,
        EndAddressOutOfRangeError,
        ResponseTooLongError,
        OperationError,
        NotInRunModeError,
        InvalidCommandError,
        ReadOnlyError,
    )
}
"""Response code (upper-case hex) -> exception class; "0000" (normal completion) is absent on purpose."""


def error_for_response_code(node: int, service: str, response_code: str) -> ResponseCodeError:
    """The exception for a non-"0000" response code (a plain ResponseCodeError for unlisted codes)."""
    cls = RESPONSE_CODE_ERRORS.get(response_code.upper(), ResponseCodeError)
    return cls(node, service, response_code.upper())
