"""Modbus back end against the simulated drive: register map file, URLs, the sweep as register writes, RTU
framing (pty, socket), Modbus exception codes, dropped connections. What every back end promises (start,
sweep, stops, watchdog, drive faults, silence): test_exciter_contract.py."""

from __future__ import annotations

import asyncio
import os
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from drivers.exciter.codes import FAULT_WATCHDOG, ExciterState
from drivers.exciter.errors import (
    ExciterConfigError,
    ExciterConnectionLostError,
    ExciterDeviceExceptionError,
)
from drivers.exciter.interface import ExciterStatus
from drivers.exciter.modbus import ModbusExciter, ModbusRtuLink, ModbusTcpLink
from drivers.exciter.register_map import (
    DEFAULT_REGISTER_MAP_PATH,
    RegisterMap,
    RegisterMapError,
    RegisterSpec,
    RegisterType,
    WordOrder,
    contiguous_runs,
)
from drivers.exciter.urls import ModbusTarget, open_exciter, parse_exciter_url
from estimator.sweep import SweepSettings
from simulators.devices.modbus_exciter import SimulatedModbusExciter
from simulators.plate import EmptyPlate

SWEEP = SweepSettings(start_Hz=0.0, stop_Hz=20.0, amplitude_m=0.004, duration_s=20.0)
TIMEOUT_S = 0.3


def run(scenario: Callable[[], Awaitable[None]]) -> None:
    asyncio.run(scenario())  # type: ignore[arg-type]


@asynccontextmanager
async def tcp_rig(**sim_kwargs: object) -> AsyncIterator[tuple[SimulatedModbusExciter, ModbusExciter]]:
    """Simulated drive on loopback TCP and a driver connected to it, both on the same simulated clock."""
    bench = EmptyPlate()
    async with SimulatedModbusExciter(bench, **sim_kwargs) as sim:  # type: ignore[arg-type]
        exciter = ModbusExciter(
            ModbusTcpLink(sim.host, sim.port), timeout_s=TIMEOUT_S, clock=bench.clock.now_s
        )
        async with exciter:
            yield sim, exciter


async def run_until(
    sim: SimulatedModbusExciter, exciter: ModbusExciter, t_s: float, step_s: float = 0.25
) -> ExciterStatus:
    """Advance simulated time to t_s in steps, polling the status each step as a host would."""
    status = await exciter.status()
    while sim.exciter.clock.now_s() < t_s - 1e-9:
        sim.advance(min(step_s, t_s - sim.exciter.clock.now_s()))
        status = await exciter.status()
    return status


# ---- register map ----------------------------------------------------------------------------------------


def test_default_map_is_documented_and_complete() -> None:
    regmap = RegisterMap.default()
    assert regmap.word_order is WordOrder.BIG
    assert set(regmap.holding) >= {"command", "keepalive", "sweep_start_Hz", "sweep_duration_s", "sweep_law"}
    assert regmap.input["position_m"].type is RegisterType.S32
    assert regmap.input_block() == (0, 5)
    assert all(spec.description for spec in [*regmap.holding.values(), *regmap.input.values()])


@pytest.mark.parametrize("order", list(WordOrder))
@given(value=st.integers(-(2**31), 2**31 - 1))
def test_32_bit_word_order_round_trips(order: WordOrder, value: int) -> None:
    spec = RegisterSpec("position_m", 10, RegisterType.S32, 1e-6, order)
    words = spec.encode(value * 1e-6)
    assert all(0 <= w <= 0xFFFF for w in words)
    assert round(spec.decode(words) / 1e-6) == value
    unsigned = value & 0xFFFFFFFF
    expected = [unsigned >> 16, unsigned & 0xFFFF]
    assert words == (expected if order is WordOrder.BIG else expected[::-1])


@pytest.mark.parametrize("order", ["big", "little"])
def test_word_order_from_file_round_trips_u32(order: str) -> None:
    text = DEFAULT_REGISTER_MAP_PATH.read_text().replace('word_order = "big"', f'word_order = "{order}"')
    regmap = RegisterMap.from_toml(text)
    words = regmap.encode_holding({"sweep_duration_s": 123456.789})
    assert words == ({5: 0x075B, 6: 0xCD15} if order == "big" else {5: 0xCD15, 6: 0x075B})
    decoded = regmap.holding["sweep_duration_s"].decode([words[5], words[6]])
    assert decoded == pytest.approx(123456.789)


