"""Anchors for the result chain's head: so that deleting a lane's newest results is found, not only
altering them.

A chain (service.store.result_chain) shows any change to a stored result and any gap in the middle, but not
its own end: remove the newest results together with their links and what is left is a shorter, intact
chain. So a lane checkpoints every new head, (lane, sequence: the link's place in the lane's chain, job id:
the id the job has where it ran, hash, time), outside the chain:

- in its heads log, `result-chain-heads.jsonl` in its data directory (`HeadLog`): one JSON line per new head,
  written after the transaction that stored the result committed (a head that was rolled back is never
  logged), opened O_APPEND and fsynced before the job counts as done;
- on the central database, when the lane syncs to one (service.store.sync): a `chain_checkpoints` row
  inserted in the central transaction that appends the pushed link.

`shockbench verify` compares every checkpoint it is given with the chain: the link at the checkpoint's
sequence must have the checkpointed hash, and a chain that ends before a checkpointed head fails, naming
the missing links (their sequence numbers and the job ids the checkpoints give).

Threat model. An attacker who can write the database (the lane's SQLite file, or the central database) but
not the heads log:
- cannot alter what a stored result says or means (the fields its link covers), nor delete or reorder
  links in the middle: the chain shows it (service.store.result_chain);
- cannot rewrite the chain from some link on to hide that (recomputing every later hash, which anyone can:
  the hashes are not keyed): every logged link's hash is compared;
- cannot delete the newest results, nor roll the database back to an older copy: the chain would end
  before the logged head;
- can delete or alter results stored after the last line that reached the log (the log is written after
  the commit: a crash or a full disk between the two leaves the newest result unlogged; the service logs a
  warning);
- can append forged results at the end: a checkpoint proves the chain up to it is complete and unchanged,
  not that what follows is genuine;
- can change what no link covers (artefacts, progress, errors, who submitted, start times) and the files
  themselves: `verify` compares the stored recording hashes, it does not read the recordings.
O_APPEND keeps the service from overwriting its own log; against a person, the log must be out of the
database writer's reach (another user, `chattr +a`, copied off the machine): whoever can edit both hides
everything. Likewise the central checkpoints hold against a writer of the lane's local store, and against a
writer of the central database only when the roles that can write results may only INSERT into
`chain_checkpoints`.
"""

from __future__ import annotations

import json
import logging
import os
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from service.store.models import ChainCheckpointRow, utcnow

HEADS_FILE = "result-chain-heads.jsonl"
"""The heads log's name in a lane's data directory."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Head:
    """A lane's chain head: its newest link."""

    lane: str
    sequence: int
    """The link's place in the lane's chain, 1 for the first."""
    job_id: int
    """The job's id where it ran (the id its link hashes)."""
    hash: str


@dataclass(frozen=True)
class Checkpoint:
    head: Head
    at: datetime
    """When it was checkpointed (UTC)."""
    source: str
    """Where it was read, for messages: "heads log PATH line N", "central checkpoint N"."""


class HeadLog:
    """A lane's append-only heads log: one JSON line per new head (module docstring)."""

    def __init__(self, path: Path, clock: Callable[[], datetime] = utcnow) -> None:
        self.path = Path(path)
        self.clock = clock

    @classmethod
    def in_data_dir(cls, data_dir: Path) -> HeadLog:
        return cls(Path(data_dir) / HEADS_FILE)

    def append(self, head: Head) -> None:
        """One line for `head`, written with O_APPEND and fsynced (OSError when that fails). A line cut off
        by a crash is ended first, so that it cannot swallow this one."""
        line = {
            "lane": head.lane,
            "sequence": head.sequence,
            "job_id": head.job_id,
            "hash": head.hash,
            "at": self.clock().isoformat(),
        }
        text = json.dumps(line, sort_keys=True, separators=(",", ":"), ensure_ascii=False) + "\n"
        created = not self.path.exists()
        # 0o666 less the umask, as the database beside it: hashes, no secret; an auditor may read the log
        descriptor = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o666)
        try:
            size = os.fstat(descriptor).st_size
            torn = size > 0 and os.pread(descriptor, 1, size - 1) != b"\n"
            os.write(descriptor, (b"\n" if torn else b"") + text.encode("utf-8"))
            os.fsync(descriptor)
        finally:
            os.close(descriptor)
        if created:  # the new file's name survives a power cut too
            folder = os.open(self.path.parent, os.O_RDONLY)
            try:
                os.fsync(folder)
            finally:
                os.close(folder)

    def record(self, head: Head) -> bool:
        """`append`, for the service: the result is stored already, so a failure is logged, not raised."""
        try:
            self.append(head)
        except OSError as exc:
            log.warning(
                "result chain head %s of lane %r not logged in %s: %s",
                head.sequence,
                head.lane,
                self.path,
                exc,
            )
            return False
        return True

    def checkpoints(self) -> tuple[list[Checkpoint], int]:
        """(every checkpoint in the log, how many lines could not be read: a write cut off by a crash)."""
        found, unreadable = [], 0
        with self.path.open("rb") as lines:
            for number, raw in enumerate(lines, start=1):
                try:
                    line = json.loads(raw)
                    head = Head(
                        str(line["lane"]), int(line["sequence"]), int(line["job_id"]), str(line["hash"])
                    )
                    at = datetime.fromisoformat(line["at"])
                except (ValueError, KeyError, TypeError):
                    unreadable += 1
                    continue
                found.append(Checkpoint(head, at, f"heads log {self.path} line {number}"))
        return found, unreadable


