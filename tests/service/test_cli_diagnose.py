"""`shockbench diagnose`: JSON of the documented shape, the Markdown report with its plots, the readable
summary, and bad input as one line on stderr."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from doctor_steps import tyre_deflection_zero_error_m

from service.cli import main as main_module

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def files(plate_offset_files: Path) -> Path:
    return plate_offset_files


@pytest.fixture
def cli():
    """shockbench's main()."""
    return main_module.main


def test_json_names_the_plate_offset_and_the_report_has_plots_and_tables(
    files: Path, cli, capsys: pytest.CaptureFixture[str], plate_offset_m: float
) -> None:
    report = files / "report"
    code = cli(
        [
            "diagnose",
            str(files / "rec.csv"),
            "--vehicle",
            str(files / "vehicle.toml"),
            "--json",
            "--report",
            str(report),
        ]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    out = json.loads(captured.out)
    assert {"gap_before_m", "steps", "gap_after_m", "unexplained"} <= set(out)
    assert len(out["steps"]) == 1
    step = out["steps"][0]
    assert set(step) == {"effect", "gap_before_m", "gap_after_m", "parameters", "evidence", "p_value"}
    assert tyre_deflection_zero_error_m(step) == pytest.approx(-plate_offset_m, rel=0.05)
    assert step["p_value"] < out["alpha"]
    assert out["gap_after_m"] <= 0.5 * out["gap_before_m"] and out["unexplained"] is False
    assert out["alpha"] == 0.05 and out["p_value"] >= out["alpha"] and out["located"] is None
    text = (report / "report.md").read_text()
    assert "| step | effect | fitted shape | gap before | gap after | p | evidence |" in text
    assert "sensor_offset" in text and "zero off by" in text
    assert "In the final model, each effect fitted beside the others:\n\n| effect | fitted shape |" in text
    assert f"p = {out['p_value']:.2g}: nothing left that the noise does not explain" in text
    for image in ("gap_per_step.png", "measured_vs_simulated.png", "residual_spectra.png"):
        assert f"]({image})" in text
        assert (report / image).read_bytes()[:8] == PNG
    assert not list(report.glob("*.part")), "no half-written files are left behind"


def test_readable_summary_and_progress(files: Path, cli, capsys: pytest.CaptureFixture[str]) -> None:
    code = cli(
        ["diagnose", str(files / "rec.csv"), "--vehicle", str(files / "vehicle.toml"), "--tyre", "maxwell"]
    )
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "step 1: sensor_offset(x_" in captured.out and "conclusion: named sensor_offset(x_" in captured.out
    assert "evidence:" in captured.out and "diagnose: step 0" in captured.err
    final = "\nthe final model, each family named fitted beside the others:\n  sensor_offset(x_"
    assert final in captured.out
    assert "goodness of fit: p = " in captured.out
    assert "nothing left that the noise does not explain" in captured.out


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["missing.csv", "--vehicle", "{files}/vehicle.toml"], "no such file"),
        (["{files}/rec.csv", "--vehicle", "{files}/axle.toml"], "axle"),
        (
            ["{files}/rec.csv", "--vehicle", "{files}/vehicle.toml", "--report", "{files}/rec.csv"],
            "not a folder",
        ),
        (["{files}/rec.csv", "--vehicle", "{files}/vehicle.toml", "--points", "2"], "--points"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(
    files: Path, cli, capsys: pytest.CaptureFixture[str], arguments: list[str], message: str
) -> None:
    code = cli(["diagnose", *(a.format(files=files) for a in arguments)])
    captured = capsys.readouterr()
    assert code == 2
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and lines[0].startswith("shockbench diagnose: error:")


def test_a_stage_s_de_generations_are_one_line_redrawn(capsys: pytest.CaptureFixture[str]) -> None:
    """The refinement's 40 generations: one line redrawn (as identify's DE), ended with the last; a stage
    without generations keeps a line of its own."""
    from estimator.doctor.diagnose import DiagnoseProgress
    from estimator.solvers.differential_evolution import DEProgress
    from service.cli.diagnose import _progress

    _progress(DiagnoseProgress(1, "testing the final model against its own noise"))
    for generation in range(1, 41):
        best = 1e-3 / generation
        _progress(DiagnoseProgress(1, "refining", DEProgress(generation, 40, best, 24 * generation)))
    _progress(DiagnoseProgress(2, "writing"))
    lines = capsys.readouterr().err.split("\n")
    assert lines[0] == "diagnose: step 1: testing the final model against its own noise"
    redrawn = lines[1].split("\r")[1:]
    assert len(redrawn) == 40 and all(r.startswith("diagnose: step 1: refining [") for r in redrawn)
    assert redrawn[-1].endswith("generation 40/40  best objective 2.5e-05")
    assert lines[2:] == ["diagnose: step 2: writing", ""]
