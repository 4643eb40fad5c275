"""Per-key quotas: how many unfinished things (queued or running jobs, waiting or running scheduled tests)
one key may have at once, checked in the transaction that inserts the new row.

Why in the transaction and not a lock in the service: instances sharing a database (`serve --database
--shared-queue`) each have their own process, so a per-process lock plus a recount would still let two
instances overshoot; the database is the one place all of them meet. The order makes two concurrent
submits of one key unable to both pass:

1. the new row is INSERTed (flushed) first;
2. on PostgreSQL, a transaction-scoped advisory lock keyed by the key id is taken: a second submit of the
   same key waits here until the first commits or rolls back, and (READ COMMITTED: every statement sees
   what was committed before it) then counts the first one's row; keys do not wait for each other;
   on SQLite, the INSERT of step 1 already holds the database's single write lock until the commit, so a
   second submit waits at its own INSERT and counts after the first committed;
3. the key's unfinished rows are counted, the new one included; over the limit, QuotaExceededError is raised
   and the whole transaction (the new row) is rolled back.

A row the service itself creates (the job the scheduler queues on a finished scheduled test's sweep) is
inserted without a quota: the work it belongs to was admitted already.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

from sqlalchemy import BigInteger, Select, func, literal, select
from sqlalchemy.orm import Session

LOCK_NAMESPACE = b"shockbench key quota "


@dataclass(frozen=True)
class KeyQuota:
    """At most `limit` unfinished rows submitted by `key_id` (service.access.key_id)."""

    key_id: str
    limit: int

    def __post_init__(self) -> None:
        if self.limit < 1:
            raise ValueError("a quota must allow at least 1")


class QuotaExceededError(Exception):
    """The key has `limit` unfinished `what` already. Not a UserError (service.api.errors maps those to
    4xx statuses without headers): a limit, not bad input, which the API answers with 429 and Retry-After
    (service.api.quotas)."""

    def __init__(self, what: str, active: int, limit: int) -> None:
        super().__init__(
            f"this key has {active} {what}, the most allowed ({limit}); submit again once one has ended"
        )
        self.what = what
        self.active = active
        self.limit = limit


def lock_key(key_id: str) -> int:
    """The key's PostgreSQL advisory lock: a signed 64-bit number from the sha256 of its id."""
    digest = hashlib.sha256(LOCK_NAMESPACE + key_id.encode("utf-8")).digest()
    return int.from_bytes(digest[:8], "big", signed=True)


def enforce(session: Session, quota: KeyQuota, unfinished: Select[Any], what: str) -> None:
    """Step 2 and 3 of the module docstring, in `session`'s transaction, right after the new row was
    flushed: `unfinished` counts the key's unfinished rows (the new one included)."""
    if session.get_bind().dialect.name == "postgresql":
        session.execute(select(func.pg_advisory_xact_lock(literal(lock_key(quota.key_id), BigInteger))))
    active = int(session.scalar(unfinished) or 0)
    if active > quota.limit:
        raise QuotaExceededError(what, active - 1, quota.limit)
