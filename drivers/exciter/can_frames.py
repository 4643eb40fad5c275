"""The plate exciter's CAN frame set (exciter.dbc) encoded and decoded with cantools.

Shared by the CAN driver (drivers/exciter/can_bus.py) and the simulated drive
(simulators/devices/can_exciter.py), so both sides read the same DBC and no byte is packed by hand.
Frames (see the comments in exciter.dbc), ids as base + offset, the DBC's own ids by default:

    host -> drive   EXC_Command (base+0, 0x680), EXC_SweepFrequencies (+1, 0x681), EXC_SweepShape (+2, 0x682),
                    EXC_HostKeepAlive (+3, 0x683)
    drive -> host   EXC_Status (+8, 0x688, answers every host frame but the keep-alive),
                    EXC_Heartbeat (+9, 0x689, periodic)

Why 0x680: the block 0x680-0x6DF is the one gap in CANopen's predefined connection set (CiA 301: NMT 0x000,
SYNC/EMCY 0x080-0x0FF, TIME 0x100, PDOs 0x180-0x57F, SDO 0x580-0x67F, NMT error control 0x700-0x77F,
LSS 0x7E4/0x7E5), so the exciter can share a bus with CANopen nodes (the first frame set used 0x181,
0x201 and 0x701: node 1's TPDO1, RPDO1 and heartbeat). `base_id` moves the whole set, keeping the offsets
(the DBC stays the description of the layout).
"""

from __future__ import annotations

from enum import IntEnum
from pathlib import Path

import can
import cantools
from cantools.database.can import Database

from drivers.exciter.errors import ExciterConfigError, ExciterEncodingError

DEFAULT_DBC_PATH = Path(__file__).with_name("exciter.dbc")
MAX_STANDARD_ID = 0x7FF

CANOPEN_PREDEFINED_IDS: tuple[tuple[int, int, str], ...] = (
    (0x000, 0x000, "NMT"),
    (0x080, 0x0FF, "SYNC/EMCY"),
    (0x100, 0x100, "TIME"),
    (0x180, 0x57F, "PDOs"),
    (0x580, 0x67F, "SDO"),
    (0x700, 0x77F, "NMT error control (heartbeat)"),
    (0x7E4, 0x7E5, "LSS"),
)
"""CANopen's predefined connection set (CiA 301) as (first id, last id, service)."""

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

    def __init__(self, dbc_path: str | Path = DEFAULT_DBC_PATH, *, base_id: int | None = None) -> None:
        """base_id: where the frame set starts (11-bit id); None keeps the DBC's ids. Each frame keeps its
        offset from the lowest id of the DBC. ExciterConfigError if a frame would leave the 11-bit range."""
        db = cantools.database.load_file(str(dbc_path), database_format="dbc")
        if not isinstance(db, Database):
            raise TypeError(f"{dbc_path} is not a CAN database")
        if base_id is not None:
            dbc_base = min(message.frame_id for message in db.messages)
            last = base_id + max(message.frame_id for message in db.messages) - dbc_base
            if base_id < 1 or last > MAX_STANDARD_ID:
                raise ExciterConfigError(
                    f"CAN base id 0x{base_id:X} puts the exciter frames at 0x{base_id:X}..0x{last:X}; "
                    f"they must lie in 0x001..0x{MAX_STANDARD_ID:X}"
                )
            for message in db.messages:
                message.frame_id = base_id + message.frame_id - dbc_base
            db.refresh()
        self.db = db

    @property
    def frame_ids(self) -> dict[str, int]:
        """{message name: CAN id} as configured."""
        return {message.name: message.frame_id for message in self.db.messages}

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


def canopen_conflicts(frame_ids: dict[str, int]) -> dict[str, str]:
    """{message name: CANopen service} for every frame whose id lies in CANopen's predefined connection
    set (a bus shared with CANopen nodes should have none)."""
    return {
        name: service
        for name, frame_id in frame_ids.items()
        for first, last, service in CANOPEN_PREDEFINED_IDS
        if first <= frame_id <= last
    }
