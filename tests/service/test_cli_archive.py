"""`shockbench archive import/export` and `reanalyse --database` on what was imported (issue 33, items 1-3):
a folder of recordings (CSV with vehicle files, an HDF5 sweep carrying its vehicle text) stored in the
database, idempotently by content, a bad file failing alone; exported back byte for byte; re-analysed from
the database alone (the folder deleted) as stored runs; and two runs compared, per vehicle and over the
fleet, with a plot."""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from live_server import simulated_inputs
from test_cli_reanalyse import BROKEN_CSV, write_hdf5

from service.store.database import Database
from service.store.reanalysis_runs import RunStore
from service.store.recordings import RecordingStore

CLI = [sys.executable, "-m", "service.cli.main"]
SECONDS = 6.0


def shockbench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=300)


def digests(folder: Path) -> dict[str, str]:
    return {
        p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """a/sim-6s-1.csv, a/sim-6s-2.csv (a/vehicle.toml), lane2/sweep.h5 (its own vehicle text), and two
    bad files: a/broken.csv (a NaN) and b/alone.csv (no vehicle file)."""
    folder = tmp_path_factory.mktemp("archive")
    simulated_inputs(folder / "a", seconds=SECONDS, seed=1)
    simulated_inputs(folder / "a", seconds=SECONDS, seed=2)
    (folder / "a" / "broken.csv").write_text(BROKEN_CSV)
    third = simulated_inputs(tmp_path_factory.mktemp("third"), seconds=SECONDS, seed=3)
    write_hdf5(folder / "lane2" / "sweep.h5", third.recording, third.vehicle.read_text())
    (folder / "b").mkdir()
    shutil.copy(folder / "a" / "sim-6s-1.csv", folder / "b" / "alone.csv")
    return folder


def test_import_is_idempotent_a_bad_file_fails_alone_and_export_gives_the_bytes_back(
    archive: Path, tmp_path: Path
) -> None:
    url = f"sqlite:///{tmp_path / 'central.sqlite3'}"
    done = shockbench("archive", "import", str(archive), "--database", url)
    assert done.returncode == 1, done.stderr
    bad = done.stderr.strip().splitlines()
    assert len(bad) == 2 and "Traceback" not in done.stderr
    assert "broken.csv:3" in bad[0] and "no vehicle file" in bad[1] and "alone.csv" in bad[1]
    assert done.stdout.startswith("stored 3 recording(s)") and "0 stored before, 2 failed" in done.stdout

    again = shockbench("archive", "import", str(archive), "--database", url)
    assert again.returncode == 1 and again.stdout.startswith("stored 0 recording(s)")
    assert "3 stored before" in again.stdout

    out = tmp_path / "exported"
    exported = shockbench("archive", "export", "--database", url, "--out", str(out))
    assert exported.returncode == 0, exported.stderr
    assert exported.stdout.strip() == f"wrote 3 recording(s) to {out}, 0 failed"
    originals, copies = digests(archive), digests(out)
    for name in ("a/sim-6s-1.csv", "a/sim-6s-2.csv", "lane2/sweep.h5"):
        assert copies[name] == originals[name]
    assert (out / "a" / "sim-6s-1.vehicle.toml").read_text() == (archive / "a" / "vehicle.toml").read_text()
    assert not (out / "lane2" / "sweep.vehicle.toml").exists()  # it carries its own

    fresh = f"sqlite:///{tmp_path / 'fresh.sqlite3'}"
    assert shockbench("archive", "import", str(out), "--database", fresh).returncode == 0
    database, other = Database(url), Database(fresh)
    try:
        assert {r.sha256 for r in RecordingStore(database).listing()} == {
            r.sha256 for r in RecordingStore(other).listing()
        }
    finally:
        database.dispose()
        other.dispose()


def test_the_same_bytes_with_another_vehicle_file_are_said_and_the_stored_vehicle_kept(
    archive: Path, tmp_path: Path
) -> None:
    """The archive is idempotent by the recording's bytes: imported again beside another vehicle file, a
    recording keeps its stored vehicle text, and the import says so in one line instead of dropping it
    silently."""
    url = f"sqlite:///{tmp_path / 'central.sqlite3'}"
    first = tmp_path / "first"
    shutil.copytree(archive / "a", first)
    (first / "broken.csv").unlink()
    assert shockbench("archive", "import", str(first), "--database", url).returncode == 0
    stated = (first / "vehicle.toml").read_text()
    changed = tmp_path / "changed"
    shutil.copytree(first, changed)
    (changed / "vehicle.toml").write_text(stated.replace("[vehicle]", "[vehicle]\n# weighed again", 1))
    again = shockbench("archive", "import", str(changed), "--database", url)
    assert again.returncode == 0, again.stderr
    lines = again.stderr.strip().splitlines()
    kept = "stored before with another vehicle text, which is kept"
    assert len(lines) == 2 and all(kept in line for line in lines)
    assert "sim-6s-1.csv" in lines[0] and "sim-6s-2.csv" in lines[1]
    assert "2 stored before (2 of them given with another vehicle text: the stored one kept)" in again.stdout
    database = Database(url)
    try:
        assert {r.vehicle_text for r in RecordingStore(database).listing()} == {stated}
    finally:
        database.dispose()
    same = shockbench("archive", "import", str(first), "--database", url)
    assert same.returncode == 0 and same.stderr == "" and "2 stored before," in same.stdout


def test_reanalysis_from_the_database_alone_is_a_run_and_two_runs_compare(
    archive: Path, tmp_path: Path
) -> None:
    source = tmp_path / "source"
    shutil.copytree(archive / "a", source)
    (source / "broken.csv").unlink()
    url = f"sqlite:///{tmp_path / 'central.sqlite3'}"
    assert shockbench("archive", "import", str(source), "--database", url).returncode == 0
    shutil.rmtree(source)  # nothing left but the database

    first = shockbench("reanalyse", "--database", url, "--workers", "1")
    assert first.returncode == 0, first.stderr
    assert "(run 1)" in first.stderr and first.stdout.startswith("results: run 1 in ")
    assert sum(line.startswith("[") for line in first.stderr.splitlines()) == 2
    second = shockbench("reanalyse", "--database", url, "--workers", "1", "--points", "12", "--diagnose")
    assert second.returncode == 0, second.stderr

    database = Database(url)
    try:
        runs = RunStore(database)
        one, two = runs.get(1), runs.get(2)
        assert one is not None and two is not None
        assert (one.recordings, one.succeeded, one.failed) == (2, 2, 0)
        assert one.finished_at is not None and one.started_at <= one.finished_at
        assert one.options == {"analyses": ["identify"], "tyre": "maxwell", "points": None}
        assert two.options["points"] == 12 and two.options["analyses"] == ["identify", "diagnose"]
        assert runs.count(2) == 4  # identify and diagnose of each
        for result in runs.results(1).values():
            assert result is not None and len(result["curves"][0]["force_N"]) != 12
        for result in runs.results(2).values():
            assert result is not None and len(result["curves"][0]["force_N"]) == 12
        stored_hashes = {r.sha256 for r in RecordingStore(database).listing()}
        assert set(runs.results(1)) == set(runs.results(2)) == stored_hashes
    finally:
        database.dispose()

    plot = tmp_path / "changes.png"
    compared = shockbench("reanalyse", "--database", url, "--compare", "1", "2", "--plot", str(plot))
    assert compared.returncode == 0, compared.stderr
    lines = compared.stdout.splitlines()
    assert lines[0] == "run 2 against run 1: 2 recording(s) in common"
    assert lines[3].startswith("fleet (2)") and lines[4].startswith("vehicle.toml (2)")
    assert "largest changes (of 2):" in compared.stdout and "verdict flips: 0" in compared.stdout
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and plot.stat().st_size > 10_000

    bad = shockbench("reanalyse", "--database", url, "--compare", "1", "7")
    assert bad.returncode == 2 and bad.stderr.strip().endswith(
        "run '7' is not stored (runs: 1, 2; or 'original')"
    )
