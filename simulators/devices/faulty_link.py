"""A TCP link that can fail on command: a small asyncio proxy on loopback between a host and a device.

    async with FaultyLink("127.0.0.1", drive_port) as link:      # the host connects to link.port
        link.silence()      # connections stay up, every byte in either direction is lost
        link.drop()         # every connection is aborted, new ones are accepted and closed at once
        link.restore()      # bytes pass again; new connections reach the device
        link.fail_on(lambda data: ..., LinkMode.SILENT)  # fail at the first host chunk the predicate picks

What a cable pulled or a switch rebooting does to a Modbus TCP drive (or a serial-to-Ethernet converter),
for any device served on a socket: the simulated ones of this package, or a plain pymodbus server.
`sent` logs every chunk the host sent, with its time and whether it reached the device, so a test can
tell what the host did during an outage (did it keep feeding a watchdog?). `modbus_tcp_requests` reads
the requests in a chunk, to pick one for `fail_on` or to count keep-alives.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum

READ_SIZE = 4096


class LinkMode(StrEnum):
    PASS = "pass"
    SILENT = "silent"
    DOWN = "down"


@dataclass(frozen=True)
class SentChunk:
    """Bytes the host sent: when (the link's clock), and whether they were passed on to the device."""

    at_s: float
    data: bytes
    delivered: bool


class FaultyLink:
    """Forwards TCP connections from (host, port) to (target_host, target_port) while in PASS mode."""

    def __init__(
        self,
        target_host: str,
        target_port: int,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.target = (target_host, target_port)
        self.host = host
        self.port = port
        self.clock = clock
        self.mode = LinkMode.PASS
        self.sent: list[SentChunk] = []
        """Every chunk the host sent, in order."""
        self.connections_accepted = 0
        self.failed_at_s: float | None = None
        """When a fail_on trigger fired (the link's clock)."""
        self._trigger: tuple[Callable[[bytes], bool], LinkMode] | None = None
        self._server: asyncio.Server | None = None
        self._pipes: set[_Pipe] = set()

    # ---- lifecycle ----------------------------------------------------------------------------------

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._accept, self.host, self.port)
        self.port = self._server.sockets[0].getsockname()[1]

    async def close(self) -> None:
        for pipe in list(self._pipes):
            pipe.abort()
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None

    async def __aenter__(self) -> FaultyLink:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    # ---- faults -------------------------------------------------------------------------------------

    def silence(self) -> None:
        """Keep every connection open but pass nothing, either way (a silent device or a dead switch)."""
        self.mode = LinkMode.SILENT

    def drop(self) -> None:
        """Abort every connection (the host sees a reset) and refuse to carry new ones until restore()."""
        self.mode = LinkMode.DOWN
        for pipe in list(self._pipes):
            pipe.abort()

    def restore(self) -> None:
        """Pass bytes again, on the connections still open and on new ones."""
        self.mode = LinkMode.PASS

    def fail_on(self, predicate: Callable[[bytes], bool], mode: LinkMode) -> None:
        """Switch to `mode` (SILENT or DOWN) at the first chunk from the host for which predicate holds;
        that chunk is lost. One shot: the trigger is cleared when it fires."""
        self._trigger = (predicate, mode)

    # ---- forwarding ---------------------------------------------------------------------------------

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self.mode is LinkMode.DOWN:
            writer.transport.abort()
            return
        try:
            device_reader, device_writer = await asyncio.open_connection(*self.target)
        except OSError:
            writer.transport.abort()
            return
        self.connections_accepted += 1
        pipe = _Pipe(writer, device_writer)
        self._pipes.add(pipe)
        try:
            await asyncio.gather(
                self._pump(reader, device_writer, from_host=True),
                self._pump(device_reader, writer, from_host=False),
            )
        finally:
            pipe.abort()
            self._pipes.discard(pipe)

    async def _pump(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, *, from_host: bool
    ) -> None:
        with contextlib.suppress(ConnectionError, OSError):
            while data := await reader.read(READ_SIZE):
                if from_host and self._trigger is not None and self._trigger[0](data):
                    mode, self._trigger = self._trigger[1], None
                    self.failed_at_s = self.clock()
                    self.drop() if mode is LinkMode.DOWN else self.silence()
                deliver = self.mode is LinkMode.PASS
                if from_host:
                    self.sent.append(SentChunk(self.clock(), data, deliver))
                if deliver:
                    writer.write(data)
                    await writer.drain()
        writer.transport.abort()  # one side gone: the other one goes too


def modbus_tcp_requests(data: bytes) -> list[tuple[int, int]]:
    """(function code, first register address) of each Modbus TCP request in `data` (whole frames)."""
    requests = []
    while len(data) >= 10:  # MBAP header (7 bytes: transaction, protocol, length, unit), then the PDU
        length = int.from_bytes(data[4:6], "big")
        frame, data = data[: 6 + length], data[6 + length :]
        requests.append((frame[7], int.from_bytes(frame[8:10], "big")))
    return requests


@dataclass(eq=False)
class _Pipe:
    host_side: asyncio.StreamWriter
    device_side: asyncio.StreamWriter

    def abort(self) -> None:
        self.host_side.transport.abort()
        self.device_side.transport.abort()
