"""Simulated plate drive speaking Modbus: a pymodbus server on loopback whose registers follow the same
RegisterMap as the driver (drivers/exciter/register_map.py).

Holding-register writes reach the `SimulatedExciter` (sweep settings, commands, keep-alive); every read of
the input registers is refreshed from the bench first. TCP framing by default; `framer="rtu"` serves RTU
frames over the TCP socket (pyserial URL socket://127.0.0.1:port) and `attach_pty()` puts the drive on a
pseudo-terminal, so an RTU client opens a real serial device path.

Fault injection (each one affects the next request(s) only):
    inject_exception(code)          answer with a Modbus exception code (2 illegal address, 4 device failure)
    drop_connection_on_next_request the server aborts the TCP connection instead of answering
    drop_responses(n)               requests are executed but their answers are lost (client times out)
    inject_drive_fault(code)        the drive trips (SimulatedPlate.set_fault) and reports `code`
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import tty
from collections.abc import Callable
from typing import Literal

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.exciter.codes import StateCode
from drivers.exciter.register_map import RegisterMap, RegisterSpec
from simulators.coupling import PlatePhysics
from simulators.devices.exciter import (
    DEFAULT_WATCHDOG_TIMEOUT_S,
    ExciterRefusalError,
    RefusalReason,
    SimulatedExciter,
)

_READ_INPUT_REGISTERS = 4
_SWEEP_REGISTERS = {
    "sweep_start_Hz": "start_Hz",
    "sweep_stop_Hz": "stop_Hz",
    "sweep_amplitude_m": "amplitude_m",
    "sweep_duration_s": "duration_s",
    "sweep_law": "law",
}
_EXCEPTION_FOR = {
    RefusalReason.FAULT: ExcCodes.DEVICE_FAILURE,
    RefusalReason.NOT_CONFIGURED: ExcCodes.ILLEGAL_VALUE,
    RefusalReason.INVALID_VALUE: ExcCodes.ILLEGAL_VALUE,
}


class SimulatedModbusExciter:
    """A plate drive on a loopback Modbus server. Use `async with` (or start()/close()); `port` is the
    bound TCP port (a free one by default)."""

    def __init__(
        self,
        bench: PlatePhysics,
        *,
        register_map: RegisterMap | None = None,
        unit: int = 1,
        framer: Literal["socket", "rtu"] = "socket",
        host: str = "127.0.0.1",
        port: int = 0,
        watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
    ) -> None:
        self.exciter = SimulatedExciter(bench, watchdog_timeout_s)
        self.register_map = register_map or RegisterMap.default()
        self.unit = unit
        self.framer = FramerType.RTU if framer == "rtu" else FramerType.SOCKET
        self.host = host
        self.port = port
        self.writes: list[tuple[int, list[int]]] = []
        """Every holding-register write as (address, words), in arrival order."""
        self.requests = 0
        self._exceptions: list[ExcCodes] = []
        self._drop_connection = False
        self._drop_responses = 0
        self._server: ModbusTcpServer | None = None
        self._bridges: list[_PtyBridge] = []
        self._activity = asyncio.Event()

    # ---- lifecycle ----------------------------------------------------------------------------------

    async def start(self) -> None:
        self._server = ModbusTcpServer(
            self._device(),
            address=(self.host, self.port),
            framer=self.framer,
            trace_packet=self._trace_packet,
        )
        await self._server.serve_forever(background=True)
        self.port = self._server.transport.sockets[0].getsockname()[1]  # type: ignore[attr-defined]

    async def close(self) -> None:
        for bridge in self._bridges:
            bridge.close()
        self._bridges.clear()
        if self._server is not None:
            await self._server.shutdown()
            self._server = None

    async def __aenter__(self) -> SimulatedModbusExciter:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    @property
    def url(self) -> str:
        """Where the driver finds this drive (TCP framing only; for RTU see serial_url / attach_pty)."""
        return f"modbus-tcp://{self.host}:{self.port}?unit={self.unit}"

    @property
    def serial_url(self) -> str:
        """pyserial URL of the server socket, for an RTU client (framer="rtu")."""
        return f"socket://{self.host}:{self.port}"

    async def attach_pty(self) -> str:
        """Serve this (framer="rtu") drive on a new pseudo-terminal; returns the serial device path."""
        if self.framer is not FramerType.RTU:
            raise RuntimeError("attach_pty needs framer='rtu'")
        bridge = await _PtyBridge.open(self.host, self.port)
        self._bridges.append(bridge)
        return bridge.path

    async def wait_until(self, predicate: Callable[[], bool], timeout_s: float) -> None:
        """Wait until predicate() holds, re-checking after each request the drive handles (TimeoutError
        after timeout_s)."""
        async with asyncio.timeout(timeout_s):
            while not predicate():
                self._activity.clear()
                await self._activity.wait()

    # ---- time ---------------------------------------------------------------------------------------

    def tick(self) -> None:
        """Run the drive's cyclic checks (watchdog) at the current simulated time."""
        self.exciter.tick()

    def advance(self, dt_s: float) -> None:
        """Advance the simulated clock by dt_s, then tick."""
        self.exciter.clock.advance(dt_s)
        self.exciter.tick()

    async def run(self, period_s: float = 0.01) -> None:
        """Tick forever (for a drive served on a wall-clock SimulatedClock)."""
        while True:
            self.tick()
            await asyncio.sleep(period_s)

    # ---- fault injection ----------------------------------------------------------------------------

    def inject_exception(self, code: int, count: int = 1) -> None:
        self._exceptions.extend([ExcCodes(code)] * count)

    def drop_connection_on_next_request(self) -> None:
        self._drop_connection = True

    def drop_responses(self, count: int = 1) -> None:
        self._drop_responses += count

    def inject_drive_fault(self, code: int) -> None:
        self.exciter.inject_fault(code)

    # ---- pymodbus hooks -----------------------------------------------------------------------------

    def _device(self) -> SimDevice:
        def block(specs: list[RegisterSpec]) -> list[SimData]:
            return [SimData(s.address, values=[0] * s.words, datatype=DataType.REGISTERS) for s in specs]

        unused_bits = [SimData(0, values=False, datatype=DataType.BITS)]
        return SimDevice(
            self.unit,
            simdata=(
                unused_bits,
                list(unused_bits),
                block(list(self.register_map.holding.values())),
                block(list(self.register_map.input.values())),
            ),
            action=self._action,
        )

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if sending and self._drop_responses:
            self._drop_responses -= 1
            return b""
        return data

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> ExcCodes | None:
        """Called by pymodbus for every register access, before the answer is built."""
        self.requests += 1
        self._activity.set()
        self.exciter.tick()
        if self._exceptions:
            return self._exceptions.pop(0)
        if self._drop_connection:
            self._drop_connection = False
            self._abort_connections()
            return None
        if function_code == _READ_INPUT_REGISTERS:
            self._refresh_inputs(start_address, registers)
        elif set_values:
            words = [int(v) for v in set_values]
            self.writes.append((address, words))
            window = slice(address - start_address, address - start_address + len(words))
            registers[window] = words  # the new contents, for the drive to act on
            try:
                self._apply_write(address, len(words), start_address, registers)
            except ExciterRefusalError as refusal:
                return _EXCEPTION_FOR[refusal.reason]
            finally:
                set_values[:] = registers[window]  # pymodbus stores set_values: keep the drive's edits
        return None

    def _abort_connections(self) -> None:
        assert self._server is not None
        for connection in list(self._server.active_connections.values()):
            if connection.transport is not None:
                connection.transport.abort()  # type: ignore[attr-defined]

    def _refresh_inputs(self, start_address: int, registers: list[int]) -> None:
        status = self.exciter.status()
        values = {
            "state": StateCode.of(status.state),
            "fault_code": status.fault_code,
            "frequency_Hz": status.frequency_Hz,
            "position_m": status.position_m,
        }
        for name, spec in self.register_map.input.items():
            offset = spec.address - start_address
            registers[offset : offset + spec.words] = spec.encode(values[name])

    def _apply_write(self, address: int, count: int, start_address: int, registers: list[int]) -> None:
        def touched(spec: RegisterSpec) -> bool:
            return spec.address < address + count and address < spec.address + spec.words

        def value(spec: RegisterSpec) -> float:
            offset = spec.address - start_address
            return spec.decode(registers[offset : offset + spec.words])

        holding = self.register_map.holding
        params = {
            field: value(holding[name]) for name, field in _SWEEP_REGISTERS.items() if touched(holding[name])
        }
        if params:
            self.exciter.set_sweep_params(**params)
        if touched(holding["keepalive"]):
            self.exciter.keepalive(int(value(holding["keepalive"])))
        if touched(holding["command"]):
            command = holding["command"]
            code = int(value(command))
            offset = command.address - start_address
            registers[offset : offset + command.words] = command.encode(0)  # the drive clears the command
            if code:
                self.exciter.command(code)


