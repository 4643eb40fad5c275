"""Connection-level guards: a deadline for the request headers, and a cap on the connections of one
client address. They live in uvicorn's HTTP protocol, below the app: a request whose headers never
complete never reaches an ASGI middleware.

uvicorn (h11: the service passes this protocol class itself, so that installing httptools changes
nothing) times out an idle keep-alive connection, but its timer is cancelled by the first byte of a
request: headers sent a byte at a time, or never finished, held a connection for as long as the client
liked (25 s and counting in the review). `GuardedH11Protocol` starts a timer whenever the connection waits
for a request's headers (when it is made, and when a response has been sent and it waits for the next
request) and closes the connection if they are not complete within `header_timeout_s`.

It also counts the open connections of each client address: past `max_per_address`, a new connection
from that address is closed at once, before anything is read. Hundreds of half-sent connections from one
address then hold only that many sockets and tasks, and a client from another address (the operator's
page, the emergency stop) is served as before. Behind a reverse proxy every client has the proxy's
address: raise the cap there, or let the proxy limit per client.

The request body has its own deadlines (service.api.limits.BodyDeadline).
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from dataclasses import dataclass, field
from typing import ClassVar

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

log = logging.getLogger("shockbench.api")


@dataclass(frozen=True)
class ConnectionLimits:
    header_timeout_s: float
    """Longest time for a request's headers, from the moment the connection waits for them."""
    max_per_address: int
    """Most connections one client address may hold open at once."""


@dataclass
class AddressTally:
    """Open connections per client address. Used on the event loop only: no lock."""

    limit: int
    open: Counter[str] = field(default_factory=Counter)
    refusing: set[str] = field(default_factory=set)
    """Addresses refused since their count was last 0: each is logged once per burst."""

    def admit(self, address: str) -> bool:
        if self.open[address] >= self.limit:
            if address not in self.refusing:
                self.refusing.add(address)
                log.warning(
                    "refusing connections from %s: it holds %d open, the most allowed per address",
                    address,
                    self.open[address],
                )
            return False
        self.open[address] += 1
        return True

    def release(self, address: str) -> None:
        self.open[address] -= 1
        if self.open[address] <= 0:
            del self.open[address]
            self.refusing.discard(address)


class GuardedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with the header deadline and the per-address cap. A subclass with the
    limits bound is made by `guarded_protocol` (uvicorn builds one instance per connection from the
    class it is given)."""

    limits: ClassVar[ConnectionLimits]
    tally: ClassVar[AddressTally]

    _address: str | None = None
    _header_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        address = self.client[0] if self.client else None
        if address is not None:
            if not self.tally.admit(address):
                transport.close()
                return
            self._address = address
        self._watch_headers()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._address is not None:
            self.tally.release(self._address)
            self._address = None
        self._stop_header_timer()
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        self._watch_headers()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        self._watch_headers()

    def _watch_headers(self) -> None:
        """Time the headers while the connection waits for them (h11: the client's side IDLE); stop
        once they are complete."""
        waiting = self.conn.their_state is h11.IDLE and not self.transport.is_closing()
        if waiting and self._header_timer is None:
            self._header_timer = self.loop.call_later(self.limits.header_timeout_s, self._headers_late)
        elif not waiting:
            self._stop_header_timer()

    def _stop_header_timer(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None

    def _headers_late(self) -> None:
        self._header_timer = None
        if self.conn.their_state is h11.IDLE and not self.transport.is_closing():
            log.info(
                "closing a connection from %s: no complete request headers within %g s",
                self._address,
                self.limits.header_timeout_s,
            )
            self.transport.close()


def guarded_protocol(limits: ConnectionLimits) -> type[GuardedH11Protocol]:
    """The protocol class to give uvicorn (`uvicorn.Config(http=...)`), with its own tally: one per
    server."""
    return type(
        "BoundGuardedH11Protocol",
        (GuardedH11Protocol,),
        {"limits": limits, "tally": AddressTally(limits.max_per_address)},
    )
