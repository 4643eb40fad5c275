"""The Modbus link after an outage (issue 14, S1), against a plain pymodbus server (not the project's
simulated drive) behind a FaultyLink proxy on 127.0.0.1 that drops or silences the connection.

Before the fix, one timeout broke the link for good while the keep-alive ran: the driver closed the
shared pymodbus client while the keep-alive's request waited in pymodbus's lock, and that request then
closed the connection the next call had just reopened; meanwhile the background keep-alive kept the drive
running. Here a host supervision loop (status read, then keep-alive) and a second status reader share
one driver through the outage. Real sockets and real timeouts: the waits are bounded polls for events,
and the assertions count calls, not seconds."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field

import pytest
from pymodbus.pdu import ModbusPDU
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from drivers.exciter.codes import ExciterState, StateCode
from drivers.exciter.errors import ExciterConnectionLostError, ExciterError, ExciterTimeoutError
from drivers.exciter.modbus import ModbusExciter, ModbusTcpLink
from drivers.exciter.register_map import RegisterMap
from estimator.sweep import SweepSettings
from simulators.devices.faulty_link import FaultyLink, modbus_tcp_requests

TIMEOUT_S = 0.2
KEEPALIVE_INTERVAL_S = 0.05
CYCLE_S = 0.02
"""The host loops' period (pacing, as a supervision cycle has; nothing waits on it)."""
WAIT_LIMIT_S = 10.0
"""Bound of every wait for an event; reaching it fails the test."""
WRITE_SINGLE_REGISTER = 6
READ_INPUT_REGISTERS = 4
REGISTERS = RegisterMap.default()
KEEPALIVE_ADDRESS = REGISTERS.holding["keepalive"].address


@dataclass
class Call:
    began_s: float
    ended_s: float
    ok: bool
    error: str = ""


@dataclass
class Host:
    """A host's calls on the driver: `supervise` (status, checks, keep-alive) or a plain status read."""

    exciter: ModbusExciter
    supervise: bool
    calls: list[Call] = field(default_factory=list)

    async def run(self, stop: asyncio.Event) -> None:
        while not stop.is_set():
            began_s = time.monotonic()
            try:
                status = await (self.exciter.supervise() if self.supervise else self.exciter.status())
                assert status.state is ExciterState.RUNNING
                self.calls.append(Call(began_s, time.monotonic(), True))
            except ExciterError as exc:
                self.calls.append(Call(began_s, time.monotonic(), False, type(exc).__name__))
            await asyncio.sleep(CYCLE_S)

    def failures(self) -> int:
        return sum(not call.ok for call in self.calls)


def plain_drive(received: list[tuple[float, int, int]]) -> ModbusTcpServer:
    """pymodbus's own server with the default register map's blocks: a drive reporting RUNNING at 5 Hz,
    1 mm. `received` logs (time, function code, address) of every request it gets."""
    inputs = {"state": StateCode.RUNNING, "fault_code": 0, "frequency_Hz": 5.0, "position_m": 0.001}
    words = [0] * sum(spec.words for spec in REGISTERS.input.values())
    for name, spec in REGISTERS.input.items():
        words[spec.address : spec.address + spec.words] = spec.encode(inputs[name])
    holding = [0] * sum(spec.words for spec in REGISTERS.holding.values())
    device = SimDevice(
        1,
        simdata=(
            [SimData(0, values=False, datatype=DataType.BITS)],
            [SimData(0, values=False, datatype=DataType.BITS)],
            [SimData(0, values=holding, datatype=DataType.REGISTERS)],
            [SimData(0, values=words, datatype=DataType.REGISTERS)],
        ),
    )

    def trace(sending: bool, pdu: ModbusPDU) -> ModbusPDU:
        if not sending:
            received.append((time.monotonic(), pdu.function_code, getattr(pdu, "address", -1)))
        return pdu

    return ModbusTcpServer(device, address=("127.0.0.1", 0), trace_pdu=trace)


@asynccontextmanager
async def rig(received: list[tuple[float, int, int]]) -> AsyncIterator[tuple[FaultyLink, ModbusExciter]]:
    server = plain_drive(received)
    await server.serve_forever(background=True)
    try:
        port = server.transport.sockets[0].getsockname()[1]  # type: ignore[attr-defined]
        async with FaultyLink("127.0.0.1", port) as link:
            exciter = ModbusExciter(
                ModbusTcpLink("127.0.0.1", link.port),
                timeout_s=TIMEOUT_S,
                keepalive_interval_s=KEEPALIVE_INTERVAL_S,
            )
            await exciter.open()
            try:
                yield link, exciter
            finally:
                await exciter.close()  # a sweep was started: this writes STOP to the plain server too
    finally:
        await server.shutdown()


