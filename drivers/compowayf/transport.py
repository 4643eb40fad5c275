"""The CompoWay/F link: one port (serial device, pty or socket) opened with pyserial's serial_for_url, and
request/response exchanges on it with timeouts, bounded retries and re-opening of a lost port.

Several amplifiers on one RS-485 line share one `CompowayFPort` (each addresses its own node); a lock keeps
their exchanges from interleaving. An exchange is: flush stale input, write the command, read until the
reply's ETX and BCC byte have arrived or the timeout expires. A reply cut short (no ETX or no BCC) counts as
a timeout (IncompleteResponseError). Errors whose class is `retryable` (timeouts, corrupted or malformed
replies, transmission end codes, a lost port) are retried up to `LinkSettings.retries` times, re-opening the
port first when it was lost; the last error is raised when all attempts failed. Refusals (response codes,
format/sub-address end codes) are raised at once.

Caveat (protocol, not implementation): CompoWay/F has no sequence number, so a reply that arrives after its
request timed out and after the next request's input flush would be taken as the next reply.
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

from drivers.compowayf.codec import ResponseFrame, build_command, check_response, parse_response, split_frame
from drivers.compowayf.errors import (
    CompowayFError,
    IncompleteResponseError,
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


@dataclass(frozen=True)
class LinkSettings:
    """Timing of the link. timeout_s bounds one attempt (write + complete reply); retries is the number of
    extra attempts for retryable errors (0 = fail at the first error); poll_s is the read slice used to
    watch the deadline (it adds no latency: reads return as soon as bytes arrive)."""

    timeout_s: float = 0.5
    retries: int = 2
    reopen: bool = True
    poll_s: float = 0.02

    def __post_init__(self) -> None:
        if self.timeout_s <= 0 or self.poll_s <= 0:
            raise ValueError("timeout_s and poll_s must be positive")
        if self.retries < 0:
            raise ValueError("retries must be >= 0")


@dataclass
class LinkCounters:
    """What the link went through since it was opened (all requests, all nodes)."""

    requests: int = 0
    attempts: int = 0
    retries: int = 0
    reopens: int = 0
    failures: int = 0


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
    ) -> None:
        """Open `url` (a device URL, see urls.py; a node= option in it is ignored here) at once.

        serial_settings and link default to the URL's options, else to the dataclass defaults. `opener`
        replaces serial_for_url (tests pass a replay double). Raises PortOpenError if the port won't open.
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
            )
        self.link = link
        self.counters = LinkCounters()
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
        wait_s = max(0.0, min(self.link.poll_s, deadline - time.monotonic()))
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

    def request(self, node: int, service: str, data: str = "") -> ResponseFrame:
        """Send one command and return its checked response (end code 00, response code 0000).

        Retries retryable errors up to link.retries times; raises the last error (a CompowayFError).
        """
        frame = build_command(node, service, data)
        with self._lock:
            self.counters.requests += 1
            for attempt in range(self.link.retries + 1):
                try:
                    reply = self._attempt(frame, f"node {node:02d} on {self.pyserial_url}")
                    response = parse_response(reply)
                    check_response(response, node, service)
                    return response
                except CompowayFError as exc:
                    if not exc.retryable or attempt == self.link.retries:
                        self.counters.failures += 1
                        raise
                    self.counters.retries += 1
            raise AssertionError("unreachable")  # pragma: no cover

    def exchange(self, frame: bytes) -> bytes:
        """One raw attempt: write `frame`, return the first complete frame that comes back (unparsed)."""
        with self._lock:
            return self._attempt(frame, self.pyserial_url)

    def _attempt(self, frame: bytes, label: str) -> bytes:
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
        port = self._port
        self.counters.attempts += 1
        received = b""
        try:
            port.reset_input_buffer()
            port.write(frame)
            deadline = time.monotonic() + self.link.timeout_s
            while True:
                reply, _rest = split_frame(received)
                if reply is not None:
                    return reply
                if time.monotonic() >= deadline:
                    break
                received += self._read_available(port, deadline)
        except (serial.SerialException, OSError) as exc:
            self._drop_port()
            raise PortLostError(f"{label}: port lost ({exc})") from exc
        if received:
            raise IncompleteResponseError(
                f"{label}: reply incomplete after {self.link.timeout_s:g} s "
                f"(no ETX/BCC, {len(received)} byte(s))"
            )
        raise ResponseTimeoutError(f"{label}: no reply within {self.link.timeout_s:g} s")