def checkpoint_central(session: Session, head: Head) -> None:
    """In `session`'s transaction on the central database: checkpoint the lane's head, unless it is there
    (a repeated push)."""
    there = select(ChainCheckpointRow.id).where(
        ChainCheckpointRow.lane == head.lane, ChainCheckpointRow.sequence == head.sequence
    )
    if session.scalar(there) is None:
        row = ChainCheckpointRow(
            lane=head.lane,
            sequence=head.sequence,
            job_id=head.job_id,
            hash=head.hash,
            checkpointed_at=utcnow(),
        )
        session.add(row)
        session.flush()


def stored_checkpoints(
    session: Session, lane: str | None = None, where: str = "checkpoint"
) -> list[Checkpoint]:
    """The `chain_checkpoints` rows of the database (of `lane` only, when given); `where` names them."""
    query = select(ChainCheckpointRow).order_by(ChainCheckpointRow.id)
    if lane is not None:
        query = query.where(ChainCheckpointRow.lane == lane)
    return [
        Checkpoint(
            Head(row.lane, row.sequence, row.job_id, row.hash), row.checkpointed_at, f"{where} {row.id}"
        )
        for row in session.scalars(query)
    ]


class Checkpoints:
    """Checkpoints by lane and sequence, for `verify`'s walk (service.store.result_chain)."""

    def __init__(self, checkpoints: Iterable[Checkpoint] = ()) -> None:
        self.by_lane: dict[str, dict[int, list[Checkpoint]]] = defaultdict(lambda: defaultdict(list))
        self.count = 0
        for checkpoint in checkpoints:
            self.by_lane[checkpoint.head.lane][checkpoint.head.sequence].append(checkpoint)
            self.count += 1

    def lanes(self) -> set[str]:
        return set(self.by_lane)

    def contradicting(self, lane: str, sequence: int, digest: str) -> Checkpoint | None:
        """A checkpoint of the lane's link `sequence` with another hash than `digest`, if any."""
        marks = self.by_lane.get(lane, {}).get(sequence, [])
        return next((mark for mark in marks if mark.head.hash != digest), None)

    def missing(self, lane: str, length: int) -> str | None:
        """What is missing when the lane's chain has `length` links: None when no checkpoint lies beyond."""
        beyond = {seq: marks for seq, marks in self.by_lane.get(lane, {}).items() if seq > length}
        if not beyond:
            return None
        newest = max(beyond)
        mark = max(beyond[newest], key=lambda m: m.at)
        jobs = sorted({m.head.job_id for marks in beyond.values() for m in marks})
        shown = ", ".join(str(j) for j in jobs[:10]) + (
            f" and {len(jobs) - 10} more" if len(jobs) > 10 else ""
        )
        links = f"link {newest}" if newest == length + 1 else f"links {length + 1}-{newest}"
        ends = f"the chain ends at link {length}" if length else "no link of the chain is left"
        return (
            f"{ends}, but {mark.source} checkpointed link {newest} (job "
            f"{mark.head.job_id}) at {mark.at.isoformat(timespec='seconds')}: {links} "
            f"(job{'s' if len(jobs) > 1 else ''} {shown}) {'are' if newest > length + 1 else 'is'} missing "
            "(the newest results were removed)"
        )
