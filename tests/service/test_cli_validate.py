"""`shockbench validate`: a model identified on one recording of a vehicle (seed 1) explains another
recording of the same vehicle (seed 2, a longer sweep, even at half the sample rate) to a small share of its
motion, and a vehicle with another damper clearly worse; bad model files are one line, exit 2."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from daq.formats.recording_csv import read_recording_csv, write_recording_csv
from daq.formats.vehicle_file import read_vehicle, write_vehicle
from estimator.identify import identify
from estimator.recording import Recording
from estimator.sweep import SweepSettings
from service.cli.main import main
from simulators.vehicle_sim import SimulationSettings, default_axle, default_quarter_car, with_effects
from simulators.vehicle_sim import simulate as simulate_car

SAME_VEHICLE_MAX_RATIO = 0.05
"""gap_ratio of a model on another sweep of its own vehicle (measured: 0.015 quarter car at 1 ms)."""
OTHER_DAMPER_MIN_RATIO = 0.3
"""gap_ratio on the same vehicle with the paper's tanh damper instead of the valve damper (measured: 0.68)."""


def cli_json(capsys: pytest.CaptureFixture[str], *args: str) -> dict[str, object]:
    code = main(list(args))
    captured = capsys.readouterr()
    assert code == 0, captured.err
    return json.loads(captured.out)


def simulate(folder: Path, name: str, vehicle: Path, seconds: str, seed: str, *extra: str) -> Path:
    out = folder / f"{name}.csv"
    assert main(["simulate", "--vehicle", str(vehicle), "--out", str(out), "--duration-s", seconds,
                 "--seed", seed, *extra]) == 0  # fmt: skip
    return out


def halve_rate(path: Path) -> Path:
    """The recording at 2 ms: every other sample."""
    rec = read_recording_csv(path)
    slower = Recording(rec.time_s[::2], {k: v[::2] for k, v in rec.channels.items()}, dict(rec.metadata))
    out = path.with_name(path.stem + "-2ms.csv")
    write_recording_csv(out, slower)
    return out


