"""`shockbench reanalyse` (issue 18, item 6): an archive of simulated recordings (CSV, and an HDF5 sweep that
carries its vehicle text) plus a broken file, re-analysed on a local Dask cluster of 2 worker processes:
the results are the simulator's truth, the broken file fails alone with its reason, the summary has every
row, a re-run touches nothing that is done, and a database's sweeps are found through SweepStore."""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest
from live_server import SimulatedInputs, simulated_inputs

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import parse_vehicle_file
from daq.storage.hdf5_recording import RecordingWriter
from estimator.damper import PiecewiseLinearCurve
from estimator.recording import QUARTER_CAR_CHANNELS
from service.reanalyse import run as run_module
from service.reanalyse import task as task_module
from service.reanalyse.run import RunSettings
from service.reanalyse.sources import items_in_folder
from service.reanalyse.task import Analysis, AnalysisOptions, Task

if TYPE_CHECKING:
    from dask.distributed import Client

CLI = [sys.executable, "-m", "service.cli.main", "reanalyse"]
SECONDS = 6.0
CURVE_TOLERANCE_PERCENT = 3.0
MASS_TOLERANCE_PERCENT = 3.0
TRUE_SPRUNG_MASS_KG = 375.0  # simulators.vehicle_sim.default_quarter_car
BROKEN_CSV = "t,x_s,x_t,x_r\n0.000,0,0,0\n0.001,nan,0,0\n0.002,0,0,0\n"


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=300)


def write_hdf5(path: Path, csv_path: Path, vehicle_text: str) -> None:
    """The recording CSV as an HDF5 sweep recording carrying its vehicle text, as `shockbench sweep`
    writes one."""
    recording = read_recording_csv(csv_path)
    vehicle = parse_vehicle_file(vehicle_text, "vehicle.toml")
    path.parent.mkdir(parents=True, exist_ok=True)
    with RecordingWriter(path, QUARTER_CAR_CHANNELS, 0.001, {"bench": "lane 2"}, vehicle=vehicle) as writer:
        writer.append(recording.time_s, recording.channels)
        writer.close(complete=True)


@pytest.fixture(scope="module")
def truth(tmp_path_factory: pytest.TempPathFactory) -> SimulatedInputs:
    return simulated_inputs(tmp_path_factory.mktemp("truth"), seconds=SECONDS, seed=1)


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory, truth: SimulatedInputs) -> Path:
    """sim-6s-1.csv and sim-6s-2.csv (vehicle.toml of the folder; the second also has its own
    sim-6s-2.vehicle.toml), broken.csv (a NaN on line 3), lane2/sweep.h5 (its vehicle text inside)."""
    folder = tmp_path_factory.mktemp("archive")
    simulated_inputs(folder, seconds=SECONDS, seed=1)
    second = simulated_inputs(folder, seconds=SECONDS, seed=2)
    shutil.copy(second.vehicle, folder / "sim-6s-2.vehicle.toml")
    (folder / "broken.csv").write_text(BROKEN_CSV)
    third = simulated_inputs(tmp_path_factory.mktemp("third"), seconds=SECONDS, seed=3)
    write_hdf5(folder / "lane2" / "sweep.h5", third.recording, third.vehicle.read_text())
    return folder


def curve_error_percent(result: dict, truth: SimulatedInputs) -> float:
    curve = result["curves"][0]
    identified = PiecewiseLinearCurve(np.array(curve["velocity_m_s"]), np.array(curve["force_N"]))
    lo, hi = np.quantile(truth.suspension_velocity_m_s, [0.005, 0.995])
    grid = np.linspace(lo, hi, 400)
    expected = truth.true_curve(grid)
    return float(100 * np.sqrt(np.mean((identified.force(grid) - expected) ** 2)) / np.max(np.abs(expected)))


def read_summary(out: Path) -> dict[str, dict[str, str]]:
    with (out / "summary.csv").open(newline="") as handle:
        return {row["name"]: row for row in csv.DictReader(handle)}


def test_the_folder_rules_name_each_recording_and_its_vehicle_file(archive: Path, tmp_path: Path) -> None:
    items = {item.name: item for item in items_in_folder(archive)}
    assert set(items) == {"sim-6s-1", "sim-6s-2", "broken", "lane2__sweep"}
    assert items["sim-6s-1"].vehicle == archive / "vehicle.toml"
    assert items["sim-6s-2"].vehicle == archive / "sim-6s-2.vehicle.toml"
    assert items["lane2__sweep"].vehicle is None  # the HDF5 recording's own vehicle text
    alone = tmp_path / "alone"
    alone.mkdir()
    (alone / "rec.csv").write_text(BROKEN_CSV)
    (alone / "rec.h5").write_bytes(b"")
    found = {item.name: item for item in items_in_folder(alone)}
    assert set(found) == {"rec.csv", "rec.h5"}  # same stem: the suffix tells them apart
    assert "no vehicle file" in (found["rec.csv"].problem or "")


