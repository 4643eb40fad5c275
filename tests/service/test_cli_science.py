"""The science CLI as scripts call it: simulate -> identify --json, fit-tanh, and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from daq.formats.vehicle_file import write_vehicle
from estimator.damper import TanhCurve
from simulators.vehicle_sim import default_axle, default_quarter_car

CLI = [sys.executable, "-m", "service.cli.main"]


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def quarter_car_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("qc")
    vehicle = folder / "vehicle.toml"
    write_vehicle(vehicle, default_quarter_car().known)
    recording = folder / "rec.csv"
    done = run(
        "simulate", "--vehicle", str(vehicle), "--out", str(recording), "--duration-s", "10", "--seed", "4"
    )
    assert done.returncode == 0, done.stderr
    return vehicle, recording


def test_identify_json_has_the_documented_keys(quarter_car_files: tuple[Path, Path]) -> None:
    vehicle, recording = quarter_car_files
    done = run("identify", str(recording), "--vehicle", str(vehicle), "--json")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    curve = out["curves"][0]
    assert curve["corner"] == "single" and len(curve["velocity_m_s"]) == 20 == len(curve["force_N"])
    assert set(curve["tanh"]) == {"c_s", "kappa", "mu", "beta"}
    assert set(out["masses_kg"]) == {"sprung", "unsprung"}
    assert abs(out["masses_kg"]["sprung"] / default_quarter_car().sprung_mass_kg - 1) < 0.03
    for key in ("tyre_damping_Ns_per_m", "objective", "gap_m"):
        assert isinstance(out[key], float)
    assert set(out["inspection"]) >= {"eusama_percent", "phase_shift_min_deg", "damping_ratio"}


def test_identify_from_a_mass_only_vehicle_file_and_free_constants(
    quarter_car_files: tuple[Path, Path], tmp_path: Path
) -> None:
    """A vehicle file with only the mass: the stiffnesses and ϑ come from the recording and the JSON says
    which were identified; --free re-identifies stated values; an unknown name is a one-line error."""
    vehicle, recording = quarter_car_files
    truth = default_quarter_car().known
    alone = tmp_path / "alone.toml"
    alone.write_text(f'[vehicle]\nmodel = "quarter-car"\nmass_kg = {truth.mass_kg}\n')
    done = run("identify", str(recording), "--vehicle", str(alone), "--json")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    stiffness = out["stiffness_N_per_m"]
    assert stiffness["identified"] == ["spring", "tyre"] and out["tyre_viscoelastic_identified"] is True
    assert abs(stiffness["spring"] / truth.spring_stiffness_N_per_m - 1) < 0.05
    assert abs(stiffness["tyre"] / truth.tyre_stiffness_N_per_m - 1) < 0.05
    assert abs(out["tyre_viscoelastic_coefficient"] - truth.tyre_viscoelastic_coefficient) < 0.01
    stated = json.loads(run("identify", str(recording), "--vehicle", str(vehicle), "--json").stdout)
    assert stated["stiffness_N_per_m"] == {
        "spring": truth.spring_stiffness_N_per_m,
        "tyre": truth.tyre_stiffness_N_per_m,
        "identified": [],
    }
    freed = run("identify", str(recording), "--vehicle", str(vehicle), "--free", "spring,tyre", "--json")
    assert json.loads(freed.stdout)["stiffness_N_per_m"]["identified"] == ["spring", "tyre"]
    summary = run("identify", str(recording), "--vehicle", str(alone), "--plot", str(tmp_path / "c.png"))
    assert "spring" in summary.stdout and "(identified)" in summary.stdout
    bad = run("identify", str(recording), "--vehicle", str(vehicle), "--free", "springs")
    assert bad.returncode == 2 and "unknown constant 'springs'" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1


def test_identify_readable_summary_writes_a_png(quarter_car_files: tuple[Path, Path], tmp_path: Path) -> None:
    vehicle, recording = quarter_car_files
    plot = tmp_path / "curve.png"
    done = run(
        "identify",
        str(recording),
        "--vehicle",
        str(vehicle),
        "--points",
        "12",
        "--tyre",
        "kelvin-voigt",
        "--plot",
        str(plot),
    )
    assert done.returncode == 0, done.stderr
    assert "sprung mass" in done.stdout and "EUSAMA" in done.stdout
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_axle_simulate_and_identify(tmp_path: Path) -> None:
    vehicle = tmp_path / "axle.toml"
    write_vehicle(vehicle, default_axle().known)
    recording = tmp_path / "axle.csv"
    simulated = run("simulate", "--vehicle", str(vehicle), "--out", str(recording), "--duration-s", "8")
    assert simulated.returncode == 0, simulated.stderr
    done = run("identify", str(recording), "--vehicle", str(vehicle), "--json")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert [c["corner"] for c in out["curves"]] == ["left", "right"]
    assert "imbalance" in out["inspection"]


def test_fit_tanh_json(tmp_path: Path) -> None:
    points = tmp_path / "points.csv"
    curve = TanhCurve(c_s=300.0, kappa=800.0, mu=6.0, beta=-0.8)
    velocities = np.arange(-5, 7) / 10
    rows = ["velocity_m_s,force_N"] + [
        f"{v:.2f},{f:.3f}" for v, f in zip(velocities, curve.force(velocities), strict=True)
    ]
    rows[4] = "-0.20,5000"
    points.write_text("\n".join(rows) + "\n")
    done = run("fit-tanh", str(points), "--json")
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert set(out) == {"c_s", "kappa", "mu", "beta", "rms_N", "outliers"}
    assert out["outliers"] == [3]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["identify", "absent.csv", "--vehicle", "absent.toml"], "absent.csv: no such file"),
        (["fit-tanh", "absent.csv"], "absent.csv: no such file"),
        (["simulate", "--vehicle", "absent.toml", "--out", "x.csv"], "absent.toml: no such file"),
    ],
)
def test_bad_input_gives_one_line_and_no_traceback(args: list[str], message: str, tmp_path: Path) -> None:
    done = subprocess.run([*CLI, *args], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert done.returncode != 0
    assert message in done.stderr
    assert "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_recording_and_vehicle_that_do_not_match(
    quarter_car_files: tuple[Path, Path], tmp_path: Path
) -> None:
    _, recording = quarter_car_files
    vehicle = tmp_path / "axle.toml"
    write_vehicle(vehicle, default_axle().known)
    done = run("identify", str(recording), "--vehicle", str(vehicle))
    assert done.returncode == 2
    assert "vehicle file is for a axle model" in done.stderr or "axle" in done.stderr
    assert "Traceback" not in done.stderr


def test_simulate_needs_the_constants_identify_can_do_without(tmp_path: Path) -> None:
    alone = tmp_path / "alone.toml"
    alone.write_text('[vehicle]\nmodel = "quarter-car"\nmass_kg = 400.0\n')
    done = run("simulate", "--vehicle", str(alone), "--out", str(tmp_path / "x.csv"))
    assert done.returncode == 2 and "the simulator needs 'spring_stiffness_N_per_m'" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "x.csv").exists()
