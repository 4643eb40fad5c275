"""Serving the app: the listening socket, and uvicorn's server told to end the job event streams as soon
as a stop begins (uvicorn waits for open connections before the lifespan shutdown, and an event stream
of a running job stays open for as long as the job runs). Its HTTP protocol is uvicorn's h11 one with
the header deadline and the per-address connection cap (service.api.connection_limits) of the app's
settings."""

from __future__ import annotations

import socket
from types import FrameType
from typing import Any

import uvicorn
from fastapi import FastAPI

from service.api.connection_limits import ConnectionLimits, guarded_protocol
from service.api.settings import DEFAULT_HEADER_TIMEOUT_S, DEFAULT_MAX_CONNECTIONS_PER_ADDRESS

SHUTDOWN_GRACE_S = 5.0
"""On a stop, open requests get this long before they are cancelled."""


def bind(host: str, port: int) -> socket.socket:
    """The listening socket, bound here so that port 0 can be reported as the port it became. (TCP as the
    protocol, not 0: asyncio sets TCP_NODELAY on accepted sockets only then; without it every answer
    waits ~40 ms for a delayed ACK.)"""
    host = host.strip("[]")
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


def url_of(sock: socket.socket) -> str:
    host, port = sock.getsockname()[:2]
    return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"


def begin_shutdown(app: FastAPI) -> None:
    """Thread-safe: end the app's event streams (each gets a `closing` event) and a running sweep (the
    plate stops now, not after the open connections have drained; the sweep is failed, "service
    stopped")."""
    services = getattr(app.state, "services", None)
    if services is not None:
        services.manager.close_streams_threadsafe()
        if services.bench is not None:
            services.bench.service_stopping()


def connection_limits(app: FastAPI) -> ConnectionLimits:
    """The limits of the settings the app was made with (service.api.create_app), else the defaults."""
    settings = getattr(app.state, "settings", None)
    return ConnectionLimits(
        header_timeout_s=getattr(settings, "header_timeout_s", DEFAULT_HEADER_TIMEOUT_S),
        max_per_address=getattr(settings, "max_connections_per_address", DEFAULT_MAX_CONNECTIONS_PER_ADDRESS),
    )


class ServiceServer(uvicorn.Server):
    def __init__(
        self,
        app: FastAPI,
        log_level: str = "info",
        *,
        log_config: dict[str, Any] | None = None,
        access_log: bool = False,
    ) -> None:
        """log_config: the service's logging (service.api.logging_setup.log_config, levels included), which
        uvicorn applies instead of its own; None: uvicorn's own at `log_level` (tests). access_log: uvicorn's
        line per request."""
        logging_options: dict[str, Any] = (
            {"log_config": log_config, "log_level": None}
            if log_config is not None
            else {"log_level": log_level}
        )
        super().__init__(
            uvicorn.Config(
                app,
                http=guarded_protocol(connection_limits(app)),
                lifespan="on",
                access_log=access_log,
                timeout_graceful_shutdown=SHUTDOWN_GRACE_S,
                **logging_options,
            )
        )
        self.service_app = app

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        """A signal (Ctrl-C, SIGTERM): uvicorn's handler runs on the main thread, the loop's."""
        begin_shutdown(self.service_app)
        super().handle_exit(sig, frame)

    def stop(self) -> None:
        """Stop from another thread."""
        begin_shutdown(self.service_app)
        self.should_exit = True
