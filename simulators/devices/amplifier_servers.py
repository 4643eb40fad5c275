"""Simulated amplifier lines on real transports: PtyAmplifierServer (a pseudo-terminal, as a USB RS-485
adapter) and TcpAmplifierServer (a socket, as a serial device server), one thread each."""

from __future__ import annotations

import contextlib
import os
import select
import selectors
import socket
import threading
import tty
from collections.abc import Mapping
from typing import Self

from simulators.devices.amplifier_line import AmplifierLine, next_command
from simulators.devices.amplifier_node import SimulatedAmplifier


class _ServedLine(AmplifierLine):
    """An amplifier line served by one thread: start/stop and the context manager; a transport says how to
    wake its thread (_wake) and what to close (_release)."""

    _thread: threading.Thread

    def start(self) -> Self:
        """Start serving (idempotent)."""
        if not self._thread.is_alive():
            self._thread.start()
        return self

    def stop(self) -> None:
        if self._thread.is_alive():
            self._wake()
            self._thread.join(timeout=2.0)
        self._release()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _wake(self) -> None:
        raise NotImplementedError

    def _release(self) -> None:
        raise NotImplementedError


class PtyAmplifierServer(_ServedLine):
    """Amplifiers on a pseudo-terminal; the driver opens `port_path` (or `device_url(node)`) as a port."""

    def __init__(self, amplifiers: Mapping[int, SimulatedAmplifier], *, echo: bool = False) -> None:
        super().__init__(amplifiers, echo=echo)
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line editing: the line carries binary BCC bytes
        self.port_path = os.ttyname(self._slave)
        self._wake_r, self._wake_w = os.pipe()
        self._thread = threading.Thread(
            target=self._serve, name=f"amplifier-pty {self.port_path}", daemon=True
        )

    def device_url(self, node: int) -> str:
        return f"serial://{self.port_path}?node={node}"

    def _wake(self) -> None:
        os.write(self._wake_w, b"x")

    def _release(self) -> None:
        for fd in (self._master, self._slave, self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)

    def _serve(self) -> None:
        buffer = b""
        while True:
            ready, _, _ = select.select([self._master, self._wake_r], [], [])
            if self._wake_r in ready:
                return
            try:
                chunk = os.read(self._master, 4096)
            except OSError:
                return
            if self.echo:
                os.write(self._master, chunk)
            buffer += chunk
            while True:
                frame, buffer = next_command(buffer)
                if frame is None:
                    break
                reply, _drop = self.reply_to(frame)  # a serial line cannot drop: DROP acts as no reply
                if reply:
                    os.write(self._master, reply)


class TcpAmplifierServer(_ServedLine):
    """Amplifiers behind a TCP socket on 127.0.0.1 (a serial-to-Ethernet converter): the driver connects
    to `url` = socket://127.0.0.1:PORT. Several clients may connect; each is served in turn by one thread."""

    def __init__(
        self,
        amplifiers: Mapping[int, SimulatedAmplifier],
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        echo: bool = False,
    ) -> None:
        super().__init__(amplifiers, echo=echo)
        self._listener = socket.create_server((host, port))
        self._listener.setblocking(False)
        self.host, self.port = self._listener.getsockname()[:2]
        self.connections_accepted = 0
        self._wake_r, self._wake_w = socket.socketpair()
        self._selector = selectors.DefaultSelector()
        self._thread = threading.Thread(target=self._serve, name=f"amplifier-tcp {self.port}", daemon=True)

    @property
    def url(self) -> str:
        return f"socket://{self.host}:{self.port}"

    def device_url(self, node: int) -> str:
        return f"{self.url}?node={node}"

    def _wake(self) -> None:
        self._wake_w.send(b"x")

    def _release(self) -> None:
        for sock in (self._listener, self._wake_r, self._wake_w):
            sock.close()
        self._selector.close()

    def _close_client(self, conn: socket.socket, buffers: dict[socket.socket, bytes]) -> None:
        self._selector.unregister(conn)
        buffers.pop(conn, None)
        conn.close()

    def _serve(self) -> None:
        buffers: dict[socket.socket, bytes] = {}
        self._selector.register(self._listener, selectors.EVENT_READ, "accept")
        self._selector.register(self._wake_r, selectors.EVENT_READ, "wake")
        try:
            while True:
                for key, _ in self._selector.select():
                    if key.data == "wake":
                        return
                    if key.data == "accept":
                        conn, _ = self._listener.accept()
                        conn.setblocking(True)
                        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                        self._selector.register(conn, selectors.EVENT_READ, "client")
                        buffers[conn] = b""
                        self.connections_accepted += 1
                        continue
                    self._serve_client(key.fileobj, buffers)  # type: ignore[arg-type]
        finally:
            for conn in list(buffers):
                self._close_client(conn, buffers)

    def _serve_client(self, conn: socket.socket, buffers: dict[socket.socket, bytes]) -> None:
        try:
            chunk = conn.recv(4096)
        except OSError:
            chunk = b""
        if not chunk:
            self._close_client(conn, buffers)
            return
        if self.echo:
            try:
                conn.sendall(chunk)
            except OSError:
                self._close_client(conn, buffers)
                return
        buffer = buffers[conn] + chunk
        while True:
            frame, buffer = next_command(buffer)
            if frame is None:
                break
            reply, drop = self.reply_to(frame)
            if drop:
                self._close_client(conn, buffers)
                return
            if reply:
                try:
                    conn.sendall(reply)
                except OSError:
                    self._close_client(conn, buffers)
                    return
        buffers[conn] = buffer
