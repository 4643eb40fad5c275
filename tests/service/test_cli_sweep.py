"""`shockbench sweep` end to end on the simulated bench, then export and identify: the CLI's main job."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import write_vehicle
from daq.storage.hdf5_recording import load_recording
from estimator.damper import PiecewiseLinearCurve
from service.cli.main import main
from simulators.vehicle_sim import default_quarter_car, true_damper


def test_simulated_sweep_export_identify_finds_the_true_curve(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    vehicle = default_quarter_car()
    vehicle_file = tmp_path / "v.toml"
    write_vehicle(vehicle_file, vehicle.known)
    h5, csv = tmp_path / "run.h5", tmp_path / "run.csv"
    args = ["sweep", "--simulated", "--vehicle", str(vehicle_file), "--out", str(h5)]
    assert main([*args, "--duration-s", "8", "--settle-s", "1", "--operator", "ci"]) == 0
    captured = capsys.readouterr()
    assert "complete; 9001 rows, 0 gap rows; plate stop: end_of_sweep" in captured.out
    assert "100.0% done" in captured.err  # the progress bar, as plain lines on a pipe
    assert load_recording(h5).metadata["operator"] == "ci"
    assert main(["export", str(h5), "--out", str(csv)]) == 0
    assert read_recording_csv(csv).metadata["rate_Hz.x_s"].startswith("1000")
    capsys.readouterr()
    assert main(["identify", str(csv), "--vehicle", str(vehicle_file), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    curve = PiecewiseLinearCurve(
        np.array(result["curves"][0]["velocity_m_s"]), np.array(result["curves"][0]["force_N"])
    )
    truth = true_damper(vehicle.dampers[0])
    grid = np.linspace(-0.3, 0.3, 200)  # well inside what an 8 s, 4 mm sweep excites
    error = np.sqrt(np.mean((curve.force(grid) - truth.force(grid)) ** 2)) / np.max(np.abs(truth.force(grid)))
    assert error < 0.03


def test_sweep_needs_a_bench(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    vehicle_file = tmp_path / "v.toml"
    write_vehicle(vehicle_file, default_quarter_car().known)
    assert main(["sweep", "--vehicle", str(vehicle_file), "--out", str(tmp_path / "r.h5")]) == 2
    assert "give --config BENCH.toml, or --simulated" in capsys.readouterr().err


def test_sweep_refuses_to_overwrite_and_nothing_moves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    vehicle_file = tmp_path / "v.toml"
    write_vehicle(vehicle_file, default_quarter_car().known)
    out = tmp_path / "r.h5"
    out.write_text("keep me")
    code = main(["sweep", "--simulated", "--vehicle", str(vehicle_file), "--out", str(out), "--quiet"])
    assert code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "already exists" in err
    assert out.read_text() == "keep me"
