"""Where a report's input comes from.

- The service (`stored_input`): a sweep's row (vehicle id, tyre pressure and operator's name as recorded
  when it was started, its lane, bench and date), its newest succeeded identification and that result's
  link in the lane's hash chain, its newest succeeded diagnosis when the model doctor was run, and its
  recording where acquisition wrote it (gone after retention: the plots over time are left out, and the
  sheet says why).
- The command line (`read_result_file`, `with_recording`): RESULT.json as `shockbench identify --json`
  prints it, or a job as `GET /api/v1/jobs/{id}` answers it (the operator page's "Result JSON"), and
  optionally the recording, whose metadata name the bench, operator and start time.

Blocking (database, files): the service calls these in a thread.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import Any

from sqlalchemy import func, select

from estimator.errors import UserError, one_line
from estimator.recording import Recording
from service.report.content import ChainRecord, RecordedTest, ReportInput, ReportInputError, identify_result
from service.store.database import Database
from service.store.jobs import JobRecord
from service.store.models import JobKind, JobRow, JobStatus, ResultChainRow
from service.store.sweeps import SweepRecord, SweepStore

# ---- the service -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class StoredTest:
    """A sweep with its newest succeeded identification (None: none yet) and diagnosis (None: not run)."""

    sweep: SweepRecord
    identification: JobRecord | None
    chain: ChainRecord | None
    diagnosis: JobRecord | None


def _newest_succeeded(sweep_id: int, kind: JobKind) -> Any:
    return select(func.max(JobRow.id)).where(
        JobRow.sweep_id == sweep_id, JobRow.kind == kind.value, JobRow.status == JobStatus.SUCCEEDED.value
    )


def stored_test(database: Database, sweep_id: int) -> StoredTest | None:
    """The sweep `sweep_id` and what its report shows from the database; None when there is no such sweep."""
    sweep = SweepStore(database).get(sweep_id)
    if sweep is None:
        return None
    with database.sessions() as session:
        found: dict[JobKind, JobRecord | None] = {}
        for kind in (JobKind.IDENTIFY, JobKind.DIAGNOSE):
            job_id = session.scalar(_newest_succeeded(sweep_id, kind))
            row = session.get(JobRow, job_id) if job_id is not None else None
            found[kind] = JobRecord.of(row) if row is not None else None
        chain = None
        identification = found[JobKind.IDENTIFY]
        if identification is not None:
            link = session.scalars(
                select(ResultChainRow).where(ResultChainRow.job_id == identification.id).limit(1)
            ).first()
            if link is not None:
                chain = ChainRecord(link.lane, link.sequence, link.hash, identification.id)
    return StoredTest(sweep, identification, chain, found[JobKind.DIAGNOSE])


def _sweep_recording(sweep: SweepRecord) -> tuple[Recording | None, str]:
    """The sweep's recording for the plots, or None and why not."""
    from daq.formats.recording_file import load_recording_file

    path = Path(sweep.recording_path) if sweep.recording_path else None
    if path is None or not path.is_file():
        return None, "the sweep's recording is no longer stored (retention), so they are left out"
    try:
        return load_recording_file(path, allow_gaps=True).recording, ""
    except (UserError, OSError) as exc:
        return None, f"the sweep's recording cannot be read ({one_line(exc).replace(str(path), path.name)})"


def stored_input(test: StoredTest, software: str = "") -> ReportInput:
    """The report's input for a stored test that has an identification."""
    assert test.identification is not None and test.identification.result is not None
    sweep, job = test.sweep, test.identification
    recording, why = _sweep_recording(sweep)
    diagnosis = test.diagnosis
    return ReportInput(
        result=job.result,
        test=RecordedTest(
            vehicle_id=sweep.settings.get("vehicle_id"),
            operator=sweep.settings.get("operator_name"),
            lane=sweep.lane,
            bench=sweep.bench,
            date=sweep.started_at or sweep.created_at,
            tyre_pressure_bar=sweep.settings.get("tyre_pressure_bar"),
            sweep_id=sweep.id,
            job_id=job.id,
        ),
        chain=test.chain,
        chain_note="its link is missing from the lane's chain (`shockbench verify` names the problem)",
        diagnosis=diagnosis.result if diagnosis is not None else None,
        diagnosis_job_id=diagnosis.id if diagnosis is not None else None,
        diagnosis_note="not run on this sweep",
        recording=recording,
        recording_note=why,
        software=software,
    )


# ---- the command line --------------------------------------------------------------------------------------


def _decoded(path: Path) -> object:
    if not path.is_file():
        raise ReportInputError(f"{path}: no such file" if not path.exists() else f"{path}: not a file")
    try:
        return json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise ReportInputError(f"{path}: not UTF-8 text, so not a result JSON") from None
    except json.JSONDecodeError as exc:
        raise ReportInputError(f"{path}: not JSON ({exc})") from None
    except RecursionError:
        raise ReportInputError(f"{path}: not a result JSON (nested too deeply)") from None


def _whole(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def read_result_file(path: Path | str, software: str = "") -> ReportInput:
    """RESULT.json: an identification's result, or an identify job as the API answers it (whose lane, job
    and sweep ids the report names). ReportInputError, one line naming the file, otherwise."""
    path = Path(path)
    raw = _decoded(path)
    test = RecordedTest()
    if isinstance(raw, dict) and "kind" in raw and "result" in raw:  # GET /jobs/{id}
        job_id = _whole(raw.get("id"))
        named = f"job {job_id}" if job_id is not None else "the job"
        if raw["kind"] != JobKind.IDENTIFY.value:
            raise ReportInputError(
                f"{path}: {named} is a {raw['kind']!s:.20} job; a report needs an identification"
            )
        if raw["result"] is None:
            raise ReportInputError(f"{path}: {named} has no result ({raw.get('status')!s:.20})")
        lane = raw.get("lane")
        test = RecordedTest(
            lane=lane if isinstance(lane, str) else None,
            sweep_id=_whole(raw.get("sweep_id")),
            job_id=job_id,
        )
        raw = raw["result"]
    try:
        identify_result(raw)
    except ReportInputError as exc:
        raise ReportInputError(f"{path}: {exc}") from None
    assert isinstance(raw, dict)
    return ReportInput(result=raw, test=test, software=software)


def _recorded_time(text: str | None) -> datetime | str | None:
    if not text:
        return None
    try:
        return datetime.fromisoformat(text)
    except ValueError:
        return text


def with_recording(source: ReportInput, recording: Recording, path: Path | str) -> ReportInput:
    """`source` with the recording for its plots, and the bench, operator and start time the recording's
    metadata name (ReportInputError when the recording is not of the result's vehicle kind)."""
    axle = "left" in source.result.get("inspection", {})
    if recording.is_axle != axle:
        kinds = ("an axle", "a quarter car")
        raise ReportInputError(
            f"{path}: the recording is {kinds[not recording.is_axle]}'s, the result {kinds[not axle]}'s"
        )
    if not axle:
        try:
            recording.require(("x_s", "x_t", "x_r"))
        except UserError as exc:
            raise ReportInputError(f"{path}: {one_line(exc)}") from None
    meta = recording.metadata
    test = source.test
    test = replace(
        test,
        operator=test.operator or meta.get("operator") or None,
        bench=test.bench or meta.get("bench") or None,
        date=_recorded_time(meta.get("start_time")) or test.date,
    )
    return replace(source, test=test, recording=recording, recording_note="")
