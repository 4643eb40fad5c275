"""The CompoWay/F link: one port (serial device, pty or socket) opened with pyserial's serial_for_url, and
request/response exchanges on it with timeouts, bounded retries and re-opening of a lost port.

Several amplifiers on one RS-485 line share one `CompowayFPort` (each addresses its own node); a lock keeps
their exchanges from interleaving. An exchange is: wait out a late reply still owed by an earlier request
(below), flush stale input, write the command, discard its echo when the adapter echoes (`LinkSettings.echo`),
then read until a reply that answers the command has arrived or the timeout expires.

Reading a reply:
* Resync on STX: bytes before the STX of a reply (a 0x00 from an RS-485 line turning around, noise, the tail
  of an older frame) are dropped, as OMRON's own receivers do ("when STX is received again during reception,
  reception is carried out again from the point where STX was received").
* Matching: CompoWay/F has no sequence number, so a reply is accepted only when it comes from the node asked,
  for the service asked, and (where the request says how, e.g. the element count or the echoed parameter
  read header) with the content asked for. Any other well-formed reply is discarded (counted in
  `LinkCounters.discarded_frames`), never returned, and reading goes on until the timeout.
* Late replies: OMRON allows a reply up to 3 s after the command (ZS/ZFV CompoWay/F command references,
  "Response Formats": "It may take three seconds at longest from sending a command to receiving a response.
  If no response is returned, be sure to send another command after waiting for at least three seconds").
  After a request got no reply, the next exchange on the port first waits until `late_reply_s` after that
  request was sent, discarding whatever arrives, unless the late reply itself arrives first. The reply to
  the next request can then not be confused with it.
  A caller that must not hold its thread that long (the acquisition: one line's thread, or a simulated
  bench's only thread) turns `waits_for_late_replies` off: the port then never waits itself. A request
  while the line must stay quiet raises LineQuietError at once, nothing sent; a timed-out attempt is not
  retried when its retry would have to wait (the timeout is raised); the caller asks `quiet_s()` (which
  takes a late reply that has come meanwhile, ending the wait early) and comes back. The rule is the same:
  nothing goes on the line until late_reply_s after an unanswered request, or its late reply came.
* A reply cut short (no ETX or no BCC) counts as a timeout (IncompleteResponseError).

Every failed attempt, retried or not, is kept in `last_failure` (one line, naming the error class), so a
caller can say why a line delivers nothing while its retries are still going on.

Errors whose class is `retryable` (timeouts, corrupted or malformed replies, transmission end codes, a lost
port) are retried up to `LinkSettings.retries` times, re-opening the port first when it was lost; the last
error is raised when all attempts failed. Refusals (response codes, format/sub-address/frame-length end
codes) are raised at once.
"""

from __future__ import annotations

import contextlib
import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import serial

from drivers.compowayf.codec import (
    NORMAL_COMPLETION,
    NORMAL_END,
    ResponseFrame,
    build_command,
    check_response,
    parse_response,
    split_reply,
)
from drivers.compowayf.errors import (
    CompowayFError,
    IncompleteResponseError,
    LineQuietError,
    MissingEchoError,
    PortError,
    PortLostError,
    PortOpenError,
    ResponseTimeoutError,
)
from drivers.compowayf.urls import SerialSettings, parse_device_url

READ_CHUNK_BYTES = 4096
"""Most bytes taken in one read once data is waiting (a CompoWay/F frame is far shorter)."""


class SerialLike(Protocol):
    """The part of pyserial's Serial API the link uses (tests may substitute a replay double)."""

    timeout: float | None

    @property
    def in_waiting(self) -> int: ...

    def read(self, size: int = 1) -> bytes: ...

    def write(self, data: bytes) -> int | None: ...

    def reset_input_buffer(self) -> None: ...

    def close(self) -> None: ...


OMRON_WORST_CASE_RESPONSE_S = 3.0
"""OMRON: "It may take three seconds at longest from sending a command to receiving a response" (ZS series
and ZFV-C CompoWay/F command references, Response Formats)."""


