"""`shockbench archive import` and `export` (issue 33): a folder of recordings into the database's
recordings (service.store.recordings) and back.

Import finds the recordings and their vehicle files by `reanalyse`'s folder rules (sources.items_in_folder),
checks that each reads as a recording and that its vehicle file parses (a bad one fails alone, named in
one line; the others are stored), and stores each unless its bytes are stored already (idempotent by their
sha256: importing the same folder twice stores nothing the second time). Its name in the database is its
path relative to the folder; its vehicle id (what `reanalyse --compare` groups by) is its vehicle file's
path relative to the folder, or its name when an HDF5 recording carries its own vehicle text.

Export writes every stored recording to FOLDER/<name>.<format> with its vehicle text beside it as
<name>.vehicle.toml (the rule `reanalyse` reads a folder by), so an exported archive re-imports to the same
hashes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from daq.formats.atomic import atomic_write
from estimator.errors import UserError, one_line
from service.reanalyse.sources import Item, items_in_folder
from service.store.database import Database
from service.store.recordings import RecordingStore


class ArchiveError(UserError, ValueError):
    """A recording that cannot be imported or exported; one line naming it."""


@dataclass
class ImportReport:
    stored: int = 0
    already: int = 0
    """Recordings whose bytes were stored already (nothing written)."""
    other_vehicle: list[str] = field(default_factory=list)
    """Of those, one line each for the ones given with another vehicle text than the stored one."""
    failed: list[str] = field(default_factory=list)
    """One line per bad file."""
    bytes_in: int = 0
    """The stored recordings' file sizes."""
    bytes_stored: int = 0
    """What they take in the database, compressed."""
    seconds: float = 0.0


def _checked(item: Item) -> tuple[bytes, str | None]:
    """The recording's bytes and its vehicle file's text, once both read as what they should be."""
    from daq.formats.recording_file import RecordingFormat, load_recording_file
    from daq.formats.vehicle_file import load_vehicle_file, parse_vehicle

    if item.problem is not None:
        raise ArchiveError(item.problem)
    read = load_recording_file(item.recording)
    if item.vehicle is not None:
        return item.recording.read_bytes(), load_vehicle_file(item.vehicle).text
    text = read.vehicle_text if read.format is RecordingFormat.HDF5 else None
    if not text:
        raise ArchiveError(f"{item.recording}: no vehicle file, and the recording carries no vehicle text")
    parse_vehicle(text, f"{item.recording} (its vehicle text)")
    return item.recording.read_bytes(), None


def import_folder(folder: Path, database: Database, say: Callable[[str], None]) -> ImportReport:
    """Store every recording of `folder` (module docstring); `say` gets one line per bad file."""
    store = RecordingStore(database)
    report = ImportReport()
    start = time.perf_counter()
    for item in items_in_folder(folder):
        try:
            content, vehicle_text = _checked(item)
        except (UserError, OSError) as exc:
            line = one_line(exc)
            report.failed.append(line if str(item.recording) in line else f"{item.recording}: {line}")
            say(report.failed[-1])
            continue
        relative = item.recording.relative_to(folder)
        if item.vehicle is not None:
            vehicle_id = item.vehicle.relative_to(folder).as_posix()
        else:
            vehicle_id = relative.with_suffix("").as_posix()
        put = store.put(
            content,
            name=relative.with_suffix("").as_posix(),
            file_format=relative.suffix.lstrip(".").lower(),
            vehicle_text=vehicle_text,
            vehicle_id=vehicle_id,
        )
        if put.created:
            report.stored += 1
            report.bytes_in += len(content)
            report.bytes_stored += put.stored_bytes
        else:
            report.already += 1
            if put.other_vehicle:  # the same bytes under another vehicle: said, not silently dropped
                report.other_vehicle.append(
                    f"{item.recording}: stored before with another vehicle text, which is kept "
                    f"(sha256 {put.sha256[:12]})"
                )
                say(report.other_vehicle[-1])
    report.seconds = time.perf_counter() - start
    return report


def _safe(folder: Path, name: str) -> Path:
    """FOLDER/name, refusing a stored name that would leave the folder (absolute, or with '..')."""
    parts = PurePosixPath(name).parts
    if not parts or PurePosixPath(name).is_absolute() or ".." in parts:
        raise ArchiveError(f"stored recording name {name!r} would leave the export folder; not written")
    return folder.joinpath(*parts)


@dataclass(frozen=True)
class ExportReport:
    written: int
    failed: list[str]


def export_folder(database: Database, out: Path, say: Callable[[str], None]) -> ExportReport:
    """Every stored recording written to `out` (module docstring); `say` gets one line per failure."""
    out.mkdir(parents=True, exist_ok=True)
    written, failed = 0, []
    for recording, content in RecordingStore(database).walk():
        try:
            path = _safe(out, recording.file_name)
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_write(path, "wb") as handle:
                handle.write(content)
            if recording.vehicle_text is not None:
                vehicle = _safe(out, recording.name + ".vehicle.toml")
                with atomic_write(vehicle, "w") as handle:
                    handle.write(recording.vehicle_text)
        except (ArchiveError, OSError) as exc:
            failed.append(one_line(exc))
            say(failed[-1])
            continue
        written += 1
    return ExportReport(written, failed)