def test_per_register_word_order_override() -> None:
    text = DEFAULT_REGISTER_MAP_PATH.read_text().replace(
        'type = "s32"\nscale = 1e-6', 'type = "s32"\nscale = 1e-6\nword_order = "little"'
    )
    regmap = RegisterMap.from_toml(text)
    assert regmap.input["position_m"].word_order is WordOrder.LITTLE
    assert regmap.holding["sweep_duration_s"].word_order is WordOrder.BIG


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("scale = 0.01\n", "scale = 0.01\nscael = 2\n"), "unknown key 'scael' in [holding.sweep_start_Hz]"),
        (('word_order = "big"', 'word_order = "big"\nunit = 1'), "unknown key 'unit' in top level"),
        (("[input.fault_code]", "[input.fault_cod]"), "unknown key 'fault_cod'"),
        (('address = 3\ntype = "s32"\n', 'type = "s32"\n'), "missing key 'address' in [input.position_m]"),
        (("[holding.sweep_law]\naddress = 7", "[holding.sweep_law]\naddress = 6"), "address 6 used by both"),
        (('type = "u32"', 'type = "f32"'), "type must be one of"),
        (('word_order = "big"', 'word_order = "middle"'), "must be 'big' or 'little'"),
        (
            (
                '[holding.command]\naddress = 0\ntype = "u16"\nscale = 1',
                '[holding.command]\naddress = 0\ntype = "u16"\nscale = 2',
            ),
            "its scale must be 1",
        ),
    ],
)
def test_map_errors_name_the_culprit(edit: tuple[str, str], message: str) -> None:
    text = DEFAULT_REGISTER_MAP_PATH.read_text()
    assert edit[0] in text
    with pytest.raises(RegisterMapError) as info:
        RegisterMap.from_toml(text.replace(edit[0], edit[1], 1), source="bench.toml")
    assert message in str(info.value)
    assert "bench.toml" in str(info.value)


def test_map_missing_register_and_file_load(tmp_path: Path) -> None:
    text = DEFAULT_REGISTER_MAP_PATH.read_text()
    start = text.index("[holding.keepalive]")
    broken = text[:start] + text[text.index("[holding.sweep_start_Hz]") :]
    with pytest.raises(RegisterMapError, match=r"missing register \[holding.keepalive\]"):
        RegisterMap.from_toml(broken)
    path = tmp_path / "map.toml"
    path.write_text(text)
    assert RegisterMap.load(path) == RegisterMap.default()
    with pytest.raises(RegisterMapError, match="not valid TOML"):
        RegisterMap.from_toml("word_order = ")


def test_contiguous_runs_and_range_errors() -> None:
    assert contiguous_runs({7: 1, 2: 5, 3: 6, 5: 0, 6: 9}) == [(2, [5, 6]), (5, [0, 9, 1])]
    spec = RegisterSpec("sweep_start_Hz", 2, RegisterType.U16, 0.01)
    with pytest.raises(ValueError, match="does not fit u16"):
        spec.encode(700.0)


# ---- URLs --------------------------------------------------------------------------------------------------


def test_modbus_urls() -> None:
    assert parse_exciter_url("modbus-tcp://127.0.0.1:5020") == ModbusTarget(ModbusTcpLink("127.0.0.1", 5020))
    assert parse_exciter_url("modbus-tcp://drive.local?unit=3&timeout=0.5") == ModbusTarget(
        ModbusTcpLink("drive.local", 502), unit=3, timeout_s=0.5
    )
    rtu = parse_exciter_url("modbus-rtu:///dev/ttyUSB1?baudrate=19200&unit=1&parity=e")
    assert rtu == ModbusTarget(ModbusRtuLink("/dev/ttyUSB1", baudrate=19200, parity="E"), unit=1)
    for bad, message in [
        ("modbus-tcp://127.0.0.1:5020?baud=9600", "unknown parameter"),
        ("modbus-rtu:///dev/ttyUSB1?baudrate=fast", "baudrate must be an integer"),
        ("modbus-rtu://?unit=1", "serial device path"),
        ("modbus-udp://127.0.0.1", "unknown scheme"),
    ]:
        with pytest.raises(ExciterConfigError, match=message):
            parse_exciter_url(bad)


# ---- sweeps over TCP and RTU -------------------------------------------------------------------------------


def test_a_sweep_is_one_write_of_its_mapped_registers() -> None:
    """The register map's side of a sweep (the cycle itself: test_exciter_contract.py)."""

    async def scenario() -> None:
        async with tcp_rig() as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            assert sim.writes == [(2, [0, 2000, 4000, 0, 20000, 0])]  # one write for registers 2..7
            await exciter.start()
            assert sim.writes[-1] == (0, [1])  # START in the command register
            sim.advance(0.25)
            await exciter.status()
            assert sim.exciter.keepalives_received == 1 and (1, [1]) in sim.writes  # register 1: keep-alive

    run(scenario)


