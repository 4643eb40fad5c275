"""examples/ (issue 32, item 2) and `shockbench config`: a bench configuration for every supported
combination of devices and a vehicle file per model, each valid against the JSON Schema and read by the real
readers; `config schema` prints that schema and `config check` is the reader, one located line when not."""

from __future__ import annotations

import json
import tomllib
from dataclasses import fields
from pathlib import Path

import cantools
import jsonschema_rs
import pytest

from daq.bench_config import BenchConfig, bench_config_schema, load_bench_config
from daq.formats.vehicle_file import load_vehicle_file
from drivers.exciter.urls import ModbusTarget, parse_exciter_url
from estimator.vehicle import ModelKind
from service.cli.main import main
from service.jobs.bounds import check_vehicle_bounds
from service.simulated_bench import SimulatedBench, vehicle_preset

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
BENCHES = sorted((EXAMPLES / "benches").glob("*.toml"))
VEHICLES = {"car.toml": ModelKind.QUARTER_CAR, "axle.toml": ModelKind.AXLE}
DRIVER_DBC = Path(__file__).resolve().parents[2] / "drivers" / "exciter" / "exciter.dbc"


def drive_of(config: BenchConfig) -> str:
    """The kind of drive a bench uses, telling Modbus TCP from RTU."""
    target = parse_exciter_url(config.exciter.url)
    if isinstance(target, ModbusTarget):
        return f"modbus-{'tcp' if 'tcp' in type(target.link).__name__.lower() else 'rtu'}"
    return config.exciter.kind


@pytest.mark.parametrize("path", BENCHES, ids=lambda p: p.name)
def test_each_bench_example_is_valid_against_the_schema_and_loads(path: Path) -> None:
    document = tomllib.loads(path.read_text(encoding="utf-8"))
    jsonschema_rs.validate(bench_config_schema(), document)  # raises on the first violation
    config = load_bench_config(path)
    assert config.name and config.lasers


def test_the_examples_cover_every_supported_combination() -> None:
    configs = {path.name: load_bench_config(path) for path in BENCHES}
    laser_lines = {name: {laser.url.split("?")[0] for laser in c.lasers} for name, c in configs.items()}
    assert drive_of(configs["zx-rs485-modbus-rtu.toml"]) == "modbus-rtu"
    assert drive_of(configs["zx-rs485-modbus-tcp.toml"]) == "modbus-tcp"
    for name in ("zx-rs485-modbus-rtu.toml", "zx-rs485-modbus-tcp.toml"):
        assert laser_lines[name] == {"serial:///dev/ttyUSB0"}  # every ZX amplifier on one RS-485 line
    assert drive_of(configs["can-drive.toml"]) == "can"
    assert drive_of(configs["cia402-drive.toml"]) == "canopen"
    assert {c.model for c in configs.values()} == set(ModelKind)


def test_the_can_example_carries_the_drivers_dbc() -> None:
    dbc = EXAMPLES / "benches" / "exciter.dbc"
    assert dbc.read_bytes() == DRIVER_DBC.read_bytes()
    frames = {message.name for message in cantools.database.load_file(str(dbc)).messages}
    assert frames == {m.name for m in cantools.database.load_file(str(DRIVER_DBC)).messages} and frames


def test_the_simulated_example_is_what_sim_devices_writes() -> None:
    """The same devices, channels, heads and settings as a simulated bench's own configuration; only the
    ports (which the simulator picks when it starts) differ."""
    example = load_bench_config(EXAMPLES / "benches" / "simulated.toml")
    bench = SimulatedBench(vehicle_preset(str(example.model)), seed=0)
    try:
        served = bench.start()
    finally:
        bench.close()
    assert (example.name, example.model, example.envelope) == (served.name, served.model, served.envelope)
    assert (example.exciter.name, example.exciter.kind) == (served.exciter.name, served.exciter.kind)
    settings = [f.name for f in fields(type(example.lasers[0])) if f.name != "url"]
    assert [[getattr(laser, s) for s in settings] for laser in example.lasers] == [
        [getattr(laser, s) for s in settings] for laser in served.lasers
    ]


@pytest.mark.parametrize(("name", "model"), VEHICLES.items())
def test_each_vehicle_example_loads_within_the_services_bounds(name: str, model: ModelKind) -> None:
    vehicle = load_vehicle_file(EXAMPLES / "vehicles" / name)
    assert vehicle.parameters.model is model
    check_vehicle_bounds(vehicle.parameters, field="vehicle")  # what POST /sweeps would accept


def test_config_schema_prints_the_schema_the_examples_point_to(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["config", "schema"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == bench_config_schema()
    assert json.loads((EXAMPLES / "bench.schema.json").read_text(encoding="utf-8")) == printed
    for path in BENCHES:
        assert "#:schema ../bench.schema.json" in path.read_text(encoding="utf-8")


def test_config_check_says_ok_on_a_good_file(capsys: pytest.CaptureFixture[str]) -> None:
    path = EXAMPLES / "benches" / "can-drive.toml"
    assert main(["config", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert out == f"{path}: OK, bench 'axle lane' (axle, can drive, 6 lasers)\n"


@pytest.mark.parametrize(
    ("old", "new", "expected"),
    [
        ('head = "ZX-LD40"\n\n[[lasers]]\nname = "plate"', 'head = "ZX-LD4"\n\n[[lasers]]\nname = "plate"',
         ":27: [[lasers]] #2 head: unknown head 'ZX-LD4'"),
        ("max_frequency_Hz = 20.0", "max_frequency_Hz = 200.0",
         ":11: [bench.envelope] max_frequency_Hz: bench envelope max_frequency_Hz=200.0 is above the hard"),
        ("unit=1&timeout", "unit=x&timeout", ":15: [exciter] url: bad exciter URL"),
    ],
)  # fmt: skip
def test_config_check_names_file_line_and_key_of_a_bad_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str, expected: str
) -> None:
    text = (EXAMPLES / "benches" / "zx-rs485-modbus-tcp.toml").read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "bench.toml"
    path.write_text(text.replace(old, new), encoding="utf-8")
    assert main(["config", "check", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1
    assert captured.err.startswith(f"shockbench config: error: {path}{expected}"), captured.err


def test_config_check_of_a_missing_file_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["config", "check", str(tmp_path / "none.toml")]) == 2
    assert (
        capsys.readouterr().err
        == f"shockbench config: error: {tmp_path / 'none.toml'}: no such bench configuration\n"
    )
