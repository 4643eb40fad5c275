"""Tamper-evident results: every succeeded job's result, with what it means (the vehicle, sweep, recording
and thresholds it belongs to), carries a hash chained to its lane's previous result, and `verify_chain`
walks the chains and names the first record that no longer matches.

Canonical JSON below means the UTF-8 bytes of the JSON text with keys sorted, separators "," and ":" without
spaces, non-ASCII characters as they are, NaN refused; sha256 is in lowercase hex. A link's hash depends on
its format, the link's `link_version`:

Version 2 (every link appended since revision 0006). The link records, in its `covered` column, for each
covered field of the job the sha256 of the canonical JSON of the field's value, and its hash is

    sha256(canonical JSON of {"link_version": 2, "previous_hash": the lane's previous link's hash (64
           zeros for the lane's first link), "covered": {field: sha256 of its value's canonical JSON}})

over exactly these fields, with the values as the database gives them back:

    "job_id":          the id the job has where it ran (its `origin_id` on the central database, where a
                       job synced from a lane's local store keeps it: service.store.sync)
    "lane", "kind", "options", "result":  the job's columns (kind: identify / diagnose / validate)
    "finished_at":     when it succeeded, ISO 8601 in UTC (datetime.isoformat:
                       2026-11-25T18:04:55.123456+00:00)
    "recording_sha256":        the job's: sha256 of the recording file's bytes when it was submitted
    "sweep_uid":               the global identity (`uid`) of the sweep it ran on (`sweep_id`): the same
                               on the lane and the central database, where the sweep's integer id differs
    "vehicle_id":              that sweep's settings["vehicle_id"], as stored
    "sweep_recording_sha256":  that sweep's `recording_sha256` (sha256 of its recording file when it ended)
    "thresholds_version":      result["verdict"]["thresholds_version"]: which verdict thresholds judged it
                               (estimator.verdict.VerdictThresholds.version, stored by
                               service.api.results.verdict_of)

A field without a value (no sweep, no verdict, a hash never computed) is null. So `verify` tells which field
changed: it compares the digests the link records with the record's now (the link's hash guards the
digests themselves). Changing a stored result, its options, kind, lane or finish time, its sweep's vehicle
id, the sweep it points at, a recording hash or the thresholds version fails, naming the job and the field.

Version 1 (links written before revision 0006, which keep verifying by it): the sha256 of the canonical
JSON of {"previous_hash", "job_id", "lane", "kind", "options", "result", "finished_at"}, the values as
above (`link_hash`).

A recording kept in the database (service.store.recordings, issue 33) is named by that same sha256 of its
file's bytes: `verify_chain` also recomputes it from the stored bytes, so a stored recording changed after
its sweep's results were chained fails too, naming the recording.

Removing a link breaks the chain; rewriting every later link to hide a change needs write access to the
whole chain. Its end is pinned by the lane's checkpoints of its head (service.store.chain_anchor, which also
states the threat model): `verify` compares the chain with the heads log and the central checkpoints.

Appending (`append_link`) happens in the transaction that marks the job succeeded (JobStore.succeed), so no
result is stored without its link. Appends are serialized per lane: on PostgreSQL by a transaction-scoped
advisory lock keyed by the lane (two instances of one lane never chain to the same previous link; the
unique (lane, previous_hash) constraint would refuse a fork anyway); SQLite has one writer at a time, and
the job's UPDATE before the append already holds its write lock.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sqlalchemy import BigInteger, exists, func, literal, select
from sqlalchemy.orm import Session

from service.store.chain_anchor import Checkpoint, Checkpoints, Head, stored_checkpoints
from service.store.database import Database
from service.store.models import JobRow, JobStatus, ResultChainRow, SweepRow
from service.store.recordings import altered_recordings

GENESIS = "0" * 64
"""previous_hash of a lane's first link."""
LINK_VERSION = 2
"""The format of the links appended now (module docstring)."""
LOCK_NAMESPACE = b"shockbench result chain "


def canonical_json(record: Any) -> bytes:
    """Sorted keys, no spaces, UTF-8; NaN and infinities refused (stored results hold none)."""
    text = json.dumps(record, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)
    return text.encode("utf-8")


def _sha256(record: Any) -> str:
    return hashlib.sha256(canonical_json(record)).hexdigest()


def _iso(moment: datetime | None) -> str | None:
    return moment.astimezone(UTC).isoformat() if moment is not None else None


def link_hash(
    previous_hash: str,
    job_id: int,
    lane: str,
    kind: str,
    options: dict[str, Any] | None,
    result: dict[str, Any] | None,
    finished_at: datetime | None,
) -> str:
    """A version 1 link's hash (module docstring); revision 0003 chained the older results by it."""
    record = {
        "previous_hash": previous_hash,
        "job_id": job_id,
        "lane": lane,
        "kind": kind,
        "options": options,
        "result": result,
        "finished_at": _iso(finished_at),
    }
    return _sha256(record)