@pytest.fixture(scope="module")
def quarter_car(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("validate")
    vehicle = folder / "vehicle.toml"
    write_vehicle(vehicle, default_quarter_car().known)
    simulate(folder, "a", vehicle, "10", "1")
    simulate(folder, "b", vehicle, "12", "2")
    simulate(folder, "other", vehicle, "12", "2", "--damper", "paper-tanh")
    return folder


@pytest.fixture(scope="module")
def model_a(quarter_car: Path) -> Path:
    """What identify --json prints for recording A (seed 1), saved as the model file."""
    result = identify(read_recording_csv(quarter_car / "a.csv"), read_vehicle(quarter_car / "vehicle.toml"))
    path = quarter_car / "a.json"
    path.write_text(json.dumps(result.to_json()))
    return path


def test_same_vehicle_small_gap_other_damper_large(
    quarter_car: Path, model_a: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model = model_a
    same = cli_json(capsys, "validate", str(quarter_car / "b.csv"), "--model", str(model), "--json")
    at_2ms = halve_rate(quarter_car / "b.csv")
    slower = cli_json(capsys, "validate", str(at_2ms), "--model", str(model), "--json")
    other = cli_json(capsys, "validate", str(quarter_car / "other.csv"), "--model", str(model), "--json")
    with capsys.disabled():
        print(f"gap_ratio same vehicle {same['gap_ratio']:.4f}, at 2 ms {slower['gap_ratio']:.4f}, "
              f"other damper {other['gap_ratio']:.4f}")  # fmt: skip
    for result in (same, slower, other):
        assert set(result) == {"gap_m", "response_rms_m", "gap_ratio", "gap_diverged", "effects"}
        assert result["effects"] == []  # identify's model has none beyond its form
        assert result["gap_ratio"] == pytest.approx(result["gap_m"] / result["response_rms_m"])
    assert same["gap_ratio"] < SAME_VEHICLE_MAX_RATIO
    assert slower["gap_ratio"] < SAME_VEHICLE_MAX_RATIO
    assert other["gap_ratio"] > OTHER_DAMPER_MIN_RATIO
    assert other["gap_ratio"] > 10 * same["gap_ratio"]
    # the readable form says the same
    assert main(["validate", str(quarter_car / "b.csv"), "--model", str(model)]) == 0
    assert f"gap ratio {100 * same['gap_ratio']:.2f}%" in capsys.readouterr().out


def test_axle_cross_validation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """identify's JSON states the axle's track: validate needs no --track-m; --track-m overrides it, and
    gives the track to a result file written before identify stated it (without, one line, exit 2)."""
    truth = default_axle().known
    vehicle = tmp_path / "axle.toml"
    write_vehicle(vehicle, truth)
    a = simulate(tmp_path, "a", vehicle, "10", "1")
    b = simulate(tmp_path, "b", vehicle, "12", "2")
    other = simulate(tmp_path, "other", vehicle, "12", "2", "--damper", "paper-tanh")
    capsys.readouterr()  # what simulate printed
    model = tmp_path / "axle.json"
    result = cli_json(capsys, "identify", str(a), "--vehicle", str(vehicle), "--json")
    assert result["track_m"] == truth.track_m
    model.write_text(json.dumps(result))
    same = cli_json(capsys, "validate", str(b), "--model", str(model), "--json")
    worse = cli_json(capsys, "validate", str(other), "--model", str(model), "--json")
    with capsys.disabled():
        print(f"axle gap_ratio same {same['gap_ratio']:.4f}, other left damper {worse['gap_ratio']:.4f}")
    assert same["gap_ratio"] < SAME_VEHICLE_MAX_RATIO
    assert worse["gap_ratio"] > 5 * same["gap_ratio"]
    # --track-m overrides the file's track: the same track gives the same gap, a wrong one another
    track = str(truth.track_m)
    assert cli_json(capsys, "validate", str(b), "--model", str(model), "--track-m", track, "--json") == same
    wrong = cli_json(capsys, "validate", str(b), "--model", str(model), "--track-m", "0.5", "--json")
    assert wrong["gap_m"] != same["gap_m"]
    # an old result file without track_m: --track-m gives it, else one line naming the key
    del result["track_m"]
    old = tmp_path / "old.json"
    old.write_text(json.dumps(result))
    assert cli_json(capsys, "validate", str(b), "--model", str(old), "--track-m", track, "--json") == same
    assert main(["validate", str(b), "--model", str(old), "--json"]) == 2
    err = capsys.readouterr().err
    assert "needs 'track_m'" in err and "--track-m" in err and err.count("\n") == 1


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda m: m.pop("masses_kg"), "missing key 'masses_kg'"),
        (lambda m: m["stiffness_N_per_m"].pop("tyre"), "missing key 'stiffness_N_per_m.tyre'"),
        (lambda m: m["curves"][0].update(force_N=[1.0]), "curves[0].force_N"),
        (lambda m: m.update(tyre_model="rubber"), "'tyre_model' must be one of"),
        (
            lambda m: (
                m.update(curves=[m["curves"][0]] * 2, roll_inertia_kg_m2=280.0, track_m=1.5)
                or m["stiffness_N_per_m"].update(anti_roll_bar=0.0)
            ),
            "the model is for an axle but the recording has quarter-car channels",
        ),
        (lambda m: m.update(effects={"wheel_wobble_N": 3.0}), "unknown effect 'effects.wheel_wobble_N'"),
        (lambda m: m.update(effects={"sensor_offset_m": {"x_s_l": 1e-4}}), "names channel 'x_s_l'"),
    ],
)
def test_bad_model_is_one_line_exit_2(
    quarter_car: Path, model_a: Path, capsys: pytest.CaptureFixture[str], change, message: str, tmp_path: Path
) -> None:
    model = json.loads(model_a.read_text())
    change(model)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(model))
    assert main(["validate", str(quarter_car / "b.csv"), "--model", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("shockbench validate: error: ") and message in err
    assert err.count("\n") == 1


def test_unreadable_model_file(quarter_car: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    for content, message in ((b"{not json", "not JSON"), (b"[1, 2]", "expected a JSON object")):
        path = tmp_path / "bad.json"
        path.write_bytes(content)
        assert main(["validate", str(quarter_car / "b.csv"), "--model", str(path)]) == 2
        assert message in capsys.readouterr().err
    assert main(["validate", str(quarter_car / "b.csv"), "--model", str(tmp_path / "none.json")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_the_model_of_diagnose_validates_with_its_effects(
    plate_offset_files: Path, plate_offset_m: float, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """validate takes the whole output of diagnose --json: its final model, with the plate laser's offset
    the doctor named, explains another sweep of the same car on the same rig better than identify's model,
    which lacks the offset."""
    vehicle = plate_offset_files / "vehicle.toml"
    recording = str(plate_offset_files / "rec.csv")
    diagnosis = cli_json(capsys, "diagnose", recording, "--vehicle", str(vehicle), "--json")
    assert diagnosis["model"]["effects"].keys() == {"sensor_offset_m"}
    doctor_model = tmp_path / "diagnosis.json"
    doctor_model.write_text(json.dumps(diagnosis))
    identify_model = tmp_path / "identify.json"
    identified = cli_json(capsys, "identify", recording, "--vehicle", str(vehicle), "--json")
    identify_model.write_text(json.dumps(identified))
    car = with_effects(default_quarter_car(), sensor_offset_m={"x_r": plate_offset_m})
    other = tmp_path / "other.csv"
    settings = SimulationSettings(sweep=SweepSettings(duration_s=8.0), seed=4, substeps=2)
    write_recording_csv(other, simulate_car(car, settings).recording)
    with_offset = cli_json(capsys, "validate", str(other), "--model", str(doctor_model), "--json")
    without = cli_json(capsys, "validate", str(other), "--model", str(identify_model), "--json")
    with capsys.disabled():
        print(
            f"gap_ratio diagnose's model {with_offset['gap_ratio']:.4f}, "
            f"identify's {without['gap_ratio']:.4f}"
        )
    assert with_offset["effects"] == ["sensor_offset_m"] and without["effects"] == []
    assert with_offset["gap_ratio"] < SAME_VEHICLE_MAX_RATIO
    assert with_offset["gap_ratio"] < 0.5 * without["gap_ratio"]