def test_full_cycle_over_rtu_on_a_pty_through_the_url() -> None:
    if not hasattr(os, "openpty"):
        pytest.skip("no pseudo-terminals on this platform")

    async def scenario() -> None:
        bench = EmptyPlate()
        async with SimulatedModbusExciter(bench, framer="rtu", unit=7) as sim:
            device = await sim.attach_pty()
            url = f"modbus-rtu://{device}?baudrate=19200&unit=7&timeout={TIMEOUT_S}"
            exciter = await open_exciter(url, clock=bench.clock.now_s)
            try:
                assert isinstance(exciter, ModbusExciter) and isinstance(exciter.link, ModbusRtuLink)
                await exciter.configure_sweep(SWEEP)
                await exciter.start()
                status = await run_until(sim, exciter, 5.0, step_s=0.4)
                assert status.state is ExciterState.RUNNING
                assert status.frequency_Hz == pytest.approx(5.0, abs=0.01)
                await exciter.stop()
                sim.advance(1.0)
                assert (await exciter.status()).state is ExciterState.IDLE
            finally:
                await exciter.close()

    run(scenario)


def test_rtu_framing_over_a_socket_url() -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        async with SimulatedModbusExciter(bench, framer="rtu") as sim:
            link = ModbusRtuLink(sim.serial_url)
            async with ModbusExciter(link, timeout_s=TIMEOUT_S, clock=bench.clock.now_s) as exciter:
                await exciter.configure_sweep(SWEEP)
                await exciter.start()
                sim.advance(0.25)
                status = await exciter.status()
                assert status.state is ExciterState.RUNNING
                assert status.frequency_Hz == pytest.approx(0.25, abs=0.01)
                sim.inject_exception(2)
                with pytest.raises(ExciterDeviceExceptionError) as info:
                    await exciter.status()
                assert info.value.exception_code == 2
                await exciter.emergency_stop()

    run(scenario)


# ---- injected faults: typed error, then the next operation works ------------------------------------------


@pytest.mark.parametrize("code", [2, 4])
def test_modbus_exception_codes(code: int) -> None:
    async def scenario() -> None:
        async with tcp_rig() as (sim, exciter):
            sim.inject_exception(code)
            with pytest.raises(ExciterDeviceExceptionError) as info:
                await exciter.configure_sweep(SWEEP)
            assert info.value.exception_code == code
            assert sim.exciter.commands == []
            await exciter.configure_sweep(SWEEP)
            await exciter.start()
            assert (await exciter.status()).state is ExciterState.RUNNING

    run(scenario)


def test_dropped_connection_is_reported_at_once_and_reconnected() -> None:
    async def scenario() -> None:
        async with tcp_rig() as (sim, exciter):
            await exciter.configure_sweep(SWEEP)
            sim.drop_connection_on_next_request()
            began = time.monotonic()
            with pytest.raises(ExciterConnectionLostError):
                await exciter.status()
            assert time.monotonic() - began < TIMEOUT_S  # not a timeout in disguise
            await exciter.start()
            sim.advance(0.25)
            assert (await exciter.status()).state is ExciterState.RUNNING

    run(scenario)


def test_unreachable_drive_is_connection_lost() -> None:
    async def scenario() -> None:
        async with tcp_rig() as (sim, _):
            port = sim.port
        with pytest.raises(ExciterConnectionLostError, match="cannot connect"):
            await ModbusExciter(ModbusTcpLink("127.0.0.1", port), timeout_s=TIMEOUT_S).open()

    run(scenario)


# ---- keep-alive on the wall clock --------------------------------------------------------------------------


def test_keepalive_comes_only_from_supervision_on_a_wall_clock_drive() -> None:
    """Real time: supervision steps (status reads) feed the drive's watchdog; when the host stops
    supervising, nothing else does (there is no background keep-alive) and the watchdog stops the plate.
    (This replaced a test of the former background keep-alive task, removed on purpose: issue 14, S2.)"""
    from simulators.coupling import SimulatedClock

    async def scenario() -> None:
        bench = EmptyPlate(SimulatedClock(follow_wall_clock=True))
        async with SimulatedModbusExciter(bench, watchdog_timeout_s=0.25) as sim:
            link = ModbusTcpLink(sim.host, sim.port)
            async with ModbusExciter(link, timeout_s=1.0, keepalive_interval_s=0.02) as exciter:
                await exciter.configure_sweep(SWEEP)
                await exciter.start()
                began_s = bench.clock.now_s()
                while sim.exciter.keepalives_received < 20:  # supervise back to back, as a host cycle would
                    status = await exciter.supervise()
                    assert status.state is ExciterState.RUNNING
                assert bench.clock.now_s() - began_s > 0.25  # longer than the watchdog timeout...
                sim.tick()
                assert not sim.exciter.watchdog_tripped  # ...and yet no trip
                assert exciter.keepalives_sent == sim.exciter.keepalives_received

                received = sim.exciter.keepalives_received
                unsupervised_s = bench.clock.now_s()
                while not sim.exciter.watchdog_tripped:  # the host stops supervising (bounded wait)
                    assert bench.clock.now_s() - unsupervised_s < 5.0
                    await asyncio.sleep(0.02)
                    sim.tick()
                assert sim.exciter.keepalives_received == received  # nothing fed it meanwhile
                assert bench.clock.now_s() - unsupervised_s >= 0.25
                status = await exciter.status()
                assert status.fault_code == FAULT_WATCHDOG

    run(scenario)
