"""Open a plate exciter back end from a URL.

    modbus-tcp://127.0.0.1:5020?unit=1&timeout=1.0
    modbus-rtu:///dev/ttyUSB1?baudrate=19200&unit=1&parity=N&stopbits=1&bytesize=8&timeout=1.0
    can://virtual/vcan0            python-can interface 'virtual', channel 'vcan0'
    can://socketcan/can0?bitrate=500000&timeout=0.5&heartbeat_timeout=0.5&base_id=0x680
                                   base_id: first CAN id of the exciter frame set (default 0x680)
    canopen://virtual/vcan0?node=5 a CiA 402 drive, CANopen node 5 (drivers/exciter/cia402.py); also
        host_node=127 (the host's heartbeat node id), bitrate=, timeout= (SDO), heartbeat_timeout= (the
        drive's heartbeat), watchdog_timeout= (the drive's wait for the host's heartbeat),
        transition_timeout= (each state transition, default 0.5), ramp_timeout= (a stop ramp, default 2)

Unknown schemes and query parameters are an ExciterConfigError naming them. `parse_exciter_url` gives the
typed target without touching any transport; `open_exciter` builds the back end and connects it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import parse_qsl, unquote, urlsplit

from drivers.exciter.can_bus import CanExciter
from drivers.exciter.cia402 import DEFAULT_HOST_NODE_ID, Cia402Exciter
from drivers.exciter.cia402_sequences import DEFAULT_RAMP_TIMEOUT_S, DEFAULT_TRANSITION_TIMEOUT_S
from drivers.exciter.envelope import SafetyEnvelope
from drivers.exciter.errors import ExciterConfigError
from drivers.exciter.interface import DEFAULT_KEEPALIVE_INTERVAL_S, PlateExciter
from drivers.exciter.modbus import ModbusExciter, ModbusLink, ModbusRtuLink, ModbusTcpLink
from drivers.exciter.register_map import RegisterMap

DEFAULT_MODBUS_TCP_PORT = 502


@dataclass(frozen=True)
class ModbusTarget:
    """A Modbus drive: link (TCP or RTU), unit id, reply timeout."""

    link: ModbusLink
    unit: int = 1
    timeout_s: float = 1.0


@dataclass(frozen=True)
class CanTarget:
    """A CAN drive: python-can interface and channel, optional bitrate, reply and heartbeat timeouts, and
    the first id of the frame set (None: the DBC's, 0x680)."""

    interface: str
    channel: str
    bitrate: int | None = None
    reply_timeout_s: float = 0.5
    heartbeat_timeout_s: float = 0.5
    base_id: int | None = None


@dataclass(frozen=True)
class Cia402Target:
    """A CiA 402 drive: python-can interface and channel, the drive's CANopen node id, the host's node id
    (its heartbeat is the drive's watchdog feed), optional bitrate, SDO timeout (`timeout_s`, as Modbus),
    the drive-heartbeat timeout, the drive's watchdog timeout, the state-transition and stop-ramp timeouts."""

    interface: str
    channel: str
    node_id: int
    host_node_id: int = DEFAULT_HOST_NODE_ID
    bitrate: int | None = None
    timeout_s: float = 0.5
    heartbeat_timeout_s: float = 0.5
    watchdog_timeout_s: float = 0.5
    transition_timeout_s: float = DEFAULT_TRANSITION_TIMEOUT_S
    ramp_timeout_s: float = DEFAULT_RAMP_TIMEOUT_S


ExciterTarget = ModbusTarget | CanTarget | Cia402Target


def parse_exciter_url(url: str) -> ExciterTarget:
    parts = urlsplit(url)
    query = _Query(url, parse_qsl(parts.query, keep_blank_values=True, strict_parsing=False))
    if parts.scheme == "modbus-tcp":
        if not parts.hostname:
            raise ExciterConfigError(f"{url}: modbus-tcp needs a host")
        try:
            port = parts.port or DEFAULT_MODBUS_TCP_PORT
        except ValueError as exc:
            raise ExciterConfigError(f"{url}: bad port: {exc}") from exc
        target: ExciterTarget = ModbusTarget(
            ModbusTcpLink(parts.hostname, port), query.integer("unit", 1), query.number("timeout", 1.0)
        )
    elif parts.scheme == "modbus-rtu":
        device = unquote(parts.netloc + parts.path)
        if not device:
            raise ExciterConfigError(f"{url}: modbus-rtu needs a serial device path")
        link = ModbusRtuLink(
            device,
            baudrate=query.integer("baudrate", 19200),
            bytesize=query.integer("bytesize", 8),
            parity=query.choice("parity", "N", ("N", "E", "O")),
            stopbits=query.integer("stopbits", 1),
        )
        target = ModbusTarget(link, query.integer("unit", 1), query.number("timeout", 1.0))
    elif parts.scheme == "can":
        interface, channel = parts.netloc, unquote(parts.path.lstrip("/"))
        if not interface or not channel:
            raise ExciterConfigError(f"{url}: expected can://<python-can interface>/<channel>")
        bitrate = query.integer("bitrate", 0) or None
        target = CanTarget(
            interface,
            channel,
            bitrate,
            query.number("timeout", 0.5),
            query.number("heartbeat_timeout", 0.5),
            query.can_id("base_id"),
        )
    elif parts.scheme == "canopen":
        interface, channel = parts.netloc, unquote(parts.path.lstrip("/"))
        if not interface or not channel:
            raise ExciterConfigError(f"{url}: expected canopen://<python-can interface>/<channel>?node=N")
        node = query.integer("node", 0)
        if not node:
            raise ExciterConfigError(f"{url}: canopen:// needs node=<the drive's CANopen node id>")
        host_node = query.integer("host_node", DEFAULT_HOST_NODE_ID)
        if not (1 <= node <= 127 and 1 <= host_node <= 127) or node == host_node:
            raise ExciterConfigError(f"{url}: node and host_node must be two different ids 1..127")
        target = Cia402Target(
            interface,
            channel,
            node,
            host_node,
            query.integer("bitrate", 0) or None,
            query.number("timeout", 0.5),
            query.number("heartbeat_timeout", 0.5),
            query.number("watchdog_timeout", 0.5),
            query.number("transition_timeout", DEFAULT_TRANSITION_TIMEOUT_S),
            query.number("ramp_timeout", DEFAULT_RAMP_TIMEOUT_S),
        )
        if not (target.transition_timeout_s > 0 and target.ramp_timeout_s > 0):
            raise ExciterConfigError(f"{url}: transition_timeout and ramp_timeout must be > 0 (seconds)")
    else:
        raise ExciterConfigError(
            f"{url}: unknown scheme {parts.scheme!r} (modbus-tcp, modbus-rtu, can or canopen)"
        )
    query.reject_leftovers()
    return target


async def open_exciter(
    url: str,
    *,
    envelope: SafetyEnvelope | None = None,
    register_map: RegisterMap | None = None,
    keepalive_interval_s: float | None = DEFAULT_KEEPALIVE_INTERVAL_S,
    clock: Callable[[], float] = time.monotonic,
) -> PlateExciter:
    """Build the back end named by `url` and open it (register_map applies to Modbus only)."""
    target = parse_exciter_url(url)
    exciter: PlateExciter
    if isinstance(target, ModbusTarget):
        exciter = ModbusExciter(
            target.link,
            unit=target.unit,
            register_map=register_map,
            timeout_s=target.timeout_s,
            envelope=envelope,
            keepalive_interval_s=keepalive_interval_s,
            clock=clock,
        )
    elif isinstance(target, Cia402Target):
        exciter = Cia402Exciter(
            target.interface,
            target.channel,
            node_id=target.node_id,
            host_node_id=target.host_node_id,
            bus_kwargs={"bitrate": target.bitrate} if target.bitrate else None,
            reply_timeout_s=target.timeout_s,
            heartbeat_timeout_s=target.heartbeat_timeout_s,
            watchdog_timeout_s=target.watchdog_timeout_s,
            transition_timeout_s=target.transition_timeout_s,
            ramp_timeout_s=target.ramp_timeout_s,
            envelope=envelope,
            keepalive_interval_s=keepalive_interval_s,
            clock=clock,
        )
    else:
        exciter = CanExciter(
            target.interface,
            target.channel,
            bus_kwargs={"bitrate": target.bitrate} if target.bitrate else None,
            reply_timeout_s=target.reply_timeout_s,
            heartbeat_timeout_s=target.heartbeat_timeout_s,
            base_id=target.base_id,
            envelope=envelope,
            keepalive_interval_s=keepalive_interval_s,
            clock=clock,
        )
    await exciter.open()
    return exciter


class _Query:
    """Query parameters consumed one by one, so that unknown ones can be reported."""

    def __init__(self, url: str, pairs: list[tuple[str, str]]) -> None:
        self.url = url
        self.values = dict(pairs)

    def _take(self, name: str) -> str | None:
        return self.values.pop(name, None)

    def integer(self, name: str, default: int) -> int:
        raw = self._take(name)
        try:
            return default if raw is None else int(raw)
        except ValueError:
            raise ExciterConfigError(f"{self.url}: {name} must be an integer, got {raw!r}") from None

    def number(self, name: str, default: float) -> float:
        raw = self._take(name)
        try:
            return default if raw is None else float(raw)
        except ValueError:
            raise ExciterConfigError(f"{self.url}: {name} must be a number, got {raw!r}") from None

    def can_id(self, name: str) -> int | None:
        """An 11-bit CAN id, decimal or 0x-hex; None when absent."""
        raw = self._take(name)
        if raw is None:
            return None
        try:
            value = int(raw, 0)
        except ValueError:
            raise ExciterConfigError(
                f"{self.url}: {name} must be a CAN id such as 0x680, got {raw!r}"
            ) from None
        if not 0 < value <= 0x7FF:
            raise ExciterConfigError(f"{self.url}: {name} must be an 11-bit CAN id 0x001..0x7FF, got {raw!r}")
        return value

    def choice(self, name: str, default: str, allowed: tuple[str, ...]) -> str:
        raw = self._take(name)
        value = default if raw is None else raw.upper()
        if value not in allowed:
            raise ExciterConfigError(f"{self.url}: {name} must be one of {allowed}, got {raw!r}")
        return value

    def reject_leftovers(self) -> None:
        if self.values:
            raise ExciterConfigError(f"{self.url}: unknown parameter(s) {sorted(self.values)}")
