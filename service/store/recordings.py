"""Recordings kept in the database (issue 33): a fleet's archive lives where its results live, so that any
machine that reaches the database can re-analyse it (`shockbench reanalyse --database`), with no shared
folder.

A recording is its file's bytes, named by their sha256 (hex): the same hash a sweep's and a job's
`recording_sha256` hold, which their result chain links cover (service.store.result_chain), and which
`verify` checks the stored bytes against (`altered_recordings`). A recording CSV is stored zlib-compressed
(level 6: about 2.5 times smaller); an HDF5 recording compresses its data inside, so it is stored as it is
unless zlib saves at least a tenth. With it: its vehicle file's text (None for an HDF5 recording that
carries its own), the vehicle it tested, and the sweep that recorded it.

Storing is idempotent by content: bytes already stored (the same sha256) are not stored again, whatever
their name (`put` says so); the unique constraint on sha256 settles two writers at once.
"""

from __future__ import annotations

import hashlib
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import inspect, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from service.store.database import Database
from service.store.models import RecordingRow, SweepRow

ZLIB_LEVEL = 6
NONE, ZLIB = "none", "zlib"
HDF5_FORMATS = ("h5", "hdf5")
WORTH_IT = 0.9
"""An HDF5 recording is zlib-compressed only when that leaves at most this fraction of its size."""
PAGE = 50
"""Recordings read per query when walking them all (each can be megabytes)."""


def pack(content: bytes, file_format: str) -> tuple[str, bytes]:
    """(compression, stored bytes) of a recording file's content (module docstring)."""
    packed = zlib.compress(content, ZLIB_LEVEL)
    if file_format in HDF5_FORMATS and len(packed) > WORTH_IT * len(content):
        return NONE, content
    return ZLIB, packed


def unpack(compression: str, data: bytes) -> bytes:
    """The recording file's bytes from what `pack` stored."""
    if compression == ZLIB:
        return zlib.decompress(data)
    if compression == NONE:
        return bytes(data)
    raise ValueError(f"unknown compression {compression!r}")


@dataclass(frozen=True)
class StoredRecording:
    """A stored recording without its bytes (listing many must not load them)."""

    id: int
    sha256: str
    name: str
    format: str
    compression: str
    size_bytes: int
    stored_bytes: int
    vehicle_text: str | None
    vehicle_id: str | None
    sweep_uid: str | None

    @property
    def file_name(self) -> str:
        """The name with its format's suffix: what `archive export` writes, what messages name."""
        return file_name(self.name, self.format)


def file_name(name: str, file_format: str) -> str:
    """A stored recording's name with its format's suffix."""
    return name if name.lower().endswith(f".{file_format}") else f"{name}.{file_format}"


@dataclass(frozen=True)
class Put:
    sha256: str
    created: bool
    """False when the same bytes were stored already (nothing written)."""
    stored_bytes: int
    other_vehicle: bool = False
    """The bytes were stored already with another vehicle text (which is kept)."""


def _listed(session: Session) -> list[StoredRecording]:
    from sqlalchemy import func

    columns = (
        RecordingRow.id,
        RecordingRow.sha256,
        RecordingRow.name,
        RecordingRow.format,
        RecordingRow.compression,
        RecordingRow.size_bytes,
        func.length(RecordingRow.data),
        RecordingRow.vehicle_text,
        RecordingRow.vehicle_id,
        RecordingRow.sweep_uid,
    )
    rows = session.execute(select(*columns).order_by(RecordingRow.id)).all()
    return [StoredRecording(*row) for row in rows]


def store_recording(
    session: Session,
    content: bytes,
    *,
    name: str,
    file_format: str,
    vehicle_text: str | None,
    vehicle_id: str | None = None,
    sweep_uid: str | None = None,
) -> Put:
    """In `session`'s transaction: the recording stored unless its bytes are (idempotent by sha256; the
    insert runs in a savepoint, so a concurrent writer's row wins without failing the transaction). Bytes
    stored already keep their stored vehicle text; Put.other_vehicle says when the one given differs."""
    sha256 = hashlib.sha256(content).hexdigest()
    stored = session.execute(select(RecordingRow.vehicle_text).where(RecordingRow.sha256 == sha256)).first()
    if stored is not None:
        return Put(sha256, False, 0, other_vehicle=stored.vehicle_text != vehicle_text)
    compression, data = pack(content, file_format.lower())
    row = RecordingRow(
        sha256=sha256,
        name=name,
        format=file_format.lower(),
        compression=compression,
        size_bytes=len(content),
        data=data,
        vehicle_text=vehicle_text,
        vehicle_id=vehicle_id,
        sweep_uid=sweep_uid,
    )
    try:
        with session.begin_nested():
            session.add(row)
    except IntegrityError:
        return Put(sha256, False, 0)
    return Put(sha256, True, len(data))


