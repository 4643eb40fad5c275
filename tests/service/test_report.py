"""The test's report (service.report) from real identification results, quarter car and axle, read back:
the PDF's text names every field the sheet must show with the stored values (vehicle, operator, lane,
bench, date, tyre pressure; the verdict per corner with the thresholds' version and limits; EUSAMA, least
phase angle and damping ratio with the axle's left/right imbalance; masses and stiffnesses with their
intervals; the doctor's conclusion; the hash-chain record), says "not recorded" where the test recorded
nothing, and the HTML page says the same without a single external URL. Both are deterministic."""

from __future__ import annotations

import io
import re
from datetime import UTC, datetime
from typing import Any

import pytest
from live_server import SimulatedInputs
from pypdf import PdfReader

from daq.formats.recording_csv import read_recording_csv
from estimator.identify import IdentifyOptions
from estimator.recording import Recording
from estimator.sweep import SweepSettings
from estimator.verdict import VerdictThresholds
from service.analysis import identify_recording
from service.api.results import verdict_of
from service.jobs.context import finite_json
from service.report import RecordedTest, ReportInput, ReportInputError, report_html, report_pdf
from service.report.content import ChainRecord
from simulators.vehicle_sim import SimulationSettings, default_axle, simulate

HASH = "3f" * 32
RECORD = RecordedTest(
    vehicle_id="WVW ZZZ 1JZ 3W386752",
    operator="A. Tester",
    lane="lane-7",
    bench="bench-west",
    date=datetime(2026, 11, 25, 18, 4, 55, tzinfo=UTC),
    tyre_pressure_bar=2.3,
    sweep_id=41,
    job_id=57,
)
DIAGNOSIS = {
    "gap_before_m": 2.1e-4,
    "steps": [
        {
            "effect": "sensor_offset(x_r)",
            "gap_before_m": 2.1e-4,
            "gap_after_m": 3.2e-5,
            "parameters": {"channel": "x_r", "offset_m": 0.0005},
            "evidence": "the plate laser reads high",
            "p_value": 1e-12,
        }
    ],
    "gap_after_m": 3.2e-5,
    "unexplained": False,
    "conclusion": "The plate laser reads 0.5 mm high; with it the model explains the sweep.",
    "starting_effects": ["tyre_viscoelastic"],
    "final_effects": ["tyre_viscoelastic", "sensor_offset(x_r)"],
    "expected_gap_m": 3.0e-5,
    "residual_ratio": 1.05,
    "p_value": 0.31,
    "alpha": 0.05,
    "where": None,
    "located": None,
    "noise_floor_m": 5e-6,
    "candidates": [],
}


def stored(recording: Recording, vehicle: Any, limits: VerdictThresholds | None = None) -> dict[str, Any]:
    """The result as the worker stores it: finite JSON with the verdict of `limits`."""
    result = finite_json(identify_recording(recording, vehicle, IdentifyOptions()).to_json())
    return verdict_of(limits or VerdictThresholds())("identify", result)


@pytest.fixture(scope="module")
def axle() -> tuple[dict[str, Any], Recording]:
    car = default_axle()
    settings = SimulationSettings(sweep=SweepSettings(duration_s=4.0), seed=2, substeps=2)
    recording = simulate(car, settings).recording
    return stored(recording, car.known), recording


@pytest.fixture(scope="module")
def quarter_car(inputs: SimulatedInputs) -> dict[str, Any]:
    from daq.formats.vehicle_file import read_vehicle

    return stored(read_recording_csv(inputs.recording), read_vehicle(inputs.vehicle))


def pdf_text(pdf: bytes) -> str:
    """Every page's text, its whitespace made single spaces."""
    return " ".join(" ".join(page.extract_text() for page in PdfReader(io.BytesIO(pdf)).pages).split())


def full_input(result: dict[str, Any], recording: Recording | None) -> ReportInput:
    return ReportInput(
        result=result,
        test=RECORD,
        chain=ChainRecord("lane-7", 12, HASH, 57),
        diagnosis=DIAGNOSIS,
        diagnosis_job_id=58,
        recording=recording,
        software="0.1.0",
    )