@dataclass(frozen=True)
class LinkSettings:
    """Timing of the link.

    timeout_s: how long one attempt waits for its reply (write + complete reply). The default 0.5 s suits
        an amplifier that answers in milliseconds and lets the acquisition notice a silent sensor quickly;
        OMRON's documented worst case is 3 s (OMRON_WORST_CASE_RESPONSE_S): set timeout_s=3 to honour it
        on every request.
    late_reply_s: after a request went unanswered, the next exchange waits until this long after that
        request was sent (draining the line) before sending, unless the late reply arrives first. Default
        OMRON's 3 s; 0 sends at once (only matching then protects against a late reply).
    retries: extra attempts for retryable errors (0 = fail at the first error).
    echo: the adapter echoes every byte the host sends (some RS-485 converters do): each frame sent is
        read back and discarded before the reply is looked for.
    poll_s: the read slice used to watch the deadline (it adds no latency: reads return as soon as bytes
        arrive).
    """

    timeout_s: float = 0.5
    retries: int = 2
    reopen: bool = True
    poll_s: float = 0.02
    late_reply_s: float = OMRON_WORST_CASE_RESPONSE_S
    echo: bool = False

    def __post_init__(self) -> None:
        if self.timeout_s <= 0 or self.poll_s <= 0:
            raise ValueError("timeout_s and poll_s must be positive")
        if self.retries < 0:
            raise ValueError("retries must be >= 0")
        if self.late_reply_s < 0:
            raise ValueError("late_reply_s must be >= 0")


@dataclass
class LinkCounters:
    """What the link went through since it was opened (all requests, all nodes).

    discarded_frames: well-formed replies that did not answer the request in hand (late, other node or
    service, other content); skipped_bytes: bytes dropped before an STX; late_reply_waits: exchanges that
    first waited out a reply owed by an unanswered request; unanswered: attempts that got no complete
    reply in time (each starts a late-reply wait)."""

    requests: int = 0
    attempts: int = 0
    retries: int = 0
    reopens: int = 0
    failures: int = 0
    discarded_frames: int = 0
    skipped_bytes: int = 0
    late_reply_waits: int = 0
    unanswered: int = 0


ReplyMatcher = Callable[[ResponseFrame], bool]
"""Says whether a normal reply (end code 00, response code 0000) for the right node and service carries
what the request asked for (e.g. the number of elements)."""

Opener = Callable[[], SerialLike]