def chained_job_id(job: JobRow) -> int:
    """The id a job's link hashes: its `origin_id` when it was synced from a lane's local store to the
    central database (service.store.sync), else its own id."""
    return job.origin_id if job.origin_id is not None else job.id


def job_hash(previous_hash: str, job: JobRow) -> str:
    """The version 1 link hash of a stored job."""
    return link_hash(
        previous_hash, chained_job_id(job), job.lane, job.kind, job.options, job.result, job.finished_at
    )


def covered_fields(job: JobRow, sweep: SweepRow | None) -> dict[str, Any]:
    """The fields a version 2 link covers, as stored now (module docstring); `sweep`: the job's sweep."""
    settings = sweep.settings if sweep is not None and isinstance(sweep.settings, dict) else {}
    verdict = job.result.get("verdict") if isinstance(job.result, dict) else None
    return {
        "job_id": chained_job_id(job),
        "lane": job.lane,
        "kind": job.kind,
        "options": job.options,
        "result": job.result,
        "finished_at": _iso(job.finished_at),
        "recording_sha256": job.recording_sha256,
        "sweep_uid": sweep.uid if sweep is not None else None,
        "vehicle_id": settings.get("vehicle_id"),
        "sweep_recording_sha256": sweep.recording_sha256 if sweep is not None else None,
        "thresholds_version": verdict.get("thresholds_version") if isinstance(verdict, dict) else None,
    }


def covered_digests(job: JobRow, sweep: SweepRow | None) -> dict[str, str]:
    """Covered field -> sha256 of its value's canonical JSON: what a version 2 link records."""
    return {name: _sha256(value) for name, value in covered_fields(job, sweep).items()}


def link_hash_v2(previous_hash: str, covered: dict[str, str]) -> str:
    """A version 2 link's hash over the digests of its covered fields (module docstring)."""
    return _sha256({"link_version": 2, "previous_hash": previous_hash, "covered": covered})


def lane_lock_key(lane: str) -> int:
    """The lane's PostgreSQL advisory lock: a signed 64-bit number from the sha256 of the lane's name."""
    digest = hashlib.sha256(LOCK_NAMESPACE + lane.encode("utf-8")).digest()
    return int.from_bytes(digest[:8], "big", signed=True)


@dataclass(frozen=True)
class Tip:
    """A lane's newest link as the next one must follow it."""

    sequence: int
    """Its place in the lane's chain (0: the lane has no link yet)."""
    hash: str
    """Its hash (GENESIS for none)."""


def locked_head(session: Session, lane: str) -> Tip:
    """The lane's newest link, the lane's chain locked for the rest of `session`'s transaction on
    PostgreSQL (SQLite has a single writer): what the next link must follow."""
    if session.get_bind().dialect.name == "postgresql":
        session.execute(select(func.pg_advisory_xact_lock(literal(lane_lock_key(lane), BigInteger))))
    newest = select(ResultChainRow.sequence, ResultChainRow.hash).where(ResultChainRow.lane == lane)
    found = session.execute(newest.order_by(ResultChainRow.id.desc()).limit(1)).first()
    if found is None:
        return Tip(0, GENESIS)
    sequence = found.sequence
    if sequence is None:  # not numbered (cannot happen after revision 0006's numbering): count
        count = select(func.count()).select_from(ResultChainRow).where(ResultChainRow.lane == lane)
        sequence = int(session.scalar(count) or 0)
    return Tip(sequence, found.hash)


def append_link(session: Session, job_id: int) -> Head:
    """Chain the job's stored result (version 2) to its lane's newest link, in `session`'s transaction;
    the lane's new head."""
    job = session.execute(select(JobRow).where(JobRow.id == job_id)).scalar_one()  # as verify reads it
    sweep = session.get(SweepRow, job.sweep_id) if job.sweep_id is not None else None
    tip = locked_head(session, job.lane)
    covered = covered_digests(job, sweep)
    digest = link_hash_v2(tip.hash, covered)
    session.add(
        ResultChainRow(
            lane=job.lane,
            job_id=job.id,
            previous_hash=tip.hash,
            hash=digest,
            link_version=LINK_VERSION,
            covered=covered,
            sequence=tip.sequence + 1,
        )
    )
    session.flush()
    return Head(job.lane, tip.sequence + 1, chained_job_id(job), digest)


@dataclass(frozen=True)
class ChainReport:
    results: int
    """Links verified (up to the first problem)."""
    lanes: int
    """Lanes walked."""
    problem: str | None = None
    """The first altered record, in one line; None when every chain holds."""
    checkpoints: int = 0
    """Checkpoints of chain heads compared (service.store.chain_anchor)."""


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