class _PtyBridge:
    """Pumps bytes between a pseudo-terminal and the RTU-framed server socket: the simulated drive then
    sits behind a real serial device path (/dev/pts/N) that pyserial and pymodbus open as usual."""

    def __init__(
        self, master_fd: int, slave_fd: int, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        self.master_fd, self.slave_fd = master_fd, slave_fd
        self.path = os.ttyname(slave_fd)
        self._writer = writer
        self._loop = asyncio.get_running_loop()
        self._loop.add_reader(master_fd, self._from_pty)
        self._to_pty = self._loop.create_task(self._pump_to_pty(reader), name=f"pty bridge {self.path}")

    @classmethod
    async def open(cls, host: str, port: int) -> _PtyBridge:
        master_fd, slave_fd = os.openpty()
        tty.setraw(master_fd)
        tty.setraw(slave_fd)
        os.set_blocking(master_fd, False)
        reader, writer = await asyncio.open_connection(host, port)
        return cls(master_fd, slave_fd, reader, writer)

    def _from_pty(self) -> None:
        try:
            data = os.read(self.master_fd, 4096)
        except OSError:  # EIO while no one holds the terminal open: nothing to forward
            return
        self._writer.write(data)

    async def _pump_to_pty(self, reader: asyncio.StreamReader) -> None:
        while data := await reader.read(4096):
            os.write(self.master_fd, data)

    def close(self) -> None:
        self._loop.remove_reader(self.master_fd)
        self._to_pty.cancel()
        self._writer.close()
        for fd in (self.master_fd, self.slave_fd):
            with contextlib.suppress(OSError):
                os.close(fd)
