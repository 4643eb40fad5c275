"""The plate drive's Modbus register map chosen in the bench configuration ([exciter] register_map,
relative to the file), so the CLI (--config), the sweep and the service's bench all use it."""

from __future__ import annotations

import asyncio
import tomllib
from pathlib import Path

import pytest

from daq.bench_config import BenchConfigError, dump_bench_config, load_bench_config, parse_bench_config
from drivers.exciter.codes import ExciterState
from drivers.exciter.errors import ExciterDeviceExceptionError
from drivers.exciter.register_map import DEFAULT_REGISTER_MAP_PATH, RegisterMap
from drivers.exciter.urls import open_exciter
from estimator.sweep import SweepSettings
from simulators.devices.modbus_exciter import SimulatedModbusExciter
from simulators.plate import EmptyPlate

HOLDING_SHIFT = 100
INPUT_SHIFT = 50


def shifted_map_text() -> str:
    """The default map with every holding register 100 and every input register 50 further on."""
    document = tomllib.loads(DEFAULT_REGISTER_MAP_PATH.read_text())
    lines = [f'word_order = "{document["word_order"]}"']
    for table, shift in (("holding", HOLDING_SHIFT), ("input", INPUT_SHIFT)):
        for name, spec in document[table].items():
            lines += ["", f"[{table}.{name}]"]
            for key, value in spec.items():
                value = value + shift if key == "address" else value
                lines.append(f"{key} = {value!r}" if not isinstance(value, str) else f'{key} = "{value}"')
    return "\n".join(lines) + "\n"


def bench_text(url: str, register_map: str | None) -> str:
    mapping = f'register_map = "{register_map}"\n' if register_map is not None else ""
    return (
        '[bench]\nname = "b"\nmodel = "quarter-car"\n\n'
        f'[exciter]\nname = "plate"\nurl = "{url}"\n{mapping}\n'
        '[[lasers]]\nname = "body"\nurl = "socket://127.0.0.1:9000?node=1"\n'
        'channel = "x_s"\nhead = "ZX-LD100"\n'
    )


@pytest.fixture
def map_file(tmp_path: Path) -> Path:
    path = tmp_path / "maps" / "drive.toml"
    path.parent.mkdir()
    path.write_text(shifted_map_text())
    return path


def test_the_configured_map_is_the_one_the_drive_is_spoken_to_with(tmp_path: Path, map_file: Path) -> None:
    async def scenario() -> None:
        bench = EmptyPlate()
        async with SimulatedModbusExciter(bench, register_map=RegisterMap.load(map_file)) as sim:
            config_path = tmp_path / "bench.toml"
            config_path.write_text(
                bench_text(f"modbus-tcp://127.0.0.1:{sim.port}?timeout=0.3", "maps/drive.toml")
            )
            config = load_bench_config(config_path)
            assert config.exciter.register_map == str(map_file)  # relative to the configuration file
            exciter = await config.exciter.open(clock=bench.clock.now_s)
            try:
                await exciter.configure_sweep(SweepSettings(duration_s=10.0))
                assert sim.writes[0][0] == 2 + HOLDING_SHIFT  # the sweep block, where the map puts it
                await exciter.start()
                for _ in range(10):  # 2.5 s, supervised every 0.25 s as a sweep would be
                    sim.advance(0.25)
                    status = await exciter.status()
                assert status.state is ExciterState.RUNNING and status.frequency_Hz == pytest.approx(5.0)
                await exciter.stop()
            finally:
                await exciter.close()
            plain = await open_exciter(config.exciter.url)  # the default map: addresses the drive lacks
            try:
                with pytest.raises(ExciterDeviceExceptionError) as info:
                    await plain.status()
                assert info.value.exception_code == 2
            finally:
                await plain.close()

    asyncio.run(scenario())


def test_the_map_survives_a_dump_and_a_reload(tmp_path: Path, map_file: Path) -> None:
    config = parse_bench_config(
        bench_text("modbus-tcp://127.0.0.1:1502", "maps/drive.toml"), base_dir=tmp_path
    )
    again = parse_bench_config(dump_bench_config(config))  # the dump holds the resolved path
    assert again == config and again.exciter.load_register_map() == RegisterMap.load(map_file)
    assert parse_bench_config(bench_text("modbus-tcp://127.0.0.1:1502", None)).exciter.register_map is None


@pytest.mark.parametrize(
    ("url", "register_map", "message"),
    [
        (
            "modbus-tcp://127.0.0.1:1502",
            "maps/none.toml",
            r"bench.toml:8: \[exciter\] register_map: register map .*none.toml: No such file",
        ),
        (
            "modbus-tcp://127.0.0.1:1502",
            "maps/broken.toml",
            r"\[exciter\] register_map: .*broken.toml: unknown key 'unused' in \[holding\]",
        ),
        (
            "can://virtual/vcan0",
            "maps/drive.toml",
            r"\[exciter\] register_map: a register map applies to a Modbus exciter only",
        ),
    ],
)
def test_register_map_errors_name_the_key_and_the_file(
    tmp_path: Path, map_file: Path, url: str, register_map: str, message: str
) -> None:
    (tmp_path / "maps" / "broken.toml").write_text(
        shifted_map_text().replace("[holding.command]", "[holding.unused]")
    )
    path = tmp_path / "bench.toml"
    path.write_text(bench_text(url, register_map))
    with pytest.raises(BenchConfigError, match=message) as info:
        load_bench_config(path)
    assert "\n" not in str(info.value)