def _altered(where: str, link: ResultChainRow, job: JobRow, sweep: SweepRow | None) -> str | None:
    """What no longer matches in the link or its job's record; None when both hold."""
    if link.link_version == 1:
        if job_hash(link.previous_hash, job) != link.hash:
            return (
                f"{where}: job {job.id}'s stored result was altered (it no longer matches its hash, "
                f"chain link {link.id})"
            )
        return None
    if link.link_version != LINK_VERSION:
        return f"{where}: chain link {link.id} (job {job.id}) has format {link.link_version}, unknown here"
    recorded = link.covered if isinstance(link.covered, dict) else {}
    if link_hash_v2(link.previous_hash, recorded) != link.hash:
        return (
            f"{where}: chain link {link.id} (job {job.id}) was altered: its hash no longer matches the "
            "fields it records"
        )
    now = covered_digests(job, sweep)
    changed = sorted(name for name in recorded.keys() | now.keys() if recorded.get(name) != now.get(name))
    if changed:
        fields = ", ".join(changed)
        return (
            f"{where}: job {job.id}'s stored result was altered: its {fields} no longer "
            f"match{'es' if len(changed) == 1 else ''} its hash (chain link {link.id})"
        )
    return None


def _walk_lane(session: Session, lane: str, marks: Checkpoints) -> tuple[int, str | None]:
    """(links verified, the first problem or None) of one lane's chain, compared with the checkpoints."""
    where = f"lane {lane!r}"
    unlinked = _unlinked(session, lane)
    missing = f"{where}: job {{}}'s result is not in the chain (its link was removed)"
    query = (
        select(ResultChainRow, JobRow, SweepRow)
        .outerjoin(JobRow, JobRow.id == ResultChainRow.job_id)
        .outerjoin(SweepRow, SweepRow.id == JobRow.sweep_id)
        .where(ResultChainRow.lane == lane)
        .order_by(ResultChainRow.id)
        .execution_options(yield_per=BATCH)
    )
    expected, verified = GENESIS, 0
    for link, job, sweep in session.execute(query):
        if link.previous_hash != expected:
            if unlinked:
                return verified, missing.format(unlinked[0])
            return verified, (
                f"{where}: the chain breaks before job {link.job_id}'s link {link.id} (a link before it was "
                "removed or altered)"
            )
        if job is None:
            return verified, f"{where}: job {link.job_id} of chain link {link.id} was removed from the jobs"
        altered = _altered(where, link, job, sweep)
        if altered is not None:
            return verified, altered
        if job.status != JobStatus.SUCCEEDED.value:
            return verified, f"{where}: job {job.id} succeeded but is now stored as {job.status}"
        contradicted = marks.contradicting(lane, verified + 1, link.hash)
        if contradicted is not None:
            return verified, (
                f"{where}: link {verified + 1} (job {job.id}) is not the one {contradicted.source} "
                f"checkpointed (job {contradicted.head.job_id}): the chain was rewritten from there on"
            )
        expected, verified = link.hash, verified + 1
    if unlinked:
        return verified, missing.format(unlinked[0])
    gone = marks.missing(lane, verified)
    return verified, f"{where}: {gone}" if gone is not None else None


def lanes_with_results(session: Session) -> list[str]:
    """Every lane that has a link or a succeeded job, sorted."""
    chained = set(session.scalars(select(ResultChainRow.lane).distinct()).all())
    succeeded = select(JobRow.lane).where(JobRow.status == JobStatus.SUCCEEDED.value).distinct()
    return sorted(chained | set(session.scalars(succeeded).all()))


def verify_chain(
    database: Database, lane: str | None = None, checkpoints: Iterable[Checkpoint] = ()
) -> ChainReport:
    """Walk every lane's chain (or only `lane`'s), recomputing each hash and comparing it with the
    `checkpoints` (a heads log's, the central database's) and the database's own; stop at the first
    problem. A lane known only from a checkpoint is walked too (all its results were removed). Without
    `lane`, the stored recordings' bytes are checked against their sha256, which the links of the results
    on them cover (service.store.recordings.altered_recordings)."""
    results = 0
    with database.sessions() as session:
        own = stored_checkpoints(session, lane, "this database's checkpoint")
        marks = Checkpoints([*own, *(c for c in checkpoints if lane is None or c.head.lane == lane)])
        lanes = sorted(set(lanes_with_results(session)) | marks.lanes())
        if lane is not None:
            lanes = [name for name in lanes if name == lane]
        for name in lanes:
            verified, problem = _walk_lane(session, name, marks)
            results += verified
            if problem is not None:
                return ChainReport(results, len(lanes), problem, marks.count)
        if lane is None:
            altered = altered_recordings(session)
            if altered:
                return ChainReport(results, len(lanes), altered[0], marks.count)
    return ChainReport(results, len(lanes), checkpoints=marks.count)


def recording_sha256(path: str | Path | None) -> str | None:
    """sha256 (hex) of a recording file's bytes, as the chain covers it (and as a recording stored
    elsewhere is named by); None when there is no such file."""
    if not path or not Path(path).is_file():
        return None
    with Path(path).open("rb") as recording:
        return hashlib.file_digest(recording, "sha256").hexdigest()
