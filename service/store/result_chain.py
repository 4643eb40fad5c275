"""Tamper-evident results: every succeeded job's result carries a content hash chained to its lane's
previous result, and `verify_chain` walks the chains and names the first record that no longer matches.

The hash of a link (`link_hash`) is the sha256, in lowercase hex, of the UTF-8 bytes of the canonical JSON
(keys sorted, separators "," and ":" without spaces, non-ASCII characters as they are, NaN refused) of

    {"previous_hash": the lane's previous link's hash (64 zeros for the lane's first link),
     "job_id": the job's id, "lane": the job's lane, "kind": identify / diagnose / validate,
     "options": the job's options, "result": its stored result,
     "finished_at": when it succeeded, ISO 8601 in UTC (datetime.isoformat: 2026-11-25T18:04:55.123456+00:00)}

with the values as the database gives them back; "job_id" is the id the job had in the store where it ran
(a job synced from a lane's local store to the central database keeps it there as `origin_id`, so its link
verifies there too). Changing a stored result, its options or kind, moving it to another lane, or removing a
link changes a hash or breaks the chain; rewriting every later link to hide a change needs write access to
the whole chain, and the newest hash, exported daily, pins it.

Appending (`append_link`) happens in the transaction that marks the job succeeded (JobStore.succeed), so no
result is stored without its link. Appends are serialized per lane: on PostgreSQL by a transaction-scoped
advisory lock keyed by the lane (two instances of one lane never chain to the same previous link; the
unique (lane, previous_hash) constraint would refuse a fork anyway); SQLite has one writer at a time, and
the job's UPDATE before the append already holds its write lock.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import BigInteger, exists, func, literal, select
from sqlalchemy.orm import Session

from service.store.database import Database
from service.store.models import JobRow, JobStatus, ResultChainRow

GENESIS = "0" * 64
"""previous_hash of a lane's first link."""
LOCK_NAMESPACE = b"shockbench result chain "


def canonical_json(record: dict[str, Any]) -> bytes:
    """Sorted keys, no spaces, UTF-8; NaN and infinities refused (stored results hold none)."""
    text = json.dumps(record, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)
    return text.encode("utf-8")


def link_hash(
    previous_hash: str,
    job_id: int,
    lane: str,
    kind: str,
    options: dict[str, Any] | None,
    result: dict[str, Any] | None,
    finished_at: datetime | None,
) -> str:
    """The link's hash (module docstring): sha256 hex of the canonical JSON of the job's stored record."""
    record = {
        "previous_hash": previous_hash,
        "job_id": job_id,
        "lane": lane,
        "kind": kind,
        "options": options,
        "result": result,
        "finished_at": finished_at.astimezone(UTC).isoformat() if finished_at is not None else None,
    }
    return hashlib.sha256(canonical_json(record)).hexdigest()


def job_hash(previous_hash: str, job: JobRow) -> str:
    """The link hash of a stored job: `job_id` is the id it has where it ran, its `origin_id` when it was
    synced from a lane's local store to the central database (service.store.sync), else its own id."""
    job_id = job.origin_id if job.origin_id is not None else job.id
    return link_hash(previous_hash, job_id, job.lane, job.kind, job.options, job.result, job.finished_at)


def lane_lock_key(lane: str) -> int:
    """The lane's PostgreSQL advisory lock: a signed 64-bit number from the sha256 of the lane's name."""
    digest = hashlib.sha256(LOCK_NAMESPACE + lane.encode("utf-8")).digest()
    return int.from_bytes(digest[:8], "big", signed=True)


def locked_head(session: Session, lane: str) -> str:
    """The hash of the lane's newest link (GENESIS for none), the lane's chain locked for the rest of
    `session`'s transaction on PostgreSQL (SQLite has a single writer): what the next link must follow."""
    if session.get_bind().dialect.name == "postgresql":
        session.execute(select(func.pg_advisory_xact_lock(literal(lane_lock_key(lane), BigInteger))))
    newest = select(ResultChainRow.hash).where(ResultChainRow.lane == lane)
    return session.scalar(newest.order_by(ResultChainRow.id.desc()).limit(1)) or GENESIS