def test_the_pdf_of_an_axle_names_every_field_with_its_stored_value(axle: tuple[dict, Recording]) -> None:
    result, recording = axle
    pdf = report_pdf(full_input(result, recording))
    text = pdf_text(pdf)
    assert len(PdfReader(io.BytesIO(pdf)).pages) == 2

    for field in (
        "vehicle id WVW ZZZ 1JZ 3W386752",
        "operator A. Tester",
        "lane lane-7",
        "bench bench-west",
        "date 2026-11-25 18:04:55 UTC",
        "tyre pressure 2.3 bar",
        "sweep 41",
        "identification job 57",
    ):
        assert field in text, field

    verdict = result["verdict"]
    assert f"Verdict: {verdict['outcome'].upper()}" in text
    assert f"thresholds {verdict['thresholds_version']} when the result was stored" in text
    assert "least phase angle fails below 35°; EUSAMA passes from 40 %, fails below 20 %" in text
    assert "check above 15 %, fail above 20 % of the larger" in text
    for side in ("left", "right"):
        f = result["inspection"][side]
        row = (
            f"{side} {f['eusama_percent']:.1f} % {f['phase_shift_min_deg']:.1f}° {f['damping_ratio']:.2f} "
            f"{f['equivalent_damping_Ns_per_m']:.0f} N·s/m PASS"
        )
        assert row in text, row
    imbalance = result["inspection"]["imbalance"]
    assert f"left/right Δ {imbalance['eusama_difference_points']:.1f} points" in text
    assert f"Δ {imbalance['damping_difference_percent']:.1f} %" in text

    masses, spread = result["masses_kg"], result["masses_kg_interval"]
    assert (
        f"sprung mass {masses['sprung']:.1f} kg {spread['sprung'][0]:.1f} – {spread['sprung'][1]:.1f} kg"
        in text
    )
    low, high = spread["unsprung"]
    assert (
        f"unsprung mass (per wheel) {masses['unsprung']:.2f} kg {low:.2f} – {high:.2f} kg identified" in text
    )
    assert (
        "spring stiffness 26 kN/m — vehicle file" in text and "anti-roll bar 18 kN/m — vehicle file" in text
    )
    low, high = result["tyre_damping_Ns_per_m_interval"]
    assert f"tyre damping {result['tyre_damping_Ns_per_m']:.0f} N·s/m {low:.0f} – {high:.0f} N·s/m" in text
    assert "roll inertia" in text

    assert "left, right overlaid" not in text and "left and right overlaid" in text
    assert "The sweep over time: plate, wheel and body displacement" in text
    assert "Transmissibility: wheel and body over plate amplitude, by frequency" in text
    assert f"Conclusion (job 58): {DIAGNOSIS['conclusion']}" in text
    assert (
        "1 sensor_offset(x_r) 32 µm the plate laser reads high" in text
        and "x_r zero off by +500.0 µm" in text
    )
    assert "p = 0.31: nothing left that the noise does not explain" in re.sub(r"\s+", " ", text)
    assert f"lane lane-7 sequence 12 job 57 result hash {HASH}" in text
    assert "shockbench verify --lane lane-7" in text


def test_what_the_test_did_not_record_is_said_and_nothing_is_filled_in(quarter_car: dict[str, Any]) -> None:
    bare = {key: value for key, value in quarter_car.items() if key != "verdict"}  # as identify --json
    text = pdf_text(report_pdf(ReportInput(result=bare)))
    for label in ("vehicle id", "operator", "lane", "bench", "date", "tyre pressure"):
        assert f"{label} not recorded" in text, label
    assert "Hash-chain record: not recorded: this result was not stored by the service." in text
    assert "Model doctor: not run on this test." in text
    assert "Sweep over time and transmissibility: no recording given." in text
    assert (
        "The result carries no verdict: judged here by the default thresholds shockbench-default-2026.1"
        in text
    )
    assert "left/right" not in text  # a quarter car has no axle imbalance
    f = quarter_car["inspection"]
    assert f"wheel {f['eusama_percent']:.1f} % {f['phase_shift_min_deg']:.1f}°" in text


def test_each_corner_is_judged_by_the_thresholds_stored_with_the_result(axle: tuple[dict, Recording]) -> None:
    result, _ = axle
    strict = VerdictThresholds(version="lane-strict-2027.2", phase_fail_below_deg=92.0)
    left, right = (result["inspection"][side]["phase_shift_min_deg"] for side in ("left", "right"))
    assert left < 92.0 < right  # the simulated axle: 89° and 96°
    judged = verdict_of(strict)("identify", {k: v for k, v in result.items() if k != "verdict"})
    text = pdf_text(report_pdf(ReportInput(result=judged)))
    assert "Verdict: FAIL" in text and "thresholds lane-strict-2027.2 when the result was stored" in text
    assert re.search(r"left [\d.]+ % [\d.]+° [\d.]+ \d+ N·s/m FAIL", text)
    assert re.search(r"right [\d.]+ % [\d.]+° [\d.]+ \d+ N·s/m PASS", text)
    assert f"• left: least phase shift {left:.1f}° below 92°" in text


def test_the_html_page_says_the_same_and_loads_nothing(axle: tuple[dict, Recording]) -> None:
    result, recording = axle
    page = report_html(full_input(result, recording))
    assert not re.search(r"""(src|href)\s*=\s*["']?\s*(https?:)?//""", page, flags=re.IGNORECASE)
    assert "http://" not in page.replace("http://www.w3.org/", "") and "https://" not in page
    assert "<script" not in page and "<link" not in page and "@import" not in page
    assert page.count('<img src="data:image/svg+xml;base64,') == 3
    for text in (
        "WVW ZZZ 1JZ 3W386752",
        "A. Tester",
        "lane-7",
        "bench-west",
        "2026-11-25 18:04:55 UTC",
        "2.3 bar",
    ):
        assert text in page
    assert HASH in page and "sensor_offset" in page and result["verdict"]["thresholds_version"] in page
    quoted = report_html(ReportInput(result=result, test=RecordedTest(operator="<b>O'Neil & Co</b>")))
    assert "&lt;b&gt;O&#x27;Neil &amp; Co&lt;/b&gt;" in quoted and "<b>O'Neil" not in quoted


def test_the_same_result_gives_the_same_bytes(axle: tuple[dict, Recording]) -> None:
    source = full_input(*axle)
    assert report_pdf(source) == report_pdf(source)
    assert report_html(source) == report_html(source)


@pytest.mark.parametrize(
    ("result", "problem"),
    [
        ([1, 2], "not an identification result (a JSON list, not an object)"),
        ({"curves": []}, "not an identification result: masses_kg: Field required"),
    ],
)
def test_a_result_that_is_not_an_identifications_is_one_line(result: Any, problem: str) -> None:
    with pytest.raises(ReportInputError) as raised:
        report_pdf(ReportInput(result=result))
    assert str(raised.value) == problem
