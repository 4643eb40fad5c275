"""Re-analysis runs in the database (issue 33): what `shockbench reanalyse --database` ran (software
version, options, start and end, counts) and one result per recording and analysis, tied to the
recording's sha256 and the run.

Writing a result is idempotent: the unique (run, recording, analysis) constraint makes a second write of the
same result (a task Dask retried after its worker died, a client that wrote before it was cut off) an
INSERT that does nothing (ON CONFLICT DO NOTHING, on SQLite and PostgreSQL alike), so every recording ends
exactly once in a run.

The results a run is compared with (`reanalyse --compare`) are another run's, or the "original" ones: the
succeeded identification jobs stored by the lanes, by the sha256 of the recording they ran on.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import func, select, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.orm import Session

from service.store.database import Database
from service.store.models import (
    JobKind,
    JobRow,
    JobStatus,
    ReanalysisResultRow,
    ReanalysisRunRow,
    SweepRow,
    utcnow,
)

ORIGINAL = "original"
"""The name `--compare` takes for the lanes' own stored results."""


@dataclass(frozen=True)
class Written:
    """One result to store: the recording's sha256, the analysis, its JSON or why it failed, seconds."""

    recording_sha256: str
    analysis: str
    result: dict[str, Any] | None
    reason: str | None
    seconds: float


@dataclass(frozen=True)
class RunRecord:
    id: int
    software_version: str
    options: dict[str, Any]
    started_at: datetime
    finished_at: datetime | None
    recordings: int
    succeeded: int
    failed: int


def _insert(session: Session) -> Any:
    """The dialect's INSERT that supports ON CONFLICT DO NOTHING."""
    name = session.get_bind().dialect.name
    if name == "postgresql":
        return postgresql.insert(ReanalysisResultRow)
    if name == "sqlite":
        return sqlite.insert(ReanalysisResultRow)
    raise ValueError(f"re-analysis runs need SQLite or PostgreSQL, not {name}")


class RunStore:
    """The runs of a database; each call is one short transaction."""

    def __init__(self, database: Database) -> None:
        self.db = database

    def begin(self, software_version: str, options: dict[str, Any], recordings: int) -> int:
        """A new run, started now; its id."""
        with self.db.transaction() as session:
            row = ReanalysisRunRow(
                software_version=software_version,
                options=options,
                recordings=recordings,
                succeeded=0,
                failed=0,
            )
            session.add(row)
            session.flush()
            return row.id

    def record(
        self,
        run_id: int,
        recording_sha256: str,
        analysis: str,
        result: dict[str, Any] | None,
        reason: str | None,
        seconds: float,
    ) -> bool:
        """Store one result of the run; False when it was stored already (nothing written)."""
        return self.record_many(run_id, [Written(recording_sha256, analysis, result, reason, seconds)]) == 1

    def record_many(self, run_id: int, written: Sequence[Written]) -> int:
        """Store results of the run in one transaction and one INSERT (a batch's); how many were new (the
        others were stored already and are left as they are). One multi-row statement, not one a result:
        the client stores every batch on the cores the workers compute on."""
        if not written:
            return 0
        now = utcnow()
        rows = [
            {
                "run_id": run_id,
                "recording_sha256": w.recording_sha256,
                "analysis": w.analysis,
                "result": w.result,
                "reason": w.reason,
                "seconds": w.seconds,
                "created_at": now,
            }
            for w in written
        ]
        with self.db.transaction() as session:
            statement = (
                _insert(session)
                .values(rows)
                .on_conflict_do_nothing(index_elements=["run_id", "recording_sha256", "analysis"])
                .returning(ReanalysisResultRow.id)
            )
            return len(session.execute(statement).all())  # a row comes back for each new result only

    def finish(self, run_id: int) -> RunRecord:
        """The run ended now, its counts taken from its stored results (a recording succeeded when every
        analysis of it did)."""
        with self.db.transaction() as session:
            per_recording = (
                select(
                    ReanalysisResultRow.recording_sha256,
                    func.max(func.coalesce(func.length(ReanalysisResultRow.reason), 0)).label("failed"),
                )
                .where(ReanalysisResultRow.run_id == run_id)
                .group_by(ReanalysisResultRow.recording_sha256)
            ).subquery()
            failed = session.scalar(select(func.count()).where(per_recording.c.failed > 0)) or 0
            total = session.scalar(select(func.count()).select_from(per_recording)) or 0
            session.execute(
                update(ReanalysisRunRow)
                .where(ReanalysisRunRow.id == run_id)
                .values(finished_at=utcnow(), succeeded=total - failed, failed=failed)
            )
        found = self.get(run_id)
        assert found is not None
        return found

    def get(self, run_id: int) -> RunRecord | None:
        with self.db.sessions() as session:
            row = session.get(ReanalysisRunRow, run_id)
            return _record(row) if row is not None else None

    def runs(self) -> list[RunRecord]:
        with self.db.sessions() as session:
            return [
                _record(row)
                for row in session.scalars(select(ReanalysisRunRow).order_by(ReanalysisRunRow.id))
            ]

    def results(self, run_id: int, analysis: str = "identify") -> dict[str, dict[str, Any] | None]:
        """recording sha256 -> the run's result (None when it failed)."""
        query = select(ReanalysisResultRow.recording_sha256, ReanalysisResultRow.result).where(
            ReanalysisResultRow.run_id == run_id, ReanalysisResultRow.analysis == analysis
        )
        with self.db.sessions() as session:
            return {key: value for key, value in session.execute(query)}

    def count(self, run_id: int) -> int:
        """Results stored for the run (every analysis)."""
        query = select(func.count()).where(ReanalysisResultRow.run_id == run_id)
        with self.db.sessions() as session:
            return int(session.scalar(query) or 0)

    def original_results(self) -> dict[str, dict[str, Any] | None]:
        """recording sha256 -> the newest succeeded identification job's result on it (the lanes' own, with
        their verdict): by the job's recording hash, else its sweep's."""
        query = (
            select(JobRow.recording_sha256, SweepRow.recording_sha256, JobRow.result)
            .outerjoin(SweepRow, SweepRow.id == JobRow.sweep_id)
            .where(JobRow.kind == JobKind.IDENTIFY.value, JobRow.status == JobStatus.SUCCEEDED.value)
            .order_by(JobRow.finished_at, JobRow.id)
        )
        found: dict[str, dict[str, Any] | None] = {}
        with self.db.sessions() as session:
            for job_hash, sweep_hash, result in session.execute(query):
                key = job_hash or sweep_hash
                if key is not None:
                    found[key] = result
        return found


def _record(row: ReanalysisRunRow) -> RunRecord:
    return RunRecord(
        id=row.id,
        software_version=row.software_version,
        options=dict(row.options or {}),
        started_at=row.started_at,
        finished_at=row.finished_at,
        recordings=row.recordings,
        succeeded=row.succeeded,
        failed=row.failed,
    )
