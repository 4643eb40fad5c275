"""Recording CSV and vehicle TOML: round trips and one-line errors that name the problem."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.formats.recording_csv import RecordingFormatError, read_recording_csv, write_recording_csv
from daq.formats.vehicle_file import VehicleFileError, parse_vehicle, read_vehicle, write_vehicle
from estimator.recording import Recording
from estimator.vehicle import PAPER_BENCH, ModelKind, VehicleParameters

AXLE_VEHICLE = '[vehicle]\nmodel = "axle"\nmass_kg = 800\ntrack_m = 1.5\n'
GOOD_VEHICLE = """[vehicle]
model = "quarter-car"
mass_kg = 420.0
spring_stiffness_N_per_m = 26000
tyre_stiffness_N_per_m = 210000
tyre_viscoelastic_coefficient = 0.97
"""


def _recording(n: int = 50) -> Recording:
    t = np.arange(n) * 0.001
    return Recording(t, {"x_s": np.sin(t), "x_t": np.cos(t) * 1e-3, "x_r": t * 1e-4}, {"operator": "test"})


def test_recording_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "rec.csv"
    original = _recording()
    write_recording_csv(path, original)
    back = read_recording_csv(path)
    assert back.metadata["operator"] == "test"
    np.testing.assert_allclose(back.time_s, original.time_s, atol=1e-9)
    for name in ("x_s", "x_t", "x_r"):
        np.testing.assert_allclose(back.channels[name], original.channels[name], rtol=1e-8, atol=1e-15)
    assert not list(tmp_path.glob("*.part"))


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "rec.csv"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("# only a comment\n", "no header"),
        ("t,x_s,x_t\n0,0,0\n", "columns t,x_s,x_t are neither"),
        (
            "t,x_s,x_t,x_r\n0,0,0,0\n0.001,0,0,0\n0.002,0,nan,0\n",
            r"rec.csv:4: missing or non-finite value in column x_t",
        ),
        ("t,x_s,x_t,x_r\n0,0,0,0\n0.001,0,0,0\n0.002,0,,0\n", r"rec.csv:4: not a number"),
        ("t,x_s,x_t,x_r\n0,0,0,0\n0.001,0,0\n", r"rec.csv:3: expected 4 values, found 3"),
        (
            "# a\nt,x_s,x_t,x_r\n0,0,0,0\n0.001,0,0,0\n0.003,0,0,0\n0.004,0,0,0\n",
            r"rec.csv:5: sample time is not uniform",
        ),
        ("t,x_s,x_t,x_r\n0,0,0,0\n", "only 1 data rows"),
    ],
)
def test_bad_recordings_name_the_problem(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(RecordingFormatError, match=message) as error:
        read_recording_csv(_write(tmp_path, text))
    assert "\n" not in str(error.value)


def test_missing_recording_file(tmp_path: Path) -> None:
    with pytest.raises(RecordingFormatError, match="no such file"):
        read_recording_csv(tmp_path / "absent.csv")


def test_a_failed_write_leaves_no_half_written_file(tmp_path: Path) -> None:
    path = tmp_path / "rec.csv"
    path.write_text("previous content")
    broken = Recording(np.arange(5) * 0.001, {"x_s": np.zeros(5)})  # lacks x_t, x_r
    with pytest.raises(ValueError):
        write_recording_csv(path, broken)
    assert path.read_text() == "previous content"
    assert not list(tmp_path.glob("*.part"))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-0.01, 0.01, allow_nan=False), min_size=3, max_size=40))
def test_any_values_round_trip_to_nanometres(values: list[float]) -> None:
    import tempfile

    n = len(values)
    rec = Recording(
        np.arange(n) * 0.001, {"x_s": np.array(values), "x_t": np.zeros(n), "x_r": -np.array(values)}
    )
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "r.csv"
        write_recording_csv(path, rec)
        back = read_recording_csv(path)
    np.testing.assert_allclose(back.channels["x_s"], rec.channels["x_s"], atol=1e-12)


def test_vehicle_round_trip(tmp_path: Path) -> None:
    axle = VehicleParameters(
        ModelKind.AXLE, 840.0, 26e3, 210e3, 0.97, track_m=1.5, anti_roll_bar_stiffness_N_per_m=18e3
    )
    rig = VehicleParameters(ModelKind.QUARTER_CAR, 4.5, 800.0, 3000.0, frame_guides=True)
    for vehicle in (PAPER_BENCH, axle, rig):
        path = tmp_path / "v.toml"
        write_vehicle(path, vehicle)
        assert read_vehicle(path) == vehicle
    assert parse_vehicle(GOOD_VEHICLE).mass_kg == 420.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (GOOD_VEHICLE + "colour = 1\n", "unknown key 'colour'"),
        (GOOD_VEHICLE.replace("mass_kg = 420.0\n", ""), "missing required key 'mass_kg'"),
        (GOOD_VEHICLE.replace('"quarter-car"', '"axle"'), "missing required key 'track_m'"),
        (GOOD_VEHICLE + "track_m = 1.5\n", "applies to an axle only"),
        (GOOD_VEHICLE.replace("420.0", '"heavy"'), "'mass_kg' must be a number"),
        (GOOD_VEHICLE.replace("420.0", "-1"), "mass_kg must be > 0"),
        (GOOD_VEHICLE.replace('"quarter-car"', '"bus"'), "model must be"),
        ("[vehicle\n", "not valid TOML"),
        (GOOD_VEHICLE + "[extra]\n", "unknown table or key 'extra'"),
        (GOOD_VEHICLE + "frame_guides = 1\n", "'frame_guides' must be true or false"),
        (AXLE_VEHICLE + "frame_guides = true\n", "quarter-car rig only"),
    ],
)
def test_bad_vehicle_files_name_the_key(text: str, message: str) -> None:
    with pytest.raises(VehicleFileError, match=message):
        parse_vehicle(text)


THETA_LINE = "tyre_viscoelastic_coefficient = 0.97"


def test_vehicle_file_with_only_the_mass_and_the_relaxation_time_key(tmp_path: Path) -> None:
    """Stiffnesses and ϑ are optional (identified when absent); ϑ may be given as the Δt-free relaxation
    time τ = C_d/K_d instead, ϑ = τ/(τ + 1 ms), but not both."""
    alone = parse_vehicle('[vehicle]\nmodel = "quarter-car"\nmass_kg = 420.0\n')
    assert alone.spring_stiffness_N_per_m is None and alone.tyre_stiffness_N_per_m is None
    assert alone.tyre_viscoelastic_coefficient is None
    path = tmp_path / "alone.toml"
    write_vehicle(path, alone)
    assert read_vehicle(path) == alone
    by_time = parse_vehicle(GOOD_VEHICLE.replace(THETA_LINE, "tyre_relaxation_time_s = 0.032"))
    assert by_time.tyre_viscoelastic_coefficient == pytest.approx(0.032 / 0.033, rel=1e-12)
    assert by_time.tyre_relaxation_time_s == pytest.approx(0.032, rel=1e-12)
    with pytest.raises(VehicleFileError, match="not both"):
        parse_vehicle(GOOD_VEHICLE + "tyre_relaxation_time_s = 0.032\n")
    with pytest.raises(VehicleFileError, match="tyre_relaxation_time_s must be > 0"):
        parse_vehicle(GOOD_VEHICLE.replace(THETA_LINE, "tyre_relaxation_time_s = 0"))
