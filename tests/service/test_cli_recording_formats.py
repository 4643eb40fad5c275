"""`identify`, `diagnose`, `validate` and `export` read every recording the bench writes (issue 31): the
HDF5 file `shockbench sweep` writes and the recording CSV, told apart by content, with the reader the
worker and `reanalyse` use. Without --vehicle the vehicle comes from the HDF5 sweep, said on stderr; a CSV
needs --vehicle. Garbled input of every kind is one line naming the file, exit 2.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import shutil
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import parse_vehicle_file, write_vehicle
from daq.storage.hdf5_recording import RecordingWriter
from estimator.recording import QUARTER_CAR_CHANNELS
from service.cli.main import main
from simulators.vehicle_sim import default_quarter_car

REPO = Path(__file__).resolve().parents[2]
TAKEN = "vehicle: taken from the sweep file"


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A sweep of the simulated bench (run.h5, its vehicle file v.toml), its CSV export (run.csv) and the
    identify result of the sweep (model.json)."""
    folder = tmp_path_factory.mktemp("formats")
    vehicle = folder / "v.toml"
    write_vehicle(vehicle, default_quarter_car().known)
    h5, csv, model = folder / "run.h5", folder / "run.csv", folder / "model.json"
    sweep = ["sweep", "--simulated", "--vehicle", str(vehicle), "--out", str(h5), "--quiet"]
    assert main([*sweep, "--duration-s", "6", "--settle-s", "1"]) == 0
    assert main(["export", str(h5), "--out", str(csv)]) == 0
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["identify", str(h5), "--vehicle", str(vehicle), "--json"]) == 0
    model.write_text(printed.getvalue(), encoding="utf-8")
    return {"folder": folder, "vehicle": vehicle, "h5": h5, "csv": csv, "model": model}


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def identify_json(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[dict, str]:
    code, out, err = run(capsys, "identify", *args, "--json")
    assert code == 0, err
    return json.loads(out), err


def test_identify_takes_the_vehicle_from_the_sweep_and_says_so(
    bench: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    stated, err = identify_json(capsys, bench["h5"], "--vehicle", bench["vehicle"])
    assert TAKEN not in err
    carried, err = identify_json(capsys, bench["h5"])
    lines = [line for line in err.splitlines() if TAKEN in line]
    assert len(lines) == 1, err
    assert str(bench["h5"]) in lines[0] and "v.toml" in lines[0] and "quarter-car, 420 kg" in lines[0]
    assert carried["masses_kg"] == stated["masses_kg"] and carried["curves"] == stated["curves"]


def test_diagnose_and_validate_read_the_sweep(
    bench: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(capsys, "diagnose", bench["h5"], "--json")
    assert code == 0, err
    assert f"shockbench diagnose: {TAKEN} {bench['h5']}" in err
    assert json.loads(out)["gap_after_m"] < 1e-4
    code, out, err = run(capsys, "validate", bench["h5"], "--model", bench["model"], "--json")
    assert code == 0, err
    assert json.loads(out)["gap_ratio"] < 0.05


def test_export_writes_the_sweep_and_rewrites_a_csv(
    bench: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    exported = read_recording_csv(bench["csv"])
    assert exported.time_s.size == 7001 and exported.metadata["source"] == str(bench["h5"])
    again = bench["folder"] / "again.csv"
    code, out, err = run(capsys, "export", bench["csv"], "--out", again)
    assert code == 0, err
    assert "wrote" in out and "incomplete" not in out
    rewritten = read_recording_csv(again)
    np.testing.assert_array_equal(rewritten.channels["x_t"], exported.channels["x_t"])
    assert rewritten.metadata == exported.metadata  # its source (the sweep) kept


def test_the_content_decides_not_the_name(bench: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """A sweep renamed .csv is read as HDF5 (its vehicle with it); a CSV named .h5 is read as CSV, and
    so needs --vehicle."""
    folder = bench["folder"]
    renamed_sweep, renamed_csv = folder / "sweep-renamed.csv", folder / "csv-renamed.h5"
    shutil.copy(bench["h5"], renamed_sweep)
    shutil.copy(bench["csv"], renamed_csv)
    from_h5, _ = identify_json(capsys, bench["h5"])
    from_renamed, err = identify_json(capsys, renamed_sweep)
    assert TAKEN in err and from_renamed["curves"] == from_h5["curves"]
    from_csv, _ = identify_json(capsys, bench["csv"], "--vehicle", bench["vehicle"])
    from_renamed_csv, err = identify_json(capsys, renamed_csv, "--vehicle", bench["vehicle"])
    assert from_renamed_csv["curves"] == from_csv["curves"] and TAKEN not in err
    code, _, err = run(capsys, "identify", renamed_csv)
    assert code == 2 and err.count("\n") == 1 and "--vehicle" in err and renamed_csv.name in err
    code, _, err = run(capsys, "export", renamed_sweep, "--out", folder / "from-renamed.csv")
    assert code == 0, err


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_a_csv_without_vehicle_is_exit_2_naming_the_option(
    bench: dict[str, Path], capsys: pytest.CaptureFixture[str], command: str
) -> None:
    code, out, err = run(capsys, command, bench["csv"])
    assert code == 2 and out == ""
    expected = f"{bench['csv']}: a recording CSV carries no vehicle; give --vehicle V.toml"
    assert err == f"shockbench {command}: error: {expected}\n"


def write_hdf5(path: Path, *, vehicle_text: str | None = None, gap: bool = False) -> Path:
    t = np.arange(3000) * 0.001
    data = {c: 1e-3 * np.sin(2 * np.pi * (i + 2) * t) for i, c in enumerate(QUARTER_CAR_CHANNELS)}
    if gap:
        data["x_t"][1200:1205] = np.nan
    vehicle = None if vehicle_text is None else parse_vehicle_file(vehicle_text, "their.toml")
    with RecordingWriter(path, QUARTER_CAR_CHANNELS, 0.001, vehicle=vehicle) as writer:
        writer.append(t, data)
        writer.close(True)
    return path


def test_an_hdf5_recording_without_vehicle_text_needs_vehicle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    h5 = write_hdf5(tmp_path / "bare.h5")
    code, _, err = run(capsys, "identify", h5)
    assert code == 2 and err.count("\n") == 1
    assert "bare.h5: the HDF5 recording carries no vehicle file; give --vehicle V.toml" in err


@pytest.mark.parametrize("command", ["identify", "diagnose", "validate"])
def test_an_hdf5_recording_with_gaps_is_refused_pointing_to_export(
    bench: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    h5 = write_hdf5(tmp_path / "gaps.h5", vehicle_text=bench["vehicle"].read_text(), gap=True)
    companion = ["--model", bench["model"]] if command == "validate" else []
    code, _, err = run(capsys, command, h5, *companion)
    assert code == 2 and err.count("\n") == 1, err
    assert "1 gap(s) (5 sample(s) without a measurement), the first at t = 1.200 s" in err
    assert f"{command} needs gap-free data: `shockbench export {h5} --out REC.csv --allow-gaps`" in err
    assert "allow_gaps (" not in err


# ---- garbled input: one line naming the file, exit 2 -------------------------------------------------

Maker = Callable[[Path, bytes], Path]


def _file(name: str, content: Callable[[bytes], bytes]) -> Maker:
    def make(folder: Path, sweep: bytes) -> Path:
        path = folder / name
        path.write_bytes(content(sweep))
        return path

    return make


def _folder(folder: Path, _sweep: bytes) -> Path:
    (folder / "rec.h5").mkdir()
    return folder / "rec.h5"


RANDOM = np.random.default_rng(31).integers(0, 256, 5000, dtype=np.uint8).tobytes()
GOOD_CSV = "t,x_s,x_t,x_r\n" + "".join(f"{k * 0.001:.3f},0.001,0.002,0.003\n" for k in range(10))

GARBLED_RECORDINGS: dict[str, tuple[Maker, str]] = {
    "random bytes (.h5)": (_file("rec.h5", lambda _: RANDOM), "not an HDF5 file"),
    "random bytes (.csv)": (_file("rec.csv", lambda _: RANDOM), "not a text file (UTF-8 expected"),
    "HDF5 cut after 1000 bytes": (_file("rec.h5", lambda s: s[:1000]), "cannot read the recording"),
    "HDF5 cut in half": (_file("rec.h5", lambda s: s[: len(s) // 2]), "cannot read the recording"),
    "HDF5 cut in half, named .csv": (_file("rec.csv", lambda s: s[: len(s) // 2]), "cannot read the"),
    "HDF5 with its object headers zeroed": (
        _file("rec.h5", lambda s: s[:48] + bytes(2000) + s[2048:]),
        "cannot read the recording",
    ),
    "HDF5 signature, then junk": (_file("rec.h5", lambda _: b"\x89HDF\r\n\x1a\n" + RANDOM), "cannot read"),
    "CSV in Latin-1": (
        _file("rec.csv", lambda _: ("# operator: Jos\xe9\n" + GOOD_CSV).encode("latin-1")),
        "rec.csv:1: not a text file (UTF-8 expected; byte 0xe9 is not UTF-8)",
    ),
    "CSV in UTF-16": (_file("rec.csv", lambda _: GOOD_CSV.encode("utf-16")), "not a text file"),
    "CSV with NUL bytes": (_file("rec.csv", lambda _: GOOD_CSV.replace("0.002", "\0").encode()), "rec.csv:2"),
    "bad CSV named .h5": (
        _file("rec.h5", lambda _: b"hello,world\n1,2\n"),
        "rec.h5: not an HDF5 file (no HDF5 signature), nor a recording CSV: line 1: columns hello,world",
    ),
    "empty (.h5)": (_file("rec.h5", lambda _: b""), "rec.h5: empty file"),
    "empty (.csv)": (_file("rec.csv", lambda _: b""), "rec.csv: empty file"),
    "a folder": (_folder, "rec.h5: is a folder, not a recording file"),
    "missing": (lambda folder, _: folder / "gone.h5", "gone.h5: no such file"),
}

GARBLED_VEHICLES: dict[str, tuple[bytes, str]] = {
    "random bytes": (RANDOM, "not a text file (UTF-8 expected)"),
    "not TOML": (b"[vehicle\nmass_kg = 1\n", "not valid TOML"),
    "Latin-1": ('[vehicle]\nmodel = "quarter-car"\nmass_kg = 420 # \xe0 vide\n'.encode("latin-1"), "UTF-8"),
    "huge number": (b'[vehicle]\nmodel = "quarter-car"\nmass_kg = ' + b"9" * 400 + b"\n", "too large"),
    "nested too deeply": (b"[vehicle]\nmass_kg = " + b"[" * 100_000 + b"\n", "not valid TOML"),
}

COMMANDS = ("identify", "diagnose", "validate", "export")


def assert_one_line_error(code: int, out: str, err: str, command: str, names: str, message: str) -> None:
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith(f"shockbench {command}: error: "), err
    assert names in err and message in err, err
    assert "Traceback" not in err and "internal error" not in err and out == ""


@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize("case", list(GARBLED_RECORDINGS))
def test_a_garbled_recording_is_one_line_exit_2(
    bench: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, case: str
) -> None:
    make, message = GARBLED_RECORDINGS[case]
    path = make(tmp_path, bench["h5"].read_bytes())
    out_csv = tmp_path / "out.csv"
    companion = {
        "identify": ["--vehicle", bench["vehicle"]],
        "diagnose": ["--vehicle", bench["vehicle"]],
        "validate": ["--model", bench["model"]],
        "export": ["--out", out_csv],
    }[command]
    code, out, err = run(capsys, command, path, *companion)
    assert_one_line_error(code, out, err, command, path.name, message)
    assert not out_csv.exists()


@pytest.mark.parametrize("command", ["identify", "diagnose"])
@pytest.mark.parametrize("case", list(GARBLED_VEHICLES))
def test_a_garbled_vehicle_file_is_one_line_exit_2(
    bench: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str, case: str
) -> None:
    content, message = GARBLED_VEHICLES[case]
    vehicle = tmp_path / "garbled.toml"
    vehicle.write_bytes(content)
    code, out, err = run(capsys, command, bench["h5"], "--vehicle", vehicle)
    assert_one_line_error(code, out, err, command, "garbled.toml", message)


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_a_garbled_vehicle_text_inside_the_sweep_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    h5 = write_hdf5(tmp_path / "odd.h5", vehicle_text='[vehicle]\nmodel = "quarter-car"\nmass_kg = 420\n')
    with h5py.File(h5, "r+") as f:
        f.attrs["vehicle_text"] = '[vehicle]\nmodel = "bicycle"\nmass_kg = 420\n'
    code, out, err = run(capsys, command, h5)
    assert_one_line_error(code, out, err, command, "odd.h5 (its vehicle text)", 'model must be "quarter-car"')


# ---- what --help and the README say ----------------------------------------------------------------------


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_help_and_readme_say_the_vehicle_is_optional_and_the_sweep_is_read(
    capsys: pytest.CaptureFixture[str], command: str
) -> None:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "[--vehicle VEHICLE]" in text and "an HDF5 sweep" in text
    assert "a recording CSV needs --vehicle" in text
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    synopsis = re.search(rf"^ +shockbench {command} (.*)$", readme, re.MULTILINE)
    assert synopsis is not None
    assert synopsis.group(1).startswith("REC.h5|REC.csv [--vehicle V.toml]")