async def wait_for(predicate: Callable[[], bool]) -> None:
    """Poll for an event with a deadline (no fixed sleep stands in for synchronisation)."""
    deadline_s = time.monotonic() + WAIT_LIMIT_S
    while not predicate():
        assert time.monotonic() < deadline_s, "event did not come"
        await asyncio.sleep(CYCLE_S / 2)


def keepalives_sent(link: FaultyLink, since_s: float, until_s: float) -> int:
    """Keep-alive writes the host sent (whether or not they got through) within [since_s, until_s]."""
    return sum(
        request == (WRITE_SINGLE_REGISTER, KEEPALIVE_ADDRESS)
        for chunk in link.sent
        if since_s <= chunk.at_s <= until_s
        for request in modbus_tcp_requests(chunk.data)
    )


@pytest.mark.parametrize(
    ("fault", "failures", "error"),
    [
        ("silence", 1, "ExciterTimeoutError"),  # the review's case: one timeout
        ("silence", 4, "ExciterTimeoutError"),  # longer than a typical 1 s drive watchdog
        ("drop", 3, "ExciterConnectionLostError"),
    ],
)
def test_link_recovers_after_an_outage_and_the_keepalive_stops_during_it(
    fault: str, failures: int, error: str
) -> None:
    async def scenario() -> None:
        received: list[tuple[float, int, int]] = []
        async with rig(received) as (link, exciter):
            await exciter.configure_sweep(SweepSettings(duration_s=60.0))
            await exciter.start()
            supervisor, reader = Host(exciter, supervise=True), Host(exciter, supervise=False)
            stop = asyncio.Event()
            hosts = asyncio.gather(supervisor.run(stop), reader.run(stop))
            try:
                await wait_for(lambda: sum(c.ok for c in supervisor.calls) >= 5)
                outage_s = time.monotonic()
                link.silence() if fault == "silence" else link.drop()
                await wait_for(lambda: supervisor.failures() >= failures)
                first_failure_s = min(c.ended_s for c in supervisor.calls if not c.ok)
                restored_s = time.monotonic()
                link.restore()
                after = lambda: [c for c in supervisor.calls + reader.calls if c.began_s > restored_s]  # noqa: E731
                await wait_for(lambda: sum(c.ok for c in after()) >= 20)
            finally:
                stop.set()
                await hosts

            # the outage was seen as what it was, by both callers
            assert {c.error for c in supervisor.calls if not c.ok} == {error}
            # S1: every call that began after the link came back succeeded (before the fix: none for 3.2 s)
            assert all(c.ok for c in after()), [c for c in after() if not c.ok]
            # the supervision loop's keep-alive resumed with it, and the drive received it
            assert keepalives_sent(link, restored_s, time.monotonic()) >= 3
            assert any(fc == WRITE_SINGLE_REGISTER and t > restored_s for t, fc, _ in received)
            # S2: no keep-alive left the host between its first failed status read and the restore, so a
            # drive's watchdog sees the host silent for the whole outage
            assert keepalives_sent(link, first_failure_s, restored_s) == 0
            fed = [
                t
                for t, fc, address in received
                if fc == WRITE_SINGLE_REGISTER and address == KEEPALIVE_ADDRESS
            ]
            gap_s = min(t for t in fed if t > restored_s) - max(t for t in fed if t < outage_s + 1e-3)
            assert gap_s >= restored_s - outage_s

    asyncio.run(scenario())


def test_a_timeout_marks_the_link_down_and_the_next_call_reconnects() -> None:
    async def scenario() -> None:
        received: list[tuple[float, int, int]] = []
        async with rig(received) as (link, exciter):
            assert exciter.link_up
            link.silence()
            with pytest.raises(ExciterTimeoutError):
                await exciter.status()
            assert not exciter.link_up  # marked down before anything else may use it
            link.restore()
            before = link.connections_accepted
            assert (await exciter.status()).state is ExciterState.RUNNING
            assert link.connections_accepted == before + 1  # a new connection, not the silenced one
            link.drop()
            with pytest.raises(ExciterConnectionLostError):
                await exciter.status()
            link.restore()
            assert (await exciter.status()).frequency_Hz == pytest.approx(5.0)

    asyncio.run(scenario())
