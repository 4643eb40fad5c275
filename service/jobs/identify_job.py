"""The identification job: its options as the API takes them, the checks at submit, and the function the
worker runs (estimator.identify.identify, then the curve plots as PNG and SVG artefacts)."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, BeforeValidator, Field

from estimator.identify import IdentifyOptions, Solver
from estimator.recording import Recording
from estimator.solvers.de_settings import DESettings
from estimator.vehicle import ModelKind, TyreModel, VehicleParameters
from service.declarations import pydantic_field
from service.jobs.bounds import check_physical_bounds, check_recording_fits
from service.jobs.context import (
    InputError,
    JobContext,
    JobOutcome,
    finite_json,
)

PLOT_FORMATS = ("png", "svg")


def _true_or_false(value: Any) -> Any:
    """Only true/false (any case) for a flag: pydantic's lax booleans take 0, 1, "yes", "off" ..., and a
    client that sends output_error=0 meaning "0 seconds" or "no limit" should hear that it was not
    understood, not find the flag silently off."""
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.strip().lower() in ("true", "false"):
        return value.strip().lower() == "true"
    raise ValueError("must be true or false")


Flag = Annotated[bool, BeforeValidator(_true_or_false)]
"""A boolean option that accepts only true or false (JSON booleans, or the words in a form)."""


class IdentifyJobOptions(BaseModel):
    """Options of an identification job (the same as `shockbench identify`). Unknown fields are refused
    by the submit endpoint. generations and seed are DESettings' (estimator.solvers.de_settings)."""

    model: ModelKind | None = Field(
        None, description="quarter-car or axle; when given it must be what the vehicle file says"
    )
    tyre: TyreModel = Field(TyreModel.MAXWELL, description="tyre model")
    solver: Solver = Field(Solver.EXACT, description="exact (default) or de (differential evolution)")
    points: int | None = Field(
        None,
        ge=IdentifyOptions.MIN_POINTS,
        le=IdentifyOptions.MAX_POINTS,
        description="damper curve points (default 20; axle 10 per side); the tanh fit needs at least "
        f"{IdentifyOptions.MIN_POINTS}",
    )
    generations: int = pydantic_field(DESettings, "generations")
    seed: int = pydantic_field(DESettings, "seed")
    refine: Flag = Field(
        False,
        description="refine the curve by DE on the output-error gap (true|false): a model that predicts "
        "the motion better, whose curve is no truer a damper curve and has no 95% band",
    )
    output_error: Flag = Field(
        True,
        description="simulate the identified model for the output-error gap (off saves seconds; true|false)",
    )

    def identify_options(self) -> IdentifyOptions:
        return IdentifyOptions(
            tyre=self.tyre,
            points=self.points,
            solver=self.solver,
            de=DESettings(generations=self.generations, seed=self.seed),
            output_error=self.output_error or self.refine,
            refine_output_error=self.refine,
        )


def check_identify_inputs(options: BaseModel, recording: Recording, vehicle: VehicleParameters) -> None:
    if not isinstance(options, IdentifyJobOptions):
        raise TypeError("check_identify_inputs needs IdentifyJobOptions")
    if options.model is not None and options.model is not vehicle.model:
        raise InputError(
            "model", f"model is {options.model.value} but the vehicle file says {vehicle.model.value}"
        )
    check_recording_fits(recording, vehicle)
    check_physical_bounds(recording, vehicle)


def run(job: JobContext) -> JobOutcome:
    """Runs in the worker process: identify, then plot. Raises InterruptedError when cancelled."""
    from estimator.identify import identify
    from service.plots import curve_plot_bytes  # matplotlib: loaded in the worker only

    options = IdentifyJobOptions.model_validate(job.options)
    job.progress.stage("differential evolution" if options.solver is Solver.DE else "identifying")
    result = identify(
        job.recording,
        job.vehicle,
        options.identify_options(),
        progress=job.progress.generation,
        cancel=job.cancel,
    )
    if job.cancel.is_set():
        raise InterruptedError("identification cancelled")
    job.progress.stage("plotting")
    artefacts = {}
    for fmt, content in curve_plot_bytes(result, PLOT_FORMATS).items():
        name = f"plot.{fmt}"
        (job.output_dir / name).write_bytes(content)
        artefacts[name] = name
    return JobOutcome(finite_json(result.to_json()), artefacts)
