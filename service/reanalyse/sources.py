"""What `shockbench reanalyse` analyses: the recordings of a folder with their vehicle files, or every
complete sweep stored in a database; and the digest that tells a re-run whether an input changed.

A folder is searched recursively for recordings (*.csv, *.h5, *.hdf5; the output folder is left out). The
vehicle file of REC.ext is the first of:

1. REC.vehicle.toml beside it (how the service keeps a sweep's: sweeps/<id>.h5, sweeps/<id>.vehicle.toml);
2. REC.toml beside it;
3. vehicle.toml in the recording's folder (one car for the whole folder);
4. for an HDF5 recording, the vehicle text it carries (a sweep stores its vehicle file inside).

A file beside the recording wins over the text inside, so a wrong vehicle file can be corrected.

A recording without one is listed with its problem and fails alone. A stored sweep brings its recording
path and vehicle file (SweepStore); when the vehicle file is gone its HDF5 recording's own text is used.
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
SWEEP_PAGE = 500
"""Sweeps read from the database per query."""


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


def items_in_database(url: str) -> list[Item]:
    """Every complete sweep stored in the database at `url`, oldest first, named sweep-<id>."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, SQLAlchemyError

    from estimator.errors import one_line
    from service.store.database import Database
    from service.store.models import SweepStatus
    from service.store.sweeps import SweepStore

    try:
        parsed = make_url(url)
    except ArgumentError:
        raise SourceError(f"database URL {url!r} is not a valid SQLAlchemy URL") from None
    if parsed.get_backend_name() == "sqlite" and not Path(parsed.database or "").is_file():
        raise SourceError(f"database {url}: no such SQLite file")  # opening it would create an empty one
    database = Database(url)
    store = SweepStore(database)
    sweeps = []
    try:
        _check_schema(database)
        while True:
            page, total = store.list_sweeps(status=SweepStatus.COMPLETE, limit=SWEEP_PAGE, offset=len(sweeps))
            sweeps += page
            if not page or len(sweeps) >= total:
                break
    except SQLAlchemyError as exc:
        cause = one_line(getattr(exc, "orig", None) or exc)  # the driver's words, without SQLAlchemy's prefix
        raise SourceError(f"database {database.safe_url}: cannot list the sweeps ({cause})") from None
    finally:
        database.dispose()
    items = []
    for sweep in sorted(sweeps, key=lambda s: s.id):
        name = f"sweep-{sweep.id}"
        if not sweep.recording_path:
            items.append(Item(name, Path(""), None, f"sweep {sweep.id}: no recording path stored"))
            continue
        vehicle = Path(sweep.vehicle_file) if sweep.vehicle_file else None
        if vehicle is not None and not vehicle.is_file():
            vehicle = None  # the vehicle text inside the sweep's HDF5 recording
        items.append(Item(name, Path(sweep.recording_path), vehicle))
    if not items:
        raise SourceError(f"database {database.safe_url}: no complete sweeps")
    return items


def input_digest(item: Item) -> str:
    """sha256 (hex) of the recording's bytes and the vehicle file's (an HDF5 recording's own vehicle text
    is among its bytes). OSError when a file cannot be read."""
    digest = hashlib.sha256()
    for path in (item.recording, item.vehicle):
        if path is None:
            continue
        with path.open("rb") as handle:
            for block in iter(lambda handle=handle: handle.read(1 << 20), b""):
                digest.update(block)
        digest.update(b"\0")  # the boundary between the files counts
    return digest.hexdigest()
