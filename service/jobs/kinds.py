"""The kinds of job the worker runs, as a small registry: adding a kind is one entry in KINDS.

An entry says how the API validates the kind's options (a pydantic model, also the multipart form the
submit endpoint documents), which cross-checks of options, recording and vehicle run at submit (so a job
that cannot run is refused with 422 before it is queued), and which function the worker calls
("module:function", imported in the worker process only, so the service never loads the estimator's
heavy parts or matplotlib).

Every kind takes a recording and one more file (`companion`, service.jobs.inputs): the vehicle file, or
for a validation the identified model (JSON). The worker function receives a JobContext and returns a
JobOutcome (service.jobs.context).

Three kinds: identify (`POST /jobs`), diagnose, the model doctor (`POST /diagnoses`), and validate, an
identified model against another recording (`POST /validations`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel

from estimator.recording import Recording
from service.jobs.context import InputError
from service.jobs.diagnose_job import DiagnoseJobOptions, check_diagnose_inputs
from service.jobs.identify_job import IdentifyJobOptions, check_identify_inputs
from service.jobs.inputs import MODEL_FILE, VEHICLE_FILE, CompanionFile
from service.jobs.validate_job import ValidateJobOptions, check_validate_inputs
from service.store.models import JobKind

__all__ = ["KINDS", "InputError", "JobKindSpec", "kind_spec"]


@dataclass(frozen=True)
class JobKindSpec:
    name: str
    summary: str
    submit_path: str
    """Path (under /api/v1) that accepts an upload of this kind."""
    options_model: type[BaseModel]
    check: Callable[[BaseModel, Recording, Any], None]
    """Raises InputError(field, message) when options, recording and the companion file (as read) do not
    go together."""
    runner: str
    """'module:function' run in the worker: function(JobContext) -> JobOutcome."""
    preload: tuple[str, ...] = ()
    """Modules the worker imports at its start, so that the first job does not wait for them."""
    companion: CompanionFile = VEHICLE_FILE
    """The file uploaded beside the recording."""


KINDS: dict[str, JobKindSpec] = {
    JobKind.IDENTIFY.value: JobKindSpec(
        name=JobKind.IDENTIFY.value,
        summary="Identify the damper curve(s), masses, tyre damping and inspection figures",
        submit_path="/jobs",
        options_model=IdentifyJobOptions,
        check=check_identify_inputs,
        runner="service.jobs.identify_job:run",
        preload=("estimator.identify", "service.plots"),
    ),
    JobKind.DIAGNOSE.value: JobKindSpec(
        name=JobKind.DIAGNOSE.value,
        summary="Diagnose the model: where the identified model and the measurement disagree, which missing "
        "effect explains it, the gap before and after adding it (the model doctor)",
        submit_path="/diagnoses",
        options_model=DiagnoseJobOptions,
        check=check_diagnose_inputs,
        runner="service.jobs.diagnose_job:run",
        preload=("estimator.doctor.diagnose", "service.doctor_report"),
    ),
    JobKind.VALIDATE.value: JobKindSpec(
        name=JobKind.VALIDATE.value,
        summary="Validate an identified model on another recording of the same vehicle: simulated from its "
        "plate, the gap to its measured body and wheel motion",
        submit_path="/validations",
        options_model=ValidateJobOptions,
        check=check_validate_inputs,
        runner="service.jobs.validate_job:run",
        preload=("estimator.validation",),
        companion=MODEL_FILE,
    ),
}


def kind_spec(name: str) -> JobKindSpec:
    try:
        return KINDS[name]
    except KeyError:
        raise ValueError(f"unknown job kind {name!r} (known: {', '.join(KINDS)})") from None
