"""The validation job (`shockbench validate` as a service job): an identified model (JSON) simulated from
another recording's plate motion; the gap to the measured body and wheel motion (estimator.validation)."""

from __future__ import annotations

from pydantic import BaseModel

from estimator.output_error import IdentifiedModel
from estimator.recording import Recording
from service.jobs.context import Companion, InputError, JobContext, JobOutcome, finite_json


class ValidateJobOptions(BaseModel):
    """A validation takes no options: the model file says everything (an axle model states its track_m, a
    diagnosis's model its effects). Unknown fields are refused by the submit endpoint."""


def check_validate_inputs(options: BaseModel, recording: Recording, model: Companion) -> None:
    if not isinstance(options, ValidateJobOptions) or not isinstance(model, IdentifiedModel):
        raise TypeError("check_validate_inputs needs ValidateJobOptions and an IdentifiedModel")
    from estimator.validation import check_model_fits

    try:
        check_model_fits(model, recording)
    except ValueError as exc:
        raise InputError("model", str(exc)) from None


def run(job: JobContext) -> JobOutcome:
    """Runs in the worker process."""
    from estimator.validation import validate

    if not isinstance(job.companion, IdentifiedModel):
        raise TypeError("a validation job needs the identified model")
    job.progress.stage("simulating the model")
    result = validate(job.companion, job.recording)
    return JobOutcome(finite_json(result.to_json()))
