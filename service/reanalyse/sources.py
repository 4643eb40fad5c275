"""What `shockbench reanalyse` analyses: the recordings of a folder with their vehicle files, or every
complete sweep stored in a database; and the digest that tells a re-run whether an input changed.

A folder is searched recursively for recordings (*.csv, *.h5, *.hdf5; the output folder is left out). The
vehicle file of REC.ext is the first of:

1. REC.vehicle.toml beside it (how the service keeps a sweep's: sweeps/<id>.h5, sweeps/<id>.vehicle.toml);
2. REC.toml beside it;
3. vehicle.toml in the recording's folder (one car for the whole folder);
4. for an HDF5 recording, the vehicle text it carries (a sweep stores its vehicle file inside).

A file beside the recording wins over the text inside, so a wrong vehicle file can be corrected.

A recording without one is listed with its problem and fails alone. A database brings the recordings it
stores (service.store.recordings: bytes, sha256, vehicle text), with no path a worker would have to see.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from estimator.errors import UserError

if TYPE_CHECKING:
    from service.store.database import Database

RECORDING_SUFFIXES = (".csv", ".h5", ".hdf5")
HDF5_SUFFIXES = (".h5", ".hdf5")
"""daq.formats.recording_file's, named here so that listing a folder imports neither h5py nor numpy."""
FOLDER_VEHICLE_FILE = "vehicle.toml"


class SourceError(UserError, ValueError):
    """The source cannot be listed (no such folder, no recordings, database unreadable); one line."""


@dataclass(frozen=True)
class Item:
    """One recording to analyse. name: the stem of its result files (unique in a run); vehicle: its
    vehicle file, or None for the vehicle text inside its HDF5 recording; problem: why it cannot run (no
    vehicle file), found while listing: it fails without being sent to a worker."""

    name: str
    recording: Path
    vehicle: Path | None
    problem: str | None = None
    sha256: str | None = None
    """A recording stored in the database: its sha256 (its bytes come from there); `recording` is then
    only its file name, for messages."""
    vehicle_id: str | None = None
    """A stored recording's vehicle (what `reanalyse --compare` groups by)."""


def _vehicle_for(recording: Path) -> tuple[Path | None, str | None]:
    """(vehicle file, problem) of a recording in a folder, by the rules of the module docstring."""
    stem = recording.with_suffix("")
    for candidate in (stem.with_name(stem.name + ".vehicle.toml"), stem.with_suffix(".toml")):
        if candidate.is_file():
            return candidate, None
    folder_file = recording.parent / FOLDER_VEHICLE_FILE
    if folder_file.is_file():
        return folder_file, None
    if recording.suffix.lower() in HDF5_SUFFIXES:
        return None, None  # its own vehicle text; a recording without one fails when read
    return None, (
        f"{recording}: no vehicle file ({stem.name}.vehicle.toml, {stem.name}.toml or "
        f"{FOLDER_VEHICLE_FILE} beside it)"
    )