class CompowayFPort:
    """One open port carrying CompoWay/F requests to one or more nodes."""

    def __init__(
        self,
        url: str,
        *,
        serial_settings: SerialSettings | None = None,
        link: LinkSettings | None = None,
        opener: Opener | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        """Open `url` (a device URL, see urls.py; a node= option in it is ignored here) at once.

        serial_settings and link default to the URL's options, else to the dataclass defaults. `opener`
        replaces serial_for_url (tests pass a replay double); `clock` (monotonic seconds) times the
        deadlines, tests pass the simulated clock of their double. Raises PortOpenError if the port won't
        open.
        """
        parsed = parse_device_url(url, serial_settings)
        self.url = url
        self.pyserial_url = parsed.pyserial_url
        self.serial_settings = parsed.serial
        if link is None:
            defaults = LinkSettings()
            link = LinkSettings(
                timeout_s=parsed.timeout_s or defaults.timeout_s,
                retries=defaults.retries if parsed.retries is None else parsed.retries,
                late_reply_s=defaults.late_reply_s if parsed.late_reply_s is None else parsed.late_reply_s,
                echo=parsed.echo,
            )
        self.link = link
        self.counters = LinkCounters()
        self._clock = clock
        self._unanswered_sent_s: float | None = None  # send time of a request whose reply may come late
        self._late_bytes = b""  # what arrived of a late reply so far (quiet_s reads without waiting)
        self.waits_for_late_replies = True
        """False: never wait out a late reply here (see the module): LineQuietError, no waiting retries."""
        self.last_failure = ""
        """The newest failed attempt on this line, any node, retried or not: "ErrorClass: message"."""
        self.awaiting_reply = False
        """True while an attempt waits for its reply (read from any thread: a silence check)."""
        self._opener = opener or self._open_with_pyserial
        self._lock = threading.RLock()
        self._port: SerialLike | None = None
        self._descriptor: int | None = None
        self._closed = False
        self._port = self._open()

    def _open_with_pyserial(self) -> SerialLike:
        port: SerialLike = serial.serial_for_url(
            self.pyserial_url,
            timeout=min(self.link.poll_s, self.link.timeout_s),
            write_timeout=self.link.timeout_s,
            **self.serial_settings.as_kwargs(),
        )
        return port

    @staticmethod
    def _waitable(port: SerialLike) -> int | None:
        """The port's file descriptor when reads can wait on it with select (serial devices, ptys, TCP
        sockets): the port is then switched to non-blocking reads. None for anything else (loop://,
        rfc2217://, test doubles), which keeps the port's own read timeout."""
        fileno = getattr(port, "fileno", None)
        if fileno is None or not isinstance(port, serial.SerialBase):
            return None
        try:
            descriptor = int(fileno())
            select.select([descriptor], [], [], 0)
            port.timeout = 0
        except (OSError, ValueError, TypeError, AttributeError, serial.SerialException):
            return None
        return descriptor

    def _read_available(self, port: SerialLike, deadline: float) -> bytes:
        """Whatever has arrived, waiting up to poll_s (and never past the deadline) for the first byte.
        Waits on the descriptor where there is one, and then takes every byte there in one read (a
        pyserial socket's in_waiting says 1 whatever is queued, so reading in_waiting bytes would
        fetch a reply byte by byte)."""
        if self._descriptor is None:
            return port.read(max(1, port.in_waiting))
        wait_s = max(0.0, min(self.link.poll_s, deadline - self._clock()))
        ready, _, _ = select.select([self._descriptor], [], [], wait_s)
        return port.read(READ_CHUNK_BYTES) if ready else b""

    def _open(self) -> SerialLike:
        try:
            port = self._opener()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise PortOpenError(f"cannot open {self.pyserial_url}: {exc}") from exc
        self._descriptor = self._waitable(port)
        return port

    @property
    def is_open(self) -> bool:
        return self._port is not None

    def close(self) -> None:
        """Close the port for good (requests afterwards raise PortError)."""
        with self._lock:
            self._closed = True
            self._drop_port()

    def _drop_port(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(serial.SerialException, OSError):
                port.close()

    def __enter__(self) -> CompowayFPort:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def request(
        self, node: int, service: str, data: str = "", *, matches: ReplyMatcher | None = None
    ) -> ResponseFrame:
        """Send one command and return its checked response (end code 00, response code 0000).

        Only a reply from `node` for `service` (and, for a normal reply, one `matches` accepts) answers the
        command; others are discarded. Retries retryable errors up to link.retries times; raises the last
        error (a CompowayFError).
        """
        frame = build_command(node, service, data)
        service = service.upper()

        def answers(response: ResponseFrame) -> bool:
            if response.node != node:
                return False
            if not response.service:  # short error form: nothing to match it by
                return True
            if response.service != service:
                return False
            normal = response.end_code == NORMAL_END and response.response_code == NORMAL_COMPLETION
            return not normal or matches is None or matches(response)

        label = f"node {node:02d} on {self.pyserial_url}"
        with self._lock:
            if not self.waits_for_late_replies and (quiet_s := self._quiet_s()) > 0:
                raise LineQuietError(
                    f"{label}: nothing sent, the line waits {quiet_s:.2f} s more for a late reply "
                    f"(up to {self.link.late_reply_s:g} s after an unanswered request)"
                )
            self.counters.requests += 1
            for attempt in range(self.link.retries + 1):
                try:
                    response = self._attempt(frame, label, answers)
                    assert isinstance(response, ResponseFrame)
                    check_response(response, node, service)
                    return response
                except CompowayFError as exc:
                    self.last_failure = f"{type(exc).__name__}: {exc}"
                    waiting_retry = not self.waits_for_late_replies and self._quiet_s() > 0
                    if not exc.retryable or attempt == self.link.retries or waiting_retry:
                        self.counters.failures += 1
                        raise
                    self.counters.retries += 1
            raise AssertionError("unreachable")  # pragma: no cover

    def exchange(self, frame: bytes) -> bytes:
        """One raw attempt: write `frame`, return the first complete frame that comes back (unparsed)."""
        with self._lock:
            reply = self._attempt(frame, self.pyserial_url, None)
            assert isinstance(reply, bytes)
            return reply

    def _usable_port(self, label: str) -> SerialLike:
        if self._closed:
            raise PortError(f"{label}: port is closed")
        if self._port is None:
            if not self.link.reopen:
                raise PortLostError(f"{self.pyserial_url}: port lost and re-opening is disabled")
            try:
                self._port = self._open()
            except PortOpenError as exc:
                raise PortLostError(f"{self.pyserial_url}: port lost, re-open failed: {exc}") from exc
            self.counters.reopens += 1
        return self._port

    def quiet_s(self) -> float:
        """Seconds the line must still stay quiet for a late reply to an unanswered request (0: a request
        may go now). Takes what has arrived meanwhile without waiting: a late reply ends the wait early
        (discarded, counted in discarded_frames)."""
        with self._lock:
            return self._quiet_s()

    def _quiet_s(self) -> float:
        sent_s = self._unanswered_sent_s
        if sent_s is None:
            return 0.0
        remaining_s = sent_s + self.link.late_reply_s - self._clock()
        port = self._port
        if remaining_s <= 0 or port is None:
            return max(0.0, remaining_s)
        try:
            self._late_bytes += self._read_now(port)
        except (serial.SerialException, OSError):
            self._drop_port()  # the next request re-opens it (and says so if it cannot)
            return remaining_s
        late, self._late_bytes, skipped = split_reply(self._late_bytes)
        self.counters.skipped_bytes += skipped
        if late is None:
            return remaining_s
        self.counters.discarded_frames += 1
        self._unanswered_sent_s, self._late_bytes = None, b""
        return 0.0

    def _read_now(self, port: SerialLike) -> bytes:
        """Whatever has arrived, without waiting."""
        if self._descriptor is not None:
            ready, _, _ = select.select([self._descriptor], [], [], 0)
            return port.read(READ_CHUNK_BYTES) if ready else b""
        waiting = port.in_waiting
        return port.read(waiting) if waiting else b""

    def _wait_out_late_reply(self, port: SerialLike) -> None:
        """Drain the line until late_reply_s after the unanswered request, or until its reply came."""
        sent_s, self._unanswered_sent_s = self._unanswered_sent_s, None
        received, self._late_bytes = self._late_bytes, b""
        if sent_s is None:
            return
        until_s = sent_s + self.link.late_reply_s
        if self._clock() >= until_s:
            return
        self.counters.late_reply_waits += 1
        while self._clock() < until_s:
            received += self._read_available(port, until_s)
            late, received, skipped = split_reply(received)
            self.counters.skipped_bytes += skipped
            if late is not None:
                self.counters.discarded_frames += 1
                return

    def _attempt(
        self, frame: bytes, label: str, answers: Callable[[ResponseFrame], bool] | None
    ) -> ResponseFrame | bytes:
        """Write `frame` and return the reply that answers it (parsed), or with answers=None the first
        complete frame (raw bytes)."""
        port = self._usable_port(label)
        self.counters.attempts += 1
        received = b""
        echo_pending = self.link.echo
        try:
            self._wait_out_late_reply(port)
            port.reset_input_buffer()
            self.awaiting_reply = True
            port.write(frame)
            sent_s = self._clock()
            deadline = sent_s + self.link.timeout_s
            while True:
                if echo_pending:
                    at = received.find(frame)
                    if at >= 0:
                        received, echo_pending = received[at + len(frame) :], False
                if not echo_pending:
                    reply, received, skipped = split_reply(received)
                    self.counters.skipped_bytes += skipped
                    if reply is not None:
                        if answers is None:
                            return reply
                        response = parse_response(reply)
                        if answers(response):
                            return response
                        self.counters.discarded_frames += 1
                        continue
                if self._clock() >= deadline:
                    break
                received += self._read_available(port, deadline)
        except (serial.SerialException, OSError) as exc:
            self._drop_port()
            raise PortLostError(f"{label}: port lost ({exc})") from exc
        finally:
            self.awaiting_reply = False
        self._unanswered_sent_s = sent_s
        self.counters.unanswered += 1
        if echo_pending:
            raise MissingEchoError(
                f"{label}: the adapter did not echo the command within {self.link.timeout_s:g} s "
                "(echo suppression is on: does this adapter echo?)"
            )
        if received:
            raise IncompleteResponseError(
                f"{label}: reply incomplete after {self.link.timeout_s:g} s "
                f"(no ETX/BCC, {len(received)} byte(s))"
            )
        raise ResponseTimeoutError(f"{label}: no reply within {self.link.timeout_s:g} s")
