"""The plate exciter's CAN frame set (exciter.dbc) encoded and decoded with cantools.

Shared by the CAN driver (drivers/exciter/can_bus.py) and the simulated drive
(simulators/devices/can_exciter.py), so both sides read the same DBC and no byte is packed by hand.
Frames (see the comments in exciter.dbc):

    host -> drive   EXC_Command (0x200), EXC_SweepFrequencies (0x201), EXC_SweepShape (0x202),
                    EXC_HostKeepAlive (0x210)
    drive -> host   EXC_Status (0x181, answers every host frame but the keep-alive),
                    EXC_Heartbeat (0x701, periodic)
"""

from __future__ import annotations

from enum import IntEnum
from pathlib import Path

import can
import cantools
from cantools.database.can import Database

from drivers.exciter.errors import ExciterEncodingError

DEFAULT_DBC_PATH = Path(__file__).with_name("exciter.dbc")

COMMAND = "EXC_Command"
SWEEP_FREQUENCIES = "EXC_SweepFrequencies"
SWEEP_SHAPE = "EXC_SweepShape"
HOST_KEEPALIVE = "EXC_HostKeepAlive"
STATUS = "EXC_Status"
HEARTBEAT = "EXC_Heartbeat"


class CanResult(IntEnum):
    """EXC_Status.Result: the outcome of the host request the status answers."""

    OK = 0
    REJECTED_FAULT = 1  # the drive is in fault (FaultCode says which)
    NOT_CONFIGURED = 2  # START before a complete sweep was written
    INVALID_VALUE = 3  # sweep settings the drive cannot run


Signals = dict[str, float]


class ExciterFrames:
    """Encode named frames to can.Message and decode can.Message back, through the DBC."""

    def __init__(self, dbc_path: str | Path = DEFAULT_DBC_PATH) -> None:
        db = cantools.database.load_file(str(dbc_path), database_format="dbc")
        if not isinstance(db, Database):
            raise TypeError(f"{dbc_path} is not a CAN database")
        self.db = db

    def encode(self, name: str, signals: Signals) -> can.Message:
        """Physical signal values -> frame. Values out of the DBC range raise ExciterEncodingError."""
        message = self.db.get_message_by_name(name)
        try:
            data = message.encode(signals, scaling=True, strict=True)
        except (cantools.database.EncodeError, KeyError, ValueError) as exc:
            raise ExciterEncodingError(f"{name}: cannot encode {signals}: {exc}") from exc
        return can.Message(arbitration_id=message.frame_id, data=data, is_extended_id=False)

    def decode(self, msg: can.Message) -> tuple[str, Signals] | None:
        """Frame -> (message name, physical signal values, codes as plain numbers); None for a frame that
        is not in the DBC or does not decode (other traffic on a shared bus)."""
        if msg.is_error_frame or msg.is_remote_frame:
            return None
        try:
            message = self.db.get_message_by_frame_id(msg.arbitration_id)
            values = message.decode(bytes(msg.data), decode_choices=False, scaling=True)
        except (KeyError, cantools.database.DecodeError, ValueError):
            return None
        return message.name, {k: float(v) for k, v in values.items()}  # type: ignore[arg-type, union-attr]

    def choices(self, message_name: str, signal_name: str) -> dict[int, str]:
        """The VAL_ table of a signal as {number: name} (used to check it against drivers.exciter.codes)."""
        signal = self.db.get_message_by_name(message_name).get_signal_by_name(signal_name)
        return {int(k): str(v) for k, v in (signal.choices or {}).items()}
