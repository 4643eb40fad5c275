"""The service's sync task: pushes the lane's local outbox to the central database whenever it is reachable
(service.store.sync says what is pushed and why it arrives exactly once), and keeps what GET /status shows
of it: the backlog, its oldest entry, the last error and whether the central database answers.

It runs on the event loop and only awaits; each round (the central schema checked once, then at most
`BATCH` entries pushed, then the backlog counted) runs in a thread. A round that cannot reach the central
database marks it unreachable and the next round comes after `retry_s`; the lane meanwhile works on its
local store as ever.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy.exc import InterfaceError, OperationalError, SQLAlchemyError

from estimator.errors import one_line
from service.store.database import CONNECT_TIMEOUT_S, Database, DatabaseError
from service.store.models import utcnow
from service.store.outbox import Backlog, backlog
from service.store.schema import SchemaError
from service.store.sync import CentralSync, LocalStoreError, SyncError

log = logging.getLogger("shockbench.sync")

BATCH = 200
"""Entries pushed per round at most (then the backlog is counted, so /status follows a long catch-up)."""
MAX_ERROR_CHARS = 300


def _reason(exc: BaseException) -> str:
    """The exception in one line (estimator.errors.one_line), cut to MAX_ERROR_CHARS for /status."""
    text = one_line(exc)
    return text if len(text) <= MAX_ERROR_CHARS else text[: MAX_ERROR_CHARS - 3] + "..."


@dataclass(frozen=True)
class SyncStatus:
    central: str
    """The central database's URL, password hidden."""
    reachable: bool | None
    """Whether the last round reached it; None before the first round."""
    backlog: int
    """Finished sweeps and jobs not yet on the central database."""
    oldest_pending: datetime | None
    """When the oldest of them finished (UTC)."""
    last_error: str | None
    """Why the last round did not finish its work (one line); None when it did."""
    last_contact: datetime | None
    """When a round last reached the central database (UTC)."""
    pushed: int
    """Entries pushed since the service started."""


class SyncAgent:
    def __init__(
        self, local: Database, central: Database, interval_s: float = 1.0, retry_s: float = 2.0
    ) -> None:
        self.local = local
        self.central = central
        self.sync = CentralSync(local, central)
        self.interval_s = interval_s
        self.retry_s = retry_s
        self._schema_checked = False
        self._reachable: bool | None = None
        self._last_error: str | None = None
        self._last_contact: datetime | None = None
        self._backlog = Backlog(0, None)
        self._wakeup = asyncio.Event()
        self._stopping = False
        self._task: asyncio.Task[None] | None = None

    def status(self) -> SyncStatus:
        """From memory (the last round's view)."""
        return SyncStatus(
            central=self.central.safe_url,
            reachable=self._reachable,
            backlog=self._backlog.count,
            oldest_pending=self._backlog.oldest,
            last_error=self._last_error,
            last_contact=self._last_contact,
            pushed=self.sync.pushed,
        )

    async def start(self) -> None:
        self._backlog = await asyncio.to_thread(backlog, self.local)
        self._task = asyncio.create_task(self._run(), name="central-sync")

    async def stop(self) -> None:
        """Let the round under way end (an entry whose central transaction committed is removed from the
        outbox, not pushed again at the next start), then stop; cut it off if the central database hangs."""
        if self._task is None:
            return
        self._stopping = True
        self._wakeup.set()
        try:
            await asyncio.wait_for(self._task, 2 * CONNECT_TIMEOUT_S)
        except TimeoutError:
            log.warning("central sync did not end its round; stopped (it resumes at the next start)")
        self._task = None

    async def _run(self) -> None:
        while not self._stopping:
            self._wakeup.clear()
            more = await asyncio.to_thread(self.round)
            if more:  # a long backlog: straight on with the next batch
                continue
            pause = self.interval_s if self._reachable and self._last_error is None else self.retry_s
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._wakeup.wait(), pause)

    def round(self) -> bool:
        """Check the central schema (once), push what is pending (up to BATCH), count the backlog; whether
        a full batch went (more may wait). Never raises."""
        was, error_before = self._reachable, self._last_error
        pushed = 0
        try:
            if not self._schema_checked:
                self.central.upgrade_schema()  # as `serve` does at start; refuses a newer schema
                self._schema_checked = True
            pushed = len(self.sync.push_pending(limit=BATCH))
            self._reachable, self._last_error, self._last_contact = True, None, utcnow()
        except (DatabaseError, OperationalError, InterfaceError) as exc:  # away, or dropped in mid-push
            self._reachable, self._last_error = False, _reason(exc)
        except (SchemaError, SyncError, SQLAlchemyError) as exc:  # it answers, but refuses
            self._reachable, self._last_error = True, _reason(exc)
        except LocalStoreError as exc:  # the central database is not to blame: tried again
            self._last_error = _reason(exc)
        except Exception as exc:
            log.exception("central sync round failed")
            self._last_error = _reason(exc)
        try:
            self._backlog = backlog(self.local)
        except Exception:
            log.exception("could not count the sync backlog")
        if was is not False and self._reachable is False:
            log.warning(
                "central database %s unreachable (%s); the lane goes on with its local store, %d to sync",
                self.central.safe_url,
                self._last_error,
                self._backlog.count,
            )
        elif was is False and self._reachable:
            log.info("central database %s reachable again; syncing", self.central.safe_url)
        elif self._reachable and self._last_error is not None and self._last_error != error_before:
            log.warning("central sync stopped: %s", self._last_error)
        return pushed == BATCH