def items_in_folder(folder: Path, out: Path | None = None) -> list[Item]:
    """Every recording under `folder` (recursively, sorted, leaving out `out`), named by its path
    relative to the folder without the suffix ('/' -> '__'), with the suffix kept where two recordings
    would share a name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise SourceError(f"{folder}: no such folder")
    skip = out.resolve() if out is not None else None
    found = []
    for path in sorted(folder.rglob("*")):
        if not path.is_file() or path.suffix.lower() not in RECORDING_SUFFIXES:
            continue
        if skip is not None and path.resolve().is_relative_to(skip):
            continue
        found.append(path)
    if not found:
        raise SourceError(f"{folder}: no recordings (*.csv, *.h5, *.hdf5)")
    stems = [path.relative_to(folder).with_suffix("").as_posix() for path in found]
    items = []
    for path, stem in zip(found, stems, strict=True):
        name = stem if stems.count(stem) == 1 else path.relative_to(folder).as_posix()
        vehicle, problem = _vehicle_for(path)
        items.append(Item(name.replace("/", "__"), path, vehicle, problem))
    return items


def _check_schema(database: Database) -> None:
    """SourceError unless the database's schema is the one this shockbench reads (read only here: an
    older one is upgraded by `shockbench db upgrade`, not by a re-analysis; service.store.schema)."""
    from service.store.schema import SchemaError

    try:
        database.require_newest_schema()
    except SchemaError as exc:
        raise SourceError(f"database {database.safe_url}: {exc}") from None


def open_archive(url: str) -> Database:
    """The database at `url`, its schema checked (SourceError, one line, when it cannot be read)."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    from service.store.database import Database

    try:
        parsed = make_url(url)
    except ArgumentError:
        raise SourceError(f"database URL {url!r} is not a valid SQLAlchemy URL") from None
    if parsed.get_backend_name() == "sqlite" and not Path(parsed.database or "").is_file():
        raise SourceError(f"database {url}: no such SQLite file")  # opening it would create an empty one
    database = Database(url)
    try:
        _check_schema(database)
    except BaseException:
        database.dispose()
        raise
    return database


def items_in_database(database: Database) -> list[Item]:
    """Every recording stored in the database (service.store.recordings) that is not a sweep's unfinished
    or incomplete one, oldest first, named by its stored name; and, failing alone, every complete sweep
    whose recording is not stored (its file missing when it ended, or a sweep from before revision 0007)."""
    from sqlalchemy import select
    from sqlalchemy.exc import SQLAlchemyError

    from estimator.errors import one_line
    from service.store.models import RecordingRow, SweepRow, SweepStatus
    from service.store.recordings import RecordingStore

    try:
        recordings = RecordingStore(database).listing()
        with database.sessions() as session:
            sweeps = session.execute(
                select(SweepRow.id, SweepRow.uid, SweepRow.status, SweepRow.recording_path).order_by(
                    SweepRow.id
                )
            ).all()
            stored = set(session.scalars(select(RecordingRow.sweep_uid)).all())
    except SQLAlchemyError as exc:
        cause = one_line(getattr(exc, "orig", None) or exc)  # the driver's words, without SQLAlchemy's prefix
        raise SourceError(f"database {database.safe_url}: cannot list the recordings ({cause})") from None
    complete = {sweep.uid for sweep in sweeps if sweep.status == SweepStatus.COMPLETE.value}
    items = [
        Item(
            recording.name.replace("/", "__"),
            Path(recording.file_name),
            None,
            sha256=recording.sha256,
            vehicle_id=recording.vehicle_id or recording.name,
        )
        for recording in recordings
        if recording.sweep_uid is None or recording.sweep_uid in complete
    ]
    for sweep in sweeps:
        if sweep.status == SweepStatus.COMPLETE.value and sweep.uid not in stored:
            where = sweep.recording_path or "no file"
            problem = f"sweep {sweep.id}: its recording ({where}) is not stored in the database"
            items.append(Item(f"sweep-{sweep.id}", Path(sweep.recording_path or ""), None, problem))
    if not items:
        raise SourceError(f"database {database.safe_url}: no recordings stored (shockbench archive import)")
    return items


def input_digest(item: Item) -> str:
    """sha256 (hex) of the recording's bytes and the vehicle file's (an HDF5 recording's own vehicle text
    is among its bytes); of a stored recording, its sha256 (its vehicle text is stored with it, once). OSError
    when a file cannot be read."""
    if item.sha256 is not None:
        return item.sha256
    digest = hashlib.sha256()
    for path in (item.recording, item.vehicle):
        if path is None:
            continue
        with path.open("rb") as handle:
            for block in iter(lambda handle=handle: handle.read(1 << 20), b""):
                digest.update(block)
        digest.update(b"\0")  # the boundary between the files counts
    return digest.hexdigest()
