"""Diagnosis jobs (the model doctor) through the API on the real server, exposed as identification jobs
are: multipart submit at /diagnoses checked at submit, the result of `shockbench diagnose --json`,
and the Markdown report with its PNG plots as the job's files."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
from doctor_steps import tyre_deflection_zero_error_m
from live_server import LiveServer, wait_for_status

from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app

OPERATOR = "operator-key-0123456789"
VIEWER = "viewer-key-0123456789"
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def files(plate_offset_files: Path) -> Path:
    return plate_offset_files


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    keys = KeyRing({OPERATOR: Role.OPERATOR, VIEWER: Role.VIEWER})
    settings = ServiceSettings(data_dir=tmp_path_factory.mktemp("diagnose"), keys=keys)
    with LiveServer(create_app(settings)) as s:
        yield s


@pytest.fixture
def client(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client(OPERATOR) as c:
        yield c


def submit(client: httpx.Client, files: Path, vehicle: str, **options: str) -> httpx.Response:
    with (files / "rec.csv").open("rb") as recording, (files / vehicle).open("rb") as vehicle_file:
        return client.post(
            "/api/v1/diagnoses",
            files={"recording": ("rec.csv", recording), "vehicle": (vehicle, vehicle_file)},
            data=options,
        )


def test_a_diagnosis_job_names_the_hidden_effect_and_serves_its_report(
    server: LiveServer, client: httpx.Client, files: Path, plate_offset_m: float
) -> None:
    response = submit(client, files, "vehicle.toml", tyre="maxwell", max_steps="2")
    assert response.status_code == 201, response.text
    job = response.json()
    assert job["kind"] == "diagnose" and response.headers["location"] == f"/api/v1/jobs/{job['id']}"
    assert job["options"]["max_steps"] == 2

    done = wait_for_status(client, job["links"]["self"], "succeeded", "failed", "cancelled", timeout_s=600)
    assert done["status"] == "succeeded", done["error"]
    result = done["result"]
    assert set(result) >= {"gap_before_m", "steps", "gap_after_m", "unexplained"}
    assert len(result["steps"]) == 1, result["steps"]
    step = result["steps"][0]
    assert step["evidence"]
    assert tyre_deflection_zero_error_m(step) == pytest.approx(-plate_offset_m, rel=0.1)
    assert result["gap_after_m"] <= 0.5 * result["gap_before_m"] and result["unexplained"] is False
    assert result["p_value"] >= result["alpha"] == 0.05

    links = done["links"]["files"]
    assert {"report.md", "gap_per_step.png", "measured_vs_simulated.png", "residual_spectra.png"} <= set(
        links
    )
    with httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {VIEWER}"}) as viewer:
        report = viewer.get(links["report.md"])
        assert report.status_code == 200 and report.headers["content-type"].startswith("text/markdown")
        assert "sensor_offset" in report.text and "gap_per_step.png" in report.text
        plot = viewer.get(links["gap_per_step.png"])
        assert plot.status_code == 200 and plot.content.startswith(PNG)
        missing = viewer.get(f"/api/v1/jobs/{job['id']}/files/..%2Fjob.db")
        assert missing.status_code == 404 and missing.json()["error"]["code"] == "not_found"
    assert done["links"]["plot_png"] is None


def test_a_diagnosis_that_cannot_run_is_refused_at_submit(client: httpx.Client, files: Path) -> None:
    response = submit(client, files, "axle.toml")
    assert response.status_code == 422 and response.json()["error"]["field"] == "recording", response.text
    response = submit(client, files, "vehicle.toml", max_steps="0")
    assert response.status_code == 422 and response.json()["error"]["field"] == "max_steps", response.text
    response = submit(client, files, "vehicle.toml", generations="10")
    assert response.status_code == 422 and response.json()["error"]["field"] == "generations", response.text


def test_a_diagnosis_job_names_as_many_effects_as_the_command_line_by_default() -> None:
    """The page's and the lane's diagnoses are the CLI's for the same recording: the same default options."""
    from estimator.doctor.diagnose import DiagnoseOptions
    from service.jobs.diagnose_job import DiagnoseJobOptions

    assert DiagnoseJobOptions().max_steps == DiagnoseOptions().max_steps


def test_the_final_refinement_s_generations_reach_the_job_as_one_stage_with_time_left() -> None:
    """The doctor's last stage on an unexplained model (the refinement, minutes on a sharp friction step)
    reaches the job's events as its stage, then its generations: throttled by the job's reporter, the first
    and the last always sent, the time left from the generations done (a clock in steps of 1 s)."""
    from estimator.doctor.diagnose import DiagnoseProgress
    from estimator.solvers.differential_evolution import DEProgress
    from service.jobs.context import ProgressReporter
    from service.jobs.diagnose_job import report_progress

    sent, now = [], iter(range(100))
    reporter = ProgressReporter(sent.append, min_interval_s=2.5, clock=lambda: float(next(now)))
    report_progress(reporter, DiagnoseProgress(2, "testing the final model against its own noise"))
    stage = "refining the curve on its free-simulation gap"
    for generation in range(1, 11):
        report_progress(
            reporter, DiagnoseProgress(2, stage, DEProgress(generation, 10, 1.0 / generation, 24))
        )
    report_progress(reporter, DiagnoseProgress(2, "writing"))
    stages = [(p.stage, p.generation) for p in sent]
    assert stages[:2] == [
        ("step 2: testing the final model against its own noise", None),
        (f"step 2: {stage}", None),
    ]
    heard = [p for p in sent if p.stage == f"step 2: {stage}" and p.generation is not None]
    assert [p.generation for p in heard] == [1, 4, 7, 10]  # every 3 s of the clock's 1 s a call, and the last
    assert heard[0].eta_s is None and heard[-1].eta_s == 0.0 and heard[1].eta_s == pytest.approx(6.0)
    assert sent[-1].stage == "step 2: writing" and sent[-1].generation == 10  # how far the refinement went
