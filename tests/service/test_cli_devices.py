"""`shockbench probe` against simulated benches on real transports (TCP sockets, ptys, Modbus TCP, CAN),
faults reported per device, and `shockbench sim-devices` run as a real process and stopped by a signal."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from daq.bench_config import BenchConfig, LaserConfig, load_bench_config, write_bench_config
from drivers.exciter.codes import CommandCode, LawCode
from estimator.recording import AXLE_CHANNELS
from estimator.vehicle import ModelKind
from service.cli.main import main
from service.simulated_bench import HEAD_MODELS, SimulatedBench, vehicle_preset
from simulators.devices.laser_amplifier import FaultKind, PtyAmplifierServer, SimulatedAmplifier

ROOT = Path(__file__).resolve().parents[2]
STARTUP_TIMEOUT_S = 30.0
"""How long sim-devices may take to write its configuration (interpreter start and imports included)."""


def run_cli(capsys: pytest.CaptureFixture[str], *argv: object) -> tuple[int, str, str]:
    code = main([str(arg) for arg in argv])
    out, err = capsys.readouterr()
    return code, out, err


def probe_json(
    capsys: pytest.CaptureFixture[str], path: Path, *extra: object
) -> tuple[int, list[dict[str, Any]]]:
    code, out, _ = run_cli(capsys, "probe", "--config", path, "--json", *extra)
    return code, json.loads(out)["devices"]


def expected_devices(config: BenchConfig) -> list[tuple[str, str, str]]:
    lasers = [(laser.name, "laser", laser.url) for laser in config.lasers]
    return [(config.exciter.name, "exciter", config.exciter.url), *lasers]


@pytest.fixture
def bench() -> Iterator[SimulatedBench]:
    """Quarter car, Modbus drive, lasers alternately on TCP and pty, noise-free heads, manual clock."""
    with SimulatedBench(vehicle_preset("quarter-car"), lasers="mixed", noise_sigma_m=0.0) as bench:
        yield bench


# ---- probe ------------------------------------------------------------------------------------------------


def test_probe_reads_every_device_during_a_sweep(
    bench: SimulatedBench, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bench.exciter.set_sweep_params(
        start_Hz=2.0, stop_Hz=2.0, amplitude_m=0.003, duration_s=10.0, law=LawCode.LINEAR
    )
    bench.exciter.command(CommandCode.START)
    bench.advance(0.125)  # a quarter period at 2 Hz: the plate at its crest, 3 mm up
    path = write_bench_config(bench.config, tmp_path / "bench.toml")
    code, devices = probe_json(capsys, path)
    assert code == 0
    assert [(d["name"], d["kind"], d["url"]) for d in devices] == expected_devices(bench.config)
    assert all(d["ok"] and "error" not in d for d in devices)
    assert {d["url"].split(":")[0] for d in devices} == {"modbus-tcp", "socket", "serial"}
    exciter = devices[0]["reading"]
    assert (exciter["state"], exciter["fault_code"]) == ("running", 0)
    assert exciter["frequency_Hz"] == pytest.approx(2.0)
    assert exciter["position_m"] == pytest.approx(0.003, abs=1e-6)
    for device, laser in zip(devices[1:], bench.config.lasers, strict=True):
        reading = device["reading"]
        assert reading["model"] == "ZX-LDA11-N"
        assert reading["channel"] == laser.channel
        true_m = bench.physics.position_m(laser.channel)  # the clock has not moved since the probe
        assert reading["channel_position_m"] == pytest.approx(
            true_m, abs=HEAD_MODELS[laser.head].resolution_m / 2
        )
    assert devices[-1]["reading"]["position_m"] == pytest.approx(0.003, abs=1e-6)  # x_r


def test_probe_prints_a_table(
    bench: SimulatedBench, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_bench_config(bench.config, tmp_path / "bench.toml")
    code, out, err = run_cli(capsys, "probe", "--config", path)
    assert (code, err) == (0, "")
    lines = out.splitlines()
    assert lines[-1] == "4 of 4 devices ok"
    for line, (name, kind, url) in zip(lines, expected_devices(bench.config), strict=False):
        assert line.split()[:3] == ["ok", kind, name] and line.endswith(url)
    assert "idle, 0.00 Hz" in lines[0] and "ZX-LDA11-N, status 00/00" in lines[1]


def test_probe_reports_each_faulty_device(
    bench: SimulatedBench, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as unused:  # a port nobody listens on
        unused.bind(("127.0.0.1", 0))
        dead_url = f"socket://127.0.0.1:{unused.getsockname()[1]}?node=1"
    lasers = list(bench.config.lasers)
    lasers[0] = replace(lasers[0], url=dead_url)  # x_s: connection refused
    config = replace(bench.config, lasers=tuple(lasers))
    path = write_bench_config(config, tmp_path / "bench.toml")
    bench.laser_lines["x_t"].inject_fault(FaultKind.NO_REPLY)  # x_t (on a pty): silent until cleared
    bench.exciter.inject_fault(0x42)

    code, devices = probe_json(capsys, path, "--timeout-s", 0.1)
    assert code == 1
    assert [(d["name"], d["kind"], d["url"]) for d in devices] == expected_devices(config)
    exciter, x_s, x_t, x_r = devices
    assert not exciter["ok"] and exciter["error"] == "plate drive in fault: fault code 0x0042"
    assert not x_s["ok"] and x_s["error"].startswith(f"cannot open {dead_url.split('?')[0]}")
    assert not x_t["ok"] and x_t["error"].endswith("no reply within 0.1 s")
    assert x_r["ok"] and x_r["reading"]["model"] == "ZX-LDA11-N"
    for device in devices[:3]:
        assert "reading" not in device and "\n" not in device["error"]

    code, out, _ = run_cli(capsys, "probe", "--config", path, "--timeout-s", 0.1)
    assert code == 1
    assert [line.split()[0] for line in out.splitlines()] == ["FAILED", "FAILED", "FAILED", "ok", "1"]

    bench.laser_lines["x_t"].clear_faults()
    bench.exciter.command(CommandCode.RESET_FAULT)
    code, devices = probe_json(capsys, path)
    assert code == 1 and [d["ok"] for d in devices] == [True, False, True, True]


def test_probe_shares_one_port_between_the_nodes_of_a_line(
    bench: SimulatedBench, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Amplifiers on one RS-485 line (one pty, several nodes): one port, each node asked in turn."""
    wiring = ((1, "x_s"), (2, "x_t"), (3, "x_r"))  # node 3 is not on the line
    amplifiers = {
        n: SimulatedAmplifier.for_channel(bench.physics, ch, noise_sigma_m=0.0) for n, ch in wiring[:2]
    }
    with PtyAmplifierServer(amplifiers) as line:
        lasers = tuple(LaserConfig(f"node {n}", line.device_url(n), ch, "ZX-LD40") for n, ch in wiring)
        config = BenchConfig("rs-485", ModelKind.QUARTER_CAR, bench.config.exciter, lasers)
        code, devices = probe_json(
            capsys, write_bench_config(config, tmp_path / "bench.toml"), "--timeout-s", 0.1
        )
    assert code == 1
    assert [d["ok"] for d in devices] == [True, True, True, False]
    assert devices[3]["error"] == f"node 03 on {line.port_path}: no reply within 0.1 s"


