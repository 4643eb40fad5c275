"""The diagnosis job (the model doctor as a service job): its options as the API takes them, the checks at
submit, and the function the worker runs (estimator.doctor.diagnose, then the Markdown report with its
PNG plots as artefacts)."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

from pydantic import BaseModel, Field

from estimator.identify import IdentifyOptions
from estimator.recording import Recording
from estimator.vehicle import TyreModel, VehicleParameters
from service.jobs.bounds import check_physical_bounds, check_recording_fits
from service.jobs.context import (
    JobContext,
    JobOutcome,
    ProgressReporter,
    finite_json,
)

if TYPE_CHECKING:
    from estimator.doctor.diagnose import DiagnoseProgress

REPORT_FOLDER = "report"


class DiagnoseJobOptions(BaseModel):
    """Options of a diagnosis job (the same as `shockbench diagnose`). Unknown fields are refused by the
    submit endpoint."""

    tyre: TyreModel = Field(TyreModel.MAXWELL, description="tyre of the starting model")
    points: int | None = Field(
        None,
        ge=IdentifyOptions.MIN_POINTS,
        le=IdentifyOptions.MAX_POINTS,
        description="damper curve points (default 30; axle 15 per side; at least "
        f"{IdentifyOptions.MIN_POINTS})",
    )
    max_steps: int = Field(
        6, ge=1, le=8, description="at most this many effects are added (default as `shockbench diagnose`'s)"
    )


def check_diagnose_inputs(options: BaseModel, recording: Recording, vehicle: VehicleParameters) -> None:
    if not isinstance(options, DiagnoseJobOptions):
        raise TypeError("check_diagnose_inputs needs DiagnoseJobOptions")
    check_recording_fits(recording, vehicle)
    check_physical_bounds(recording, vehicle)


def run(job: JobContext) -> JobOutcome:
    """Runs in the worker process: diagnose, then write the report. Raises InterruptedError when
    cancelled."""
    from estimator.doctor.diagnose import DiagnoseOptions, diagnose
    from service.doctor_report import write_report  # matplotlib: loaded in the worker only

    options = job.options_as(DiagnoseJobOptions)
    result = diagnose(
        job.recording,
        job.vehicle,
        DiagnoseOptions(tyre=options.tyre, points=options.points, max_steps=options.max_steps),
        progress=partial(report_progress, job.progress),
        cancel=job.cancel,
    )
    if job.cancel.is_set():
        raise InterruptedError("diagnosis cancelled")
    job.progress.stage("writing the report")
    folder = job.output_dir / REPORT_FOLDER
    write_report(result, folder, title=f"job {job.job_id}")
    artefacts = {path.name: f"{REPORT_FOLDER}/{path.name}" for path in sorted(folder.iterdir())}
    return JobOutcome(finite_json(result.to_json()), artefacts)


def report_progress(reporter: ProgressReporter, p: DiagnoseProgress) -> None:
    """A diagnosis's progress as the job's: each stage as it comes; a DE's generations within one (the final
    refinement's) after it, through the reporter that throttles them and estimates the time left."""
    if p.generation is None or p.generation.generation == 1:
        reporter.stage(f"step {p.step}: {p.stage}")
    if p.generation is not None:
        reporter.generation(p.generation)
