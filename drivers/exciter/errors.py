"""Typed errors of the plate exciter drivers, the same for every back end (Modbus TCP/RTU, CAN).

Callers catch `ExciterError` for "anything went wrong with the exciter", or one of the subclasses to
react to a specific cause (reconnect on `ExciterConnectionLostError`, acknowledge an
`ExciterDeviceFaultError`, fix the sweep on `EnvelopeViolationError`). Configuration mistakes (register
map, URL, envelope limits) are `ExciterConfigError`, which is also a `ValueError`.
"""

from __future__ import annotations

from estimator.errors import UserError


class ExciterError(Exception):
    """Base of every error raised by a plate exciter driver."""


class ExciterConfigError(ExciterError, UserError, ValueError):
    """A configuration is unusable: register map file, exciter URL, envelope limits above the hard limits."""


class ExciterConnectionLostError(ExciterError):
    """The link to the drive is gone (TCP connection dropped, serial port closed, CAN bus down).

    The operation that saw it did not complete; the next operation reconnects."""


class ExciterBusError(ExciterConnectionLostError):
    """The CAN bus reported an error frame during the operation: frames may have been lost."""


class ExciterTimeoutError(ExciterError):
    """The drive did not answer within the reply timeout."""


class ExciterDeviceExceptionError(ExciterError):
    """The drive refused a request with an exception code (for Modbus, the Modbus exception code:
    1 illegal function, 2 illegal data address, 3 illegal data value, 4 slave device failure, ...)."""

    def __init__(self, exception_code: int, message: str) -> None:
        super().__init__(f"{message} (exception code {exception_code})")
        self.exception_code = exception_code


class ExciterDeviceFaultError(ExciterError):
    """The drive is in fault (tripped, watchdog expired, ...) and reports `fault_code`; it refuses to run
    until the fault is reset."""

    def __init__(self, fault_code: int, message: str = "plate drive in fault") -> None:
        super().__init__(f"{message}: fault code 0x{fault_code:04X}")
        self.fault_code = fault_code


class ExciterHeartbeatLostError(ExciterError):
    """The drive's own periodic heartbeat stopped for longer than the supervision timeout."""

    def __init__(self, silent_s: float, timeout_s: float) -> None:
        super().__init__(f"drive heartbeat silent for {silent_s:.3f} s (timeout {timeout_s:.3f} s)")
        self.silent_s = silent_s
        self.timeout_s = timeout_s


class EnvelopeViolationError(ExciterError, UserError, ValueError):
    """A sweep lies outside the safety envelope; raised before anything is sent to the drive.

    `field` names the offending SweepSettings field, `limit_name` the envelope limit it broke."""

    def __init__(self, field: str, value: float, limit_name: str, limit: float) -> None:
        super().__init__(f"sweep {field}={value!r} exceeds the safety envelope ({limit_name}={limit!r})")
        self.field = field
        self.value = value
        self.limit_name = limit_name
        self.limit = limit


class EnvelopeBreachError(ExciterError):
    """While a sweep ran, the drive reported a frequency or plate position outside the safety envelope, or
    kept running past the sweep's end. The driver sent an emergency stop before raising this
    (`stopped` says whether the drive acknowledged it; if not, the keep-alive has ended and the drive's
    watchdog stops the plate)."""

    def __init__(self, quantity: str, value: float, limit_name: str, limit: float, stopped: bool) -> None:
        action = "emergency stop sent" if stopped else "emergency stop failed: the drive's watchdog must act"
        super().__init__(
            f"drive reported {quantity}={value:.6g} outside the safety envelope ({limit_name}={limit:.6g}); "
            f"{action}"
        )
        self.quantity = quantity
        self.value = value
        self.limit_name = limit_name
        self.limit = limit
        self.stopped = stopped


class ExciterEncodingError(ExciterError, UserError, ValueError):
    """A value cannot be represented on the wire (out of the register or signal range after scaling);
    raised before anything is sent."""