def test_a_recording_without_vehicle_file_fails_without_a_worker(tmp_path: Path) -> None:
    (tmp_path / "archive").mkdir()
    (tmp_path / "archive" / "rec.csv").write_text(BROKEN_CSV)
    said: list[str] = []
    items = items_in_folder(tmp_path / "archive")
    report = run_module.reanalyse(items, RunSettings(out=tmp_path / "out"), said.append)
    assert said == [
        "1 recording(s): 0 analysis(es) to run on a local cluster of 2 worker process(es), 0 done "
        "before (skipped)"
    ]  # no cluster started for nothing
    (row,) = report.rows
    assert (
        row["status"] == "failed"
        and row["reason"].startswith("identify: ")
        and "no vehicle file" in row["reason"]
    )


def test_a_bug_on_one_recording_is_its_reason_not_a_crash(
    monkeypatch: pytest.MonkeyPatch, archive: Path
) -> None:
    def bug(*_: object) -> dict:
        raise RuntimeError("index 7 is out of bounds\nsecond line")

    monkeypatch.setattr(task_module, "analyse", bug)
    item = items_in_folder(archive)[0]
    outcome = task_module.run_task(Task(item, Analysis.IDENTIFY, AnalysisOptions()))
    assert (
        not outcome.ok
        and outcome.reason == "internal error: RuntimeError: index 7 is out of bounds"  # one line
    )


@pytest.fixture(scope="module")
def first_run(
    archive: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path_factory.mktemp("results")
    return out, run(str(archive), "--out", str(out), "--workers", "2")


def test_the_archive_is_identified_and_the_broken_file_fails_alone(
    first_run: tuple[Path, subprocess.CompletedProcess], truth: SimulatedInputs
) -> None:
    out, done = first_run
    assert done.returncode == 1, done.stderr  # some failed
    assert "1 of 4 recording(s) failed" in done.stderr
    assert "4 analysis(es) to run on a local cluster of 2 worker process(es)" in done.stderr
    assert sum(line.startswith("[") for line in done.stderr.splitlines()) == 4  # one progress line each
    assert "Traceback" not in done.stderr
    rows = read_summary(out)
    assert set(rows) == {"sim-6s-1", "sim-6s-2", "broken", "lane2__sweep"}
    broken = rows["broken"]
    assert broken["status"] == "failed" and "broken.csv:3" in broken["reason"], broken
    assert "\n" not in broken["reason"] and not (out / "broken.identify.json").exists()
    for name in ("sim-6s-1", "sim-6s-2", "lane2__sweep"):
        assert rows[name]["status"] == "ok" and rows[name]["reason"] == ""
        assert (
            abs(float(rows[name]["sprung_mass_kg"]) / TRUE_SPRUNG_MASS_KG - 1) * 100 <= MASS_TOLERANCE_PERCENT
        )
        assert 0 < float(rows[name]["gap_m"]) < 1e-3 and 0 < float(rows[name]["eusama_percent"]) < 100
        document = json.loads((out / f"{name}.identify.json").read_text())
        assert len(document["input_sha256"]) == 64 and document["options"] == {
            "tyre": "maxwell",
            "points": None,
        }
        assert float(rows[name]["sprung_mass_kg"]) == pytest.approx(document["result"]["masses_kg"]["sprung"])
    assert json.loads((out / "lane2__sweep.identify.json").read_text())["vehicle"] is None
    first = json.loads((out / "sim-6s-1.identify.json").read_text())["result"]
    assert curve_error_percent(first, truth) <= CURVE_TOLERANCE_PERCENT


@pytest.fixture(scope="module")
def dask_client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Client]:
    """The local cluster `reanalyse` starts, with one worker process."""
    with run_module.dask_client(RunSettings(out=tmp_path_factory.mktemp("unused"), workers=1)) as client:
        yield client


@pytest.fixture(scope="module")
def scheduler(dask_client: Client) -> str:
    """A running Dask scheduler with one worker process, for `--scheduler`."""
    return dask_client.scheduler.address


