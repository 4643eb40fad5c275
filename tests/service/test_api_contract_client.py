"""The OpenAPI schema is a contract a client can be generated from: openapi-python-client generates a
Python client from the live server's /api/v1/openapi.json (offline, no formatter hooks), and that client
alone runs the bench's day: status, an identification job from uploaded files to its curve and plot, its
event stream, a diagnosis submitted and cancelled, a sweep on the simulated bench and its recording, the
job and sweep lists. Every answer is parsed into the generated typed models."""

from __future__ import annotations

import importlib
import io
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import httpx
import numpy as np
import pytest
from live_server import LiveServer, SimulatedInputs, wait_until

from daq.formats.vehicle_file import format_vehicle
from estimator.damper import PiecewiseLinearCurve
from service.access import KeyRing, Role
from service.api import ServiceSettings, create_app
from simulators.vehicle_sim import default_quarter_car

OPERATOR = "operator-key-0123456789"
PACKAGE = "shockbench_contract_client"
GENERATOR_CONFIG = f"""\
package_name_override: {PACKAGE}
project_name_override: shockbench-contract-client
post_hooks: []
content_type_overrides:
  image/png: application/octet-stream
  image/svg+xml: application/octet-stream
  text/csv: application/octet-stream
  text/markdown: application/octet-stream
  application/pdf: application/octet-stream
  text/html: application/octet-stream
"""
"""As README's "Generated clients" says: no formatter hooks (offline), downloads read as bytes."""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    settings = ServiceSettings(
        data_dir=tmp_path_factory.mktemp("contract-client"),
        keys=KeyRing({OPERATOR: Role.OPERATOR}),
        simulated=True,
    )
    with LiveServer(create_app(settings)) as s:
        yield s