def append_link(session: Session, job_id: int) -> str:
    """Chain the job's stored result to its lane's newest link, in `session`'s transaction; its hash."""
    job = session.execute(select(JobRow).where(JobRow.id == job_id)).scalar_one()  # as verify reads it
    previous = locked_head(session, job.lane)
    digest = job_hash(previous, job)
    session.add(ResultChainRow(lane=job.lane, job_id=job.id, previous_hash=previous, hash=digest))
    session.flush()
    return digest


@dataclass(frozen=True)
class ChainReport:
    results: int
    """Links verified (up to the first problem)."""
    lanes: int
    """Lanes walked."""
    problem: str | None = None
    """The first altered record, in one line; None when every chain holds."""


BATCH = 200
"""Links read per round trip while walking (results can be tens of kB each)."""


def _unlinked(session: Session, lane: str) -> list[int]:
    """Succeeded jobs of the lane without a link, in the order they finished."""
    linked = exists().where(ResultChainRow.job_id == JobRow.id)
    query = (
        select(JobRow.id)
        .where(JobRow.lane == lane, JobRow.status == JobStatus.SUCCEEDED.value, ~linked)
        .order_by(JobRow.finished_at, JobRow.id)
    )
    return list(session.scalars(query).all())


def _walk_lane(session: Session, lane: str) -> tuple[int, str | None]:
    """(links verified, the first problem or None) of one lane's chain."""
    where = f"lane {lane!r}"
    unlinked = _unlinked(session, lane)
    missing = f"{where}: job {{}}'s result is not in the chain (its link was removed)"
    query = (
        select(ResultChainRow, JobRow)
        .outerjoin(JobRow, JobRow.id == ResultChainRow.job_id)
        .where(ResultChainRow.lane == lane)
        .order_by(ResultChainRow.id)
        .execution_options(yield_per=BATCH)
    )
    expected, verified = GENESIS, 0
    for link, job in session.execute(query):
        if link.previous_hash != expected:
            if unlinked:
                return verified, missing.format(unlinked[0])
            return verified, (
                f"{where}: the chain breaks before job {link.job_id}'s link {link.id} (a link before it was "
                "removed or altered)"
            )
        if job is None:
            return verified, f"{where}: job {link.job_id} of chain link {link.id} was removed from the jobs"
        if job_hash(link.previous_hash, job) != link.hash:
            return verified, (
                f"{where}: job {job.id}'s stored result was altered (it no longer matches its hash, "
                f"chain link {link.id})"
            )
        if job.status != JobStatus.SUCCEEDED.value:
            return verified, f"{where}: job {job.id} succeeded but is now stored as {job.status}"
        expected, verified = link.hash, verified + 1
    if unlinked:
        return verified, missing.format(unlinked[0])
    return verified, None


def lanes_with_results(session: Session) -> list[str]:
    """Every lane that has a link or a succeeded job, sorted."""
    chained = set(session.scalars(select(ResultChainRow.lane).distinct()).all())
    succeeded = select(JobRow.lane).where(JobRow.status == JobStatus.SUCCEEDED.value).distinct()
    return sorted(chained | set(session.scalars(succeeded).all()))


def verify_chain(database: Database, lane: str | None = None) -> ChainReport:
    """Walk every lane's chain (or only `lane`'s), recomputing each hash; stop at the first problem."""
    results = 0
    with database.sessions() as session:
        lanes = lanes_with_results(session)
        if lane is not None:
            lanes = [name for name in lanes if name == lane]
        for name in lanes:
            verified, problem = _walk_lane(session, name)
            results += verified
            if problem is not None:
                return ChainReport(results, len(lanes), problem)
    return ChainReport(results, len(lanes))