def test_a_rerun_skips_what_is_done_and_redoes_a_changed_input(
    first_run: tuple[Path, subprocess.CompletedProcess], archive: Path, scheduler: str, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    shutil.copytree(first_run[0], out)
    source = tmp_path / "archive"
    shutil.copytree(archive, source)
    (source / "broken.csv").unlink()
    before = {path.name: path.stat().st_mtime_ns for path in out.glob("*.identify.json")}
    done = run(str(source), "--out", str(out), "--scheduler", scheduler)
    assert done.returncode == 0, done.stderr  # every recording ok now
    assert "0 analysis(es) to run" in done.stderr and "3 done before (skipped)" in done.stderr
    assert {path.name: path.stat().st_mtime_ns for path in out.glob("*.identify.json")} == before
    assert set(read_summary(out)) == {"sim-6s-1", "sim-6s-2", "lane2__sweep"}

    vehicle = source / "sim-6s-2.vehicle.toml"
    vehicle.write_text(vehicle.read_text().replace("mass_kg = 420.0", "mass_kg = 430.0"))
    done = run(str(source), "--out", str(out), "--scheduler", scheduler)
    assert done.returncode == 0, done.stderr
    assert "1 analysis(es) to run" in done.stderr and "[1/1] sim-6s-2 identify: ok" in done.stderr
    assert (out / "sim-6s-2.identify.json").stat().st_mtime_ns != before["sim-6s-2.identify.json"]
    assert (out / "sim-6s-1.identify.json").stat().st_mtime_ns == before["sim-6s-1.identify.json"]


def test_every_complete_sweep_of_a_database_with_the_doctor(
    archive: Path, scheduler: str, tmp_path: Path
) -> None:
    from service.store.database import Database
    from service.store.models import SweepStatus
    from service.store.sweeps import SweepStore

    url = f"sqlite:///{tmp_path / 'shockbench.sqlite3'}"
    database = Database(url)
    database.upgrade_schema()
    store = SweepStore(database)
    sweeps = tmp_path / "sweeps"
    sweeps.mkdir()

    def place(sweep_id: int) -> tuple[Path, Path]:
        """As the service keeps a sweep: sweeps/<id>.h5 and sweeps/<id>.vehicle.toml."""
        recording, vehicle = sweeps / f"{sweep_id}.h5", sweeps / f"{sweep_id}.vehicle.toml"
        if sweep_id == 1:
            shutil.copy(archive / "lane2" / "sweep.h5", recording)
            shutil.copy(archive / "vehicle.toml", vehicle)
        return recording, vehicle  # sweep 2's recording is missing

    for status in (SweepStatus.COMPLETE, SweepStatus.COMPLETE, SweepStatus.ABORTED):
        sweep = store.create("lane 2", {}, place)
        store.finish(sweep.id, status, complete=status is SweepStatus.COMPLETE, reason=None)
    database.dispose()
    out = tmp_path / "out"
    done = run("--database", url, "--out", str(out), "--scheduler", scheduler, "--diagnose")
    assert done.returncode == 1, done.stderr
    rows = read_summary(out)
    assert set(rows) == {"sweep-1", "sweep-2"}  # the aborted sweep is left out
    assert rows["sweep-1"]["status"] == "ok", rows["sweep-1"]
    assert rows["sweep-1"]["diagnosis"].startswith("nothing named"), rows["sweep-1"]
    assert (out / "sweep-1.identify.json").is_file() and (out / "sweep-1.diagnose.json").is_file()
    assert rows["sweep-2"]["status"] == "failed" and "2.h5" in rows["sweep-2"]["reason"]
    assert rows["sweep-2"]["reason"].startswith("identify, diagnose: ")  # one reason, said once


def test_bad_input_is_one_line(archive: Path, tmp_path: Path) -> None:
    out = str(tmp_path / "out")
    for args, says in (
        ([str(tmp_path / "nowhere"), "--out", out], "nowhere: no such folder"),
        (["--out", out], "give either SOURCE"),
        ([str(archive)], "--out is needed with SOURCE"),
        (["--database", f"sqlite:///{tmp_path / 'none.sqlite3'}", "--compare", "1"], "expected 2 arguments"),
        ([str(archive), "--out", out, "--scheduler", "foo"], "--scheduler foo: missing port number"),
        (["--database", f"sqlite:///{tmp_path / 'none.sqlite3'}", "--out", out], "no such SQLite file"),
    ):
        done = run(*args)
        last = done.stderr.strip().splitlines()[-1]
        assert done.returncode == 2 and says in last and last.startswith("shockbench reanalyse: error:"), args
        assert "Traceback" not in done.stderr
    assert not (tmp_path / "none.sqlite3").exists()  # not created by looking