def test_probe_axle_bench_with_a_can_drive(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with SimulatedBench(vehicle_preset("axle"), exciter="can", lasers="pty", seed=7) as bench:
        config = bench.config
        assert [laser.channel for laser in config.lasers] == list(AXLE_CHANNELS)
        assert [laser.head for laser in config.lasers] == ["ZX-LD100"] * 2 + ["ZX-LD40"] * 4
        assert config.exciter.url.startswith("can://virtual/")
        path = write_bench_config(config, tmp_path / "bench.toml")
        code, devices = probe_json(capsys, path)
        assert code == 0 and all(d["ok"] for d in devices) and len(devices) == 7
        assert devices[0]["reading"]["state"] == "idle"

        quick = replace(config, exciter=replace(config.exciter, url=config.exciter.url + "?timeout=0.1"))
        write_bench_config(quick, path)
        bench.can.go_silent()  # type: ignore[union-attr]
        code, devices = probe_json(capsys, path)
        assert code == 1 and [d["ok"] for d in devices] == [False] + [True] * 6
        assert "no answer" in devices[0]["error"] or "heartbeat" in devices[0]["error"]


def test_probe_bad_input_is_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(capsys, "probe", "--config", tmp_path / "missing.toml")
    assert (code, out) == (2, "") and err.startswith("shockbench probe: error: ") and err.count("\n") == 1
    (tmp_path / "bench.toml").write_text('[bench]\nname = "b"\nmodel = "truck"\n')
    code, _, err = run_cli(capsys, "probe", "--config", tmp_path / "bench.toml")
    assert code == 2 and err == f"shockbench probe: error: {tmp_path}/bench.toml: missing [exciter] table\n"
    code, _, err = run_cli(capsys, "probe", "--config", tmp_path / "bench.toml", "--timeout-s", 0)
    assert code == 2 and "--timeout-s must be > 0" in err


# ---- simulated bench --------------------------------------------------------------------------------------


def test_manual_clock_bench_is_deterministic() -> None:
    """What `shockbench sweep --simulated` relies on: same seed and same advances give the same samples,
    and the CAN drive's heartbeats follow the simulated clock."""

    def samples(seed: int) -> list[int]:
        with SimulatedBench(exciter="can", seed=seed) as bench:
            assert bench.can is not None and bench.can.heartbeats_sent == 1  # the first one at start
            out = []
            for _ in range(5):
                bench.advance(0.2)
                out += [amplifier.sample() for amplifier in bench.amplifiers.values()]
            assert bench.can.heartbeats_sent == 11
            return out

    assert samples(3) == samples(3) != samples(4)


def test_sim_devices_refuses_bad_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = tmp_path / "bench.toml"
    cases = [
        (["--can-url", "can://socketcan/vcan0"], "--can-url needs --exciter can"),
        (["--exciter", "can", "--can-url", "modbus-tcp://127.0.0.1:502"], "must be a can:// URL"),
        (["--exciter", "can", "--can-url", "can://virtual"], "expected can://"),
        (["--exciter", "can", "--can-url", "can://socketcan/no-such-can"], "cannot start the simulated"),
    ]
    for extra, message in cases:
        code, _, err = run_cli(capsys, "sim-devices", "--config", config, *extra)
        assert code == 2 and message in err
    code, _, err = run_cli(capsys, "sim-devices", "--config", tmp_path / "nowhere" / "bench.toml")
    assert code == 2 and "does not exist" in err
    assert not config.exists()


@pytest.mark.parametrize("stop_signal", [signal.SIGTERM, signal.SIGINT])
def test_sim_devices_serves_until_signalled(
    stop_signal: signal.Signals, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config_path = tmp_path / "bench.toml"
    log_path = tmp_path / "sim-devices.out"
    command = [sys.executable, "-m", "service.cli.main", "sim-devices", "--config", str(config_path)]
    with log_path.open("w") as log:
        process = subprocess.Popen(
            [*command, "--lasers", "mixed"], cwd=ROOT, stdout=log, stderr=subprocess.STDOUT
        )
    try:
        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        while not config_path.exists():  # written once every device is up
            assert process.poll() is None, f"sim-devices exited early:\n{log_path.read_text()}"
            assert time.monotonic() < deadline, f"no configuration after {STARTUP_TIMEOUT_S} s"
            time.sleep(0.05)
        config = load_bench_config(config_path)
        code, devices = probe_json(capsys, config_path)
        assert code == 0, devices
        assert [(d["name"], d["kind"], d["url"]) for d in devices] == expected_devices(config)
        process.send_signal(stop_signal)
        assert process.wait(timeout=10) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    out = log_path.read_text()
    for _, _, url in expected_devices(config):
        assert url in out
    assert out.rstrip().endswith("sim-devices: stopped")
    assert "Traceback" not in out
