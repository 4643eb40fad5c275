"""`shockbench report RESULT.json [--recording REC] --out FILE.pdf|.html`: from a sweep of the simulated
bench (`shockbench sweep --operator`) and its `identify --json`, the sheet is written (exit 0) with the
bench, operator and date the HDF5 sweep records and the plots over time; a job as the API answers it names
its lane and ids. Bad input of every kind is exit 2 with one line naming the file, nothing written."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path
from typing import Any

import pytest
from pypdf import PdfReader

from daq.formats.vehicle_file import write_vehicle
from service.cli.main import main
from simulators.vehicle_sim import default_axle, default_quarter_car


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """run.h5: a 4 s sweep of the simulated bench by B. Tester; result.json: its `identify --json`."""
    folder = tmp_path_factory.mktemp("report-cli")
    vehicle, h5, result = folder / "v.toml", folder / "run.h5", folder / "result.json"
    write_vehicle(vehicle, default_quarter_car().known)
    sweep = ["sweep", "--simulated", "--vehicle", str(vehicle), "--out", str(h5), "--quiet"]
    assert main([*sweep, "--duration-s", "4", "--settle-s", "0.5", "--operator", "B. Tester"]) == 0
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["identify", str(h5), "--json"]) == 0
    result.write_text(printed.getvalue(), encoding="utf-8")
    axle = folder / "axle.toml"
    write_vehicle(axle, default_axle().known)
    return {"folder": folder, "h5": h5, "result": result, "axle_vehicle": axle}


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main(["report", *(str(a) for a in args)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def pdf_text(path: Path) -> str:
    return " ".join(" ".join(page.extract_text() for page in PdfReader(path).pages).split())


def test_a_pdf_from_the_result_and_its_hdf5_sweep(
    bench: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    out = bench["folder"] / "report.pdf"
    code, printed, err = run(capsys, bench["result"], "--recording", bench["h5"], "--out", out)
    assert (code, printed, err) == (0, f"wrote {out}\n", "")
    text = pdf_text(out)
    assert "operator B. Tester" in text and "bench simulated bench" in text
    assert "vehicle id not recorded" in text and "tyre pressure not recorded" in text  # not in the files
    assert "date 20" in text and "date not recorded" not in text  # the sweep's start, as recorded
    assert "The sweep over time: plate, wheel and body displacement" in text
    result = json.loads(bench["result"].read_text())
    assert f"wheel {result['inspection']['eusama_percent']:.1f} %" in text
    assert "The result carries no verdict: judged here by the default thresholds" in text


def test_an_html_page_from_a_job_as_the_api_answers_it(
    bench: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    job = {
        "id": 57,
        "lane": "lane-3",
        "kind": "identify",
        "status": "succeeded",
        "sweep_id": 41,
        "result": json.loads(bench["result"].read_text()),
    }
    path = bench["folder"] / "job-57.json"
    path.write_text(json.dumps(job), encoding="utf-8")
    out = bench["folder"] / "report.html"
    code, _, err = run(capsys, path, "--out", out)
    assert code == 0, err
    page = out.read_text(encoding="utf-8")
    assert "lane-3" in page and "sweep 41, job 57" in page
    assert "no recording given" in page and "http://" not in page.replace("http://www.w3.org/", "")


def garbled(folder: Path, name: str) -> tuple[list[str], str]:
    """(the report's arguments, the start of the one line that must name the problem) for input `name`."""
    result = folder / "result.json"
    cases: dict[str, tuple[str, bytes, list[str], str]] = {
        "truncated JSON": ("cut.json", b'{"curves": [{"corner": ', [], ": not JSON"),
        "random bytes": ("noise.json", bytes(range(128, 256)), [], ": not UTF-8 text"),
        "not a result": (
            "other.json",
            b'{"gap_m": 1}',
            [],
            ": not an identification result: curves",
        ),
        "a diagnosis job": (
            "diag.json",
            b'{"id": 3, "kind": "diagnose", "result": {}}',
            [],
            ": job 3 is a diagnose job; a report needs an identification",
        ),
        "a recording of noise": ("rec.h5", b"\x89HDF\r\n\x1a\n" + bytes(200), ["--recording"], ":"),
        "an output it cannot write": ("", b"", ["--out", str(folder / "report.txt")], "--out"),
    }
    file, content, option, problem = cases[name]
    if not file:
        return [str(result), *option], problem
    path = folder / file
    path.write_bytes(content)
    if option:
        return [str(result), *option, str(path), "--out", str(folder / "x.pdf")], f"{path}{problem}"
    return [str(path), "--out", str(folder / "x.pdf")], f"{path}{problem}"


@pytest.mark.parametrize(
    "name",
    [
        "truncated JSON",
        "random bytes",
        "not a result",
        "a diagnosis job",
        "a recording of noise",
        "an output it cannot write",
    ],
)
def test_bad_input_is_exit_2_naming_the_file(
    bench: dict[str, Path], capsys: pytest.CaptureFixture[str], name: str
) -> None:
    arguments, problem = garbled(bench["folder"], name)
    code, printed, err = run(capsys, *arguments)
    assert code == 2 and printed == "", err
    assert err.startswith(f"shockbench report: error: {problem}") and err.count("\n") == 1, err
    assert not (bench["folder"] / "x.pdf").exists()


def test_a_recording_of_another_vehicle_kind_is_refused(
    bench: dict[str, Any], capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    from daq.formats.recording_csv import write_recording_csv
    from estimator.sweep import SweepSettings
    from simulators.vehicle_sim import SimulationSettings, simulate

    axle = tmp_path / "axle.csv"
    settings = SimulationSettings(sweep=SweepSettings(duration_s=2.0), seed=1, substeps=2)
    write_recording_csv(axle, simulate(default_axle(), settings).recording)
    code, _, err = run(capsys, bench["result"], "--recording", axle, "--out", tmp_path / "r.pdf")
    assert code == 2
    assert (
        err == f"shockbench report: error: {axle}: the recording is an axle's, the result a quarter car's\n"
    )
    assert not (tmp_path / "r.pdf").exists()
