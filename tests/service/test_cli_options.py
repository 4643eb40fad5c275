"""Unit-bearing options are spelled alike across the CLI's commands (`--duration-s`, `--settle-s`,
`--amplitude-mm`, `--stop-hz`), and a spelling they had before still works, with one line on stderr saying the
new one (service/cli/options.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest
from cli_help import help_text, usage_options

from daq.formats.vehicle_file import write_vehicle
from service.cli.main import COMMAND_MODULES, build_parser, main
from service.cli.options import add_option
from simulators.vehicle_sim import default_axle, default_quarter_car

UNIT_SPELLINGS = {
    "--duration": "--duration-s",
    "--settle": "--settle-s",
    "--rest": "--rest-s",
    "--amplitude": "--amplitude-mm",
    "--start": "--start-hz",
    "--stop": "--stop-hz",
}
"""Each quantity the commands share and its one spelling: unit last, as the code names values."""


def test_every_command_spells_a_shared_quantity_alike() -> None:
    seen: dict[str, set[str]] = {}
    for command in COMMAND_MODULES:
        for option in usage_options(command):
            for stem, spelling in UNIT_SPELLINGS.items():
                if option == stem or option.startswith(f"{stem}-"):
                    seen.setdefault(option, set()).add(command)
                    assert option == spelling, f"{command}: {option} should be spelled {spelling}"
    assert {"simulate", "sweep"} <= seen["--duration-s"] & seen["--settle-s"] & seen["--amplitude-mm"]
    assert {"simulate", "sweep"} <= seen["--stop-hz"]


def test_help_shows_the_new_spellings_alone() -> None:
    text = help_text("simulate")
    for new in (
        "--duration-s",
        "--settle-s",
        "--amplitude-mm",
        "--tyre-damping-ns-per-m",
        "--roll-inertia-kg-m2",
    ):
        assert new in text
    for old in ("--seconds", "--settle ", "--amplitude-m ", "--tyre-damping ", "--roll-inertia "):
        assert old not in text


@pytest.mark.parametrize(
    ("old", "value", "new", "expected", "converted"),
    [
        ("--seconds", "7", "--duration-s", 7.0, ""),
        ("--settle", "0.5", "--settle-s", 0.5, ""),
        ("--amplitude-m", "0.003", "--amplitude-mm", 3.0, " (in mm: read as --amplitude-mm 3)"),
        ("--tyre-damping", "900", "--tyre-damping-ns-per-m", 900.0, ""),
        ("--roll-inertia", "300", "--roll-inertia-kg-m2", 300.0, ""),
    ],
)
def test_an_old_spelling_is_read_with_a_one_line_notice(
    capsys: pytest.CaptureFixture[str], old: str, value: str, new: str, expected: float, converted: str
) -> None:
    base = ["simulate", "--vehicle", "v.toml", "--out", "r.csv"]
    dest = new.removeprefix("--").replace("-", "_")
    args = build_parser("simulate").parse_args([*base, old, value])
    assert getattr(args, dest) == pytest.approx(expected)
    assert capsys.readouterr().err == f"shockbench simulate: {old} is now {new}{converted}\n"
    assert getattr(build_parser("simulate").parse_args([*base, new, value]), dest) == pytest.approx(
        float(value)
    )
    assert getattr(build_parser("simulate").parse_args(base), dest) != pytest.approx(expected)  # the default
    assert capsys.readouterr().err == ""


def test_old_spellings_give_the_same_recording_as_the_new(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    vehicle = tmp_path / "axle.toml"
    write_vehicle(vehicle, default_axle().known)
    common = ["simulate", "--vehicle", str(vehicle), "--seed", "2"]
    new = [*common, "--out", str(tmp_path / "new.csv"), "--duration-s", "2", "--settle-s", "0.5"]
    new += ["--amplitude-mm", "3", "--tyre-damping-ns-per-m", "1200", "--roll-inertia-kg-m2", "300"]
    old = [*common, "--out", str(tmp_path / "old.csv"), "--seconds", "2", "--settle", "0.5"]
    old += ["--amplitude-m", "0.003", "--tyre-damping", "1200", "--roll-inertia", "300"]
    assert main(new) == 0
    assert capsys.readouterr().err == ""
    assert main(old) == 0
    assert len(capsys.readouterr().err.splitlines()) == 5  # one notice per old spelling
    assert (tmp_path / "old.csv").read_text() == (tmp_path / "new.csv").read_text().replace(
        "new.csv", "old.csv"
    )
    assert "3 mm, 2 s" in (tmp_path / "new.csv").read_text()  # the sweep the metadata states


def test_a_bad_duration_names_the_new_spelling(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    vehicle = tmp_path / "car.toml"
    write_vehicle(vehicle, default_quarter_car().known)
    assert (
        main(["simulate", "--vehicle", str(vehicle), "--out", str(tmp_path / "r.csv"), "--seconds", "0"]) == 2
    )
    assert capsys.readouterr().err.splitlines() == [
        "shockbench simulate: --seconds is now --duration-s",
        "shockbench simulate: error: --duration-s must lie in (0, 600]",
    ]


def test_the_helper_keeps_the_new_default_and_converts_only_the_old_unit() -> None:
    parser = argparse.ArgumentParser(prog="tool")
    add_option(
        parser, "--gap-mm", formerly="--gap-m", factor=1e3, unit="mm", type=float, default=2.0, help="gap"
    )
    assert parser.parse_args([]).gap_mm == 2.0
    assert parser.parse_args(["--gap-mm", "5"]).gap_mm == 5.0
    assert parser.parse_args(["--gap-m=0.005"]).gap_mm == pytest.approx(5.0)
    assert "--gap-m " not in parser.format_help() and "--gap-mm" in parser.format_help()