class RecordingStore:
    """The stored recordings of a database; each call opens its own short session."""

    def __init__(self, database: Database) -> None:
        self.db = database

    def put(
        self, content: bytes, *, name: str, file_format: str, vehicle_text: str | None, **more: str | None
    ) -> Put:
        with self.db.transaction() as session:
            return store_recording(
                session, content, name=name, file_format=file_format, vehicle_text=vehicle_text, **more
            )

    def listing(self) -> list[StoredRecording]:
        """Every stored recording, oldest first, without its bytes."""
        with self.db.sessions() as session:
            return _listed(session)

    def packed(self, sha256: str) -> tuple[str, bytes]:
        """(compression, stored bytes) of one recording (KeyError when it is not stored)."""
        with self.db.sessions() as session:
            found = session.execute(
                select(RecordingRow.compression, RecordingRow.data).where(RecordingRow.sha256 == sha256)
            ).first()
        if found is None:
            raise KeyError(sha256)
        return found.compression, bytes(found.data)

    def shipped(self, sha256: str) -> tuple[str, bytes, str | None]:
        """(compression, stored bytes, vehicle text) of one recording: what a worker is sent (KeyError
        when it is not stored)."""
        columns = (RecordingRow.compression, RecordingRow.data, RecordingRow.vehicle_text)
        with self.db.sessions() as session:
            found = session.execute(select(*columns).where(RecordingRow.sha256 == sha256)).first()
        if found is None:
            raise KeyError(f"recording {sha256[:12]} is not stored in the database")
        return found.compression, bytes(found.data), found.vehicle_text

    def shipped_many(self, sha256s: Sequence[str]) -> dict[str, tuple[str, bytes, str | None]]:
        """`shipped` of several recordings in one query; those not stored are left out."""
        columns = (
            RecordingRow.sha256,
            RecordingRow.compression,
            RecordingRow.data,
            RecordingRow.vehicle_text,
        )
        with self.db.sessions() as session:
            rows = session.execute(select(*columns).where(RecordingRow.sha256.in_(list(sha256s)))).all()
        return {row.sha256: (row.compression, bytes(row.data), row.vehicle_text) for row in rows}

    def content(self, sha256: str) -> bytes:
        """The recording file's bytes (KeyError when it is not stored)."""
        return unpack(*self.packed(sha256))

    def walk(self) -> Iterator[tuple[StoredRecording, bytes]]:
        """Every recording with its file's bytes, oldest first, PAGE at a time."""
        listing = self.listing()
        for start in range(0, len(listing), PAGE):
            page = listing[start : start + PAGE]
            with self.db.sessions() as session:
                query = select(RecordingRow.id, RecordingRow.data).where(
                    RecordingRow.id.in_([r.id for r in page])
                )
                data = {key: value for key, value in session.execute(query)}
            for recording in page:
                yield recording, unpack(recording.compression, data[recording.id])


def store_sweep_recording(session: Session, sweep: SweepRow, content: bytes) -> Put:
    """In the transaction that ends the sweep: its recording file's bytes and its vehicle file's text (when
    that file can be read) stored with it, named sweep-<id> with the recording's suffix."""
    suffix = Path(sweep.recording_path or "").suffix.lstrip(".") or "h5"
    vehicle_text = None
    if sweep.vehicle_file:
        try:
            vehicle_text = Path(sweep.vehicle_file).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            vehicle_text = None  # the HDF5 recording carries the vehicle text it was run with
    settings = sweep.settings if isinstance(sweep.settings, dict) else {}
    vehicle_id = settings.get("vehicle_id")
    return store_recording(
        session,
        content,
        name=f"sweep-{sweep.id}",
        file_format=suffix,
        vehicle_text=vehicle_text,
        vehicle_id=str(vehicle_id) if vehicle_id else None,
        sweep_uid=sweep.uid,
    )


def altered_recordings(session: Session, limit: int = 1) -> list[str]:
    """One line for each stored recording (at most `limit`) whose bytes no longer hash to the sha256 it is
    stored under, or that a sweep recorded under another hash than the sweep's `recording_sha256` (which
    the sweep's results' chain links cover): what `verify` adds to the chains."""
    problems: list[str] = []
    if not inspect(session.connection()).has_table(RecordingRow.__tablename__):
        return problems  # a schema from before revision 0007 (its chains verify without it)
    sweeps = dict(
        session.execute(
            select(SweepRow.uid, SweepRow.recording_sha256).where(SweepRow.uid.is_not(None))
        ).all()
    )
    ids = list(session.scalars(select(RecordingRow.id).order_by(RecordingRow.id)).all())
    for start in range(0, len(ids), PAGE):
        query = select(RecordingRow).where(RecordingRow.id.in_(ids[start : start + PAGE]))
        for row in session.scalars(query.order_by(RecordingRow.id)):
            try:
                actual = hashlib.sha256(unpack(row.compression, row.data)).hexdigest()
            except (ValueError, zlib.error):
                actual = None
            if actual != row.sha256:
                problems.append(
                    f"recording {row.name} ({row.sha256[:12]}) was altered: its bytes no longer "
                    "match its sha256"
                )
            elif (
                row.sweep_uid is not None and row.sweep_uid in sweeps and sweeps[row.sweep_uid] != row.sha256
            ):
                problems.append(
                    f"recording {row.name} ({row.sha256[:12]}) is not the one its sweep's chained "
                    "recording hash names"
                )
            if len(problems) >= limit:
                return problems
            session.expunge(row)
    return problems
