"""Modbus back end of the plate exciter: pymodbus async client over TCP or RTU (serial line).

Registers follow a `RegisterMap` (TOML, see default_register_map.toml). The sweep goes out as one write
per run of consecutive holding registers, commands and keep-alives as single-register writes, and the
status is one read of the input-register block.

Every request, keep-alives included, goes through one asyncio.Lock of the driver: one request on the
link at a time, and no request can wait inside pymodbus while another one closes the link under it.

Error translation (pymodbus 3.16): an exception response -> ExciterDeviceExceptionError with the Modbus
exception code; no response within `timeout_s` -> ExciterTimeoutError; a connection that drops during a
request -> ExciterConnectionLostError at once (not after the timeout). After a timeout or a drop the link
is marked down first, then its pymodbus client is closed and dropped: no late answer can be mistaken for
the next request's, and the next operation connects a new client. (Reconnecting the same client is not
safe: asyncio delivers the old socket's connection_lost later, to the same pymodbus protocol object, which
then closes the new socket.) pymodbus's own automatic reconnection is disabled (reconnect_delay=0) and it
does not retry (retries=0): the caller decides.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

from pymodbus import FramerType
from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.pdu import ModbusPDU

from drivers.exciter.codes import CommandCode, LawCode
from drivers.exciter.envelope import SafetyEnvelope
from drivers.exciter.errors import (
    ExciterConnectionLostError,
    ExciterDeviceExceptionError,
    ExciterError,
    ExciterTimeoutError,
)
from drivers.exciter.interface import DEFAULT_KEEPALIVE_INTERVAL_S, ExciterStatus, PlateExciter
from drivers.exciter.register_map import RegisterMap, contiguous_runs
from estimator.sweep import SweepSettings


@dataclass(frozen=True)
class ModbusTcpLink:
    """Modbus TCP: drive at host:port."""

    host: str
    port: int = 502

    def __str__(self) -> str:
        return f"modbus-tcp://{self.host}:{self.port}"


@dataclass(frozen=True)
class ModbusRtuLink:
    """Modbus RTU on a serial line. `port` is a device path or any pyserial URL (socket://host:port)."""

    port: str
    baudrate: int = 19200
    bytesize: int = 8
    parity: str = "N"
    stopbits: int = 1

    def __str__(self) -> str:
        return f"modbus-rtu://{self.port}?baudrate={self.baudrate}"


ModbusLink = ModbusTcpLink | ModbusRtuLink
ModbusClient = AsyncModbusTcpClient | AsyncModbusSerialClient


@dataclass
class _Connection:
    """One connected pymodbus client and the event its trace_connect hook sets when it drops."""

    client: ModbusClient
    dropped: asyncio.Event = field(default_factory=asyncio.Event)


class ModbusExciter(PlateExciter):
    """Plate exciter reached over Modbus TCP or RTU; `unit` is the Modbus device id of the drive."""

    def __init__(
        self,
        link: ModbusLink,
        *,
        unit: int = 1,
        register_map: RegisterMap | None = None,
        timeout_s: float = 1.0,
        envelope: SafetyEnvelope | None = None,
        keepalive_interval_s: float | None = DEFAULT_KEEPALIVE_INTERVAL_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__(envelope=envelope, keepalive_interval_s=keepalive_interval_s, clock=clock)
        self.link = link
        self.unit = unit
        self.register_map = register_map or RegisterMap.default()
        self.timeout_s = timeout_s
        self._lock = asyncio.Lock()
        self._connection: _Connection | None = None
        self._open = False

    @property
    def link_up(self) -> bool:
        """A connection is established and has not been marked down."""
        connection = self._connection
        return connection is not None and connection.client.connected and not connection.dropped.is_set()

    async def open(self) -> None:
        async with self._lock:
            self._open = True
            await self._connected()

    def _make_client(self, dropped: asyncio.Event) -> ModbusClient:
        def on_link_change(connected: bool) -> None:
            """pymodbus trace_connect hook of this client only: a drop fails its pending request at once."""
            if not connected:
                dropped.set()

        common = dict(timeout=self.timeout_s, retries=0, reconnect_delay=0, trace_connect=on_link_change)
        if isinstance(self.link, ModbusTcpLink):
            return AsyncModbusTcpClient(self.link.host, port=self.link.port, **common)  # type: ignore[arg-type]
        return AsyncModbusSerialClient(
            self.link.port,
            framer=FramerType.RTU,
            baudrate=self.link.baudrate,
            bytesize=self.link.bytesize,
            parity=self.link.parity,
            stopbits=self.link.stopbits,
            **common,  # type: ignore[arg-type]
        )

    async def _connected(self) -> _Connection:
        """The live connection, or a new client connected now (call with the lock held)."""
        if not self._open:
            raise ExciterError("Modbus exciter is not open")
        if self.link_up:
            assert self._connection is not None
            return self._connection
        self._mark_down()
        dropped = asyncio.Event()
        connection = _Connection(self._make_client(dropped), dropped)
        if not await connection.client.connect():
            connection.client.close()
            raise ExciterConnectionLostError(f"cannot connect to the plate drive at {self.link}")
        self._connection = connection
        return connection

    def _mark_down(self) -> None:
        """Forget the current connection first (so nothing uses it again), then close it."""
        connection, self._connection = self._connection, None
        if connection is not None:
            connection.client.close()

    async def _request(self, what: str, call: Callable[[ModbusClient], Awaitable[ModbusPDU]]) -> ModbusPDU:
        """Run one pymodbus request under the driver's lock; translate every failure into a typed
        ExciterError, marking the link down on a timeout or a drop."""
        async with self._lock:
            connection = await self._connected()
            request = asyncio.ensure_future(call(connection.client))
            dropped = asyncio.ensure_future(connection.dropped.wait())
            try:
                await asyncio.wait({request, dropped}, return_when=asyncio.FIRST_COMPLETED)
            finally:
                for task in (request, dropped):
                    task.cancel()
                await asyncio.gather(request, dropped, return_exceptions=True)
            if not (request.done() and not request.cancelled()):
                self._mark_down()
                raise ExciterConnectionLostError(f"{what}: connection to {self.link} lost")
            try:
                response = request.result()
            except ConnectionException as exc:
                self._mark_down()
                raise ExciterConnectionLostError(f"{what}: {self.link}: {exc}") from exc
            except ModbusIOException as exc:
                self._mark_down()  # a late answer must not be taken for the next request's
                raise ExciterTimeoutError(
                    f"{what}: no answer from {self.link} within {self.timeout_s} s"
                ) from exc
            except ModbusException as exc:
                raise ExciterError(f"{what}: {exc}") from exc
        if response.isError():
            code = int(getattr(response, "exception_code", 0))
            raise ExciterDeviceExceptionError(code, f"{what} refused by the drive at {self.link}")
        return response

    async def _write_holding(self, what: str, values: dict[str, float]) -> None:
        runs = contiguous_runs(self.register_map.encode_holding(values))  # all encoded before any write
        for address, words in runs:
            if len(words) == 1:
                await self._request(
                    what, lambda c, a=address, w=words[0]: c.write_register(a, w, device_id=self.unit)
                )
            else:
                await self._request(
                    what, lambda c, a=address, ws=words: c.write_registers(a, ws, device_id=self.unit)
                )

    async def _write_sweep(self, settings: SweepSettings) -> None:
        await self._write_holding(
            "configure sweep",
            {
                "sweep_start_Hz": settings.start_Hz,
                "sweep_stop_Hz": settings.stop_Hz,
                "sweep_amplitude_m": settings.amplitude_m,
                "sweep_duration_s": settings.duration_s,
                "sweep_law": LawCode.of(settings.law),
            },
        )

    async def _send_command(self, command: CommandCode) -> None:
        await self._write_holding(f"command {command.name}", {"command": command})

    async def _send_keepalive(self, counter: int) -> None:
        await self._write_holding("keep-alive", {"keepalive": counter})

    async def _read_status(self) -> ExciterStatus:
        start, count = self.register_map.input_block()
        response = await self._request(
            "read status", lambda c: c.read_input_registers(start, count=count, device_id=self.unit)
        )
        if len(response.registers) != count:
            raise ExciterError(f"read status: expected {count} registers, got {len(response.registers)}")
        values = self.register_map.decode_inputs(start, response.registers)
        return ExciterStatus.from_codes(
            values["state"], values["fault_code"], values["frequency_Hz"], values["position_m"]
        )

    async def _close_transport(self) -> None:
        async with self._lock:
            self._open = False
            connection, self._connection = self._connection, None
            if connection is not None:
                connection.client.close()