@pytest.fixture(scope="module")
def generated(server: LiveServer, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ModuleType]:
    """The generated client package, imported from its temporary folder."""
    folder = tmp_path_factory.mktemp("generated")
    schema = folder / "openapi.json"
    schema.write_bytes(httpx.get(f"{server.url}/api/v1/openapi.json").content)
    config = folder / "config.yaml"
    config.write_text(GENERATOR_CONFIG)
    generator = Path(sys.executable).with_name("openapi-python-client")
    run = subprocess.run(
        [str(generator), "generate", "--path", str(schema), "--output-path", str(folder / "client"),
         "--config", str(config)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert run.returncode == 0, run.stdout + run.stderr
    assert "Warning" not in run.stdout + run.stderr, run.stdout + run.stderr  # every operation generated
    sys.path.insert(0, str(folder / "client"))
    try:
        yield importlib.import_module(PACKAGE)
    finally:
        sys.path.remove(str(folder / "client"))
        for name in [m for m in sys.modules if m == PACKAGE or m.startswith(PACKAGE + ".")]:
            del sys.modules[name]


def api(package: ModuleType, name: str) -> Any:
    """A generated module: an operation (`api.jobs.get_job`) or the models."""
    return importlib.import_module(f"{PACKAGE}.{name}")


def test_a_generated_client_runs_jobs_and_sweeps(
    server: LiveServer, generated: ModuleType, inputs: SimulatedInputs
) -> None:
    models = api(generated, "models")
    types = api(generated, "types")
    jobs = {n: api(generated, f"api.jobs.{n}") for n in ("submit_identify", "submit_diagnose", "get_job",
                                                          "get_job_plot_png", "job_events", "cancel_job",
                                                          "list_jobs")}  # fmt: skip
    sweeps = {n: api(generated, f"api.sweeps.{n}") for n in ("start_sweep", "get_sweep", "list_sweeps",
                                                              "get_sweep_recording_csv")}  # fmt: skip
    client = generated.AuthenticatedClient(base_url=server.url, token=OPERATOR, timeout=httpx.Timeout(60))

    status = api(generated, "api.status.get_status").sync(client=client)
    assert isinstance(status, models.StatusOut)
    assert isinstance(status.bench, models.BenchOut) and status.bench.simulated is True

    def upload(model: type, **options: Any) -> Any:
        recording = io.BytesIO(inputs.recording.read_bytes())
        vehicle = io.BytesIO(inputs.vehicle.read_bytes())
        return model(
            recording=types.File(payload=recording, file_name="rec.csv", mime_type="text/csv"),
            vehicle=types.File(payload=vehicle, file_name="car.toml", mime_type="application/toml"),
            **options,
        )

    submitted = jobs["submit_identify"].sync_detailed(
        client=client, body=upload(models.IdentifyUpload, points=12, solver=models.Solver.EXACT)
    )
    assert submitted.status_code == 201, submitted.content
    job = submitted.parsed
    assert isinstance(job, models.IdentifyJobOut) and job.options.points == 12
    assert submitted.headers["location"] == job.links.self_ == f"/api/v1/jobs/{job.id}"

    diagnosis = jobs["submit_diagnose"].sync_detailed(
        client=client, body=upload(models.DiagnoseUpload, max_steps=1)
    )
    assert diagnosis.status_code == 201, diagnosis.content
    assert isinstance(diagnosis.parsed, models.DiagnoseJobOut) and diagnosis.parsed.kind == "diagnose"
    cancelled = jobs["cancel_job"].sync_detailed(diagnosis.parsed.id, client=client)
    assert cancelled.status_code in (200, 202) and isinstance(cancelled.parsed, models.DiagnoseJobOut)

    def finished() -> Any:
        now = jobs["get_job"].sync(job.id, client=client)
        return now if now.status in (models.JobStatus.SUCCEEDED, models.JobStatus.FAILED) else None

    done = wait_until(finished, 180, f"job {job.id} finished")
    assert isinstance(done, models.IdentifyJobOut) and done.status == models.JobStatus.SUCCEEDED, done.error
    result = done.result
    assert isinstance(result, models.IdentifyResult) and isinstance(result.masses_kg, models.MassesOut)
    (curve,) = result.curves
    assert curve.corner == "single" and len(curve.force_n) == 12
    identified = PiecewiseLinearCurve(np.array(curve.velocity_m_s), np.array(curve.force_n))
    excited = np.percentile(np.abs(inputs.suspension_velocity_m_s), 90)
    grid = np.linspace(-excited, excited, 41)
    truth = inputs.true_curve(grid)
    assert np.max(np.abs(identified.force(grid) - truth)) < 0.1 * np.max(np.abs(truth))
    assert (
        isinstance(result.inspection, models.InspectionOut) and result.inspection.eusama_percent is not None
    )

    plot = jobs["get_job_plot_png"].sync(job.id, client=client)
    assert plot.payload.read().startswith(b"\x89PNG\r\n\x1a\n")
    events = jobs["job_events"].sync_detailed(job.id, client=client).content.decode()  # the stream as text
    first = events.split("\n\n", 1)[0].splitlines()  # an event's fields in any order (the SSE format)
    assert {"id: 1", "event: state"} <= set(first) and "event: succeeded\n" in events

    started = sweeps["start_sweep"].sync_detailed(
        client=client,
        body=models.SweepIn(
            duration_s=2.0, settle_s=0.5, vehicle_toml=format_vehicle(default_quarter_car().known)
        ),
    )
    assert started.status_code == 201, started.content
    sweep = started.parsed
    assert started.headers["location"] == sweep.links.self_
    assert isinstance(sweep.settings, models.SweepSettingsOut) and sweep.settings.duration_s == 2.0

    def sweep_ended() -> Any:
        now = sweeps["get_sweep"].sync(sweep.id, client=client)
        return now if now.status not in (models.SweepStatus.REQUESTED, models.SweepStatus.RUNNING) else None

    ended = wait_until(sweep_ended, 120, f"sweep {sweep.id} ended")
    assert ended.status == models.SweepStatus.COMPLETE and ended.complete, ended.reason
    csv = sweeps["get_sweep_recording_csv"].sync(sweep.id, client=client).payload.read().decode()
    header = next(line for line in csv.splitlines() if not line.startswith("#"))
    assert header == "t,x_s,x_t,x_r" and len(csv.splitlines()) > 2000  # 2.5 s at 1 kHz

    listed = jobs["list_jobs"].sync(client=client)
    kinds = {j.id: type(j).__name__ for j in listed.jobs}
    assert kinds[job.id] == "IdentifyJobOut" and kinds[diagnosis.parsed.id] == "DiagnoseJobOut"
    assert listed.total == 2 and all(j.result is None for j in listed.jobs)
    swept = sweeps["list_sweeps"].sync(client=client)
    assert [s.id for s in swept.sweeps] == [sweep.id] and swept.sweeps[0].settings.settle_s == 0.5
