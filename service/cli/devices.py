"""`shockbench sim-devices` and `shockbench probe`: a simulated bench on real transports, and a check that
every device of a bench configuration answers.

    shockbench sim-devices --config bench.toml [--vehicle-preset quarter-car|axle] [--seed N]
                           [--exciter modbus|can] [--lasers tcp|pty|mixed] [--can-url can://socketcan/vcan0]
    shockbench probe --config bench.toml [--json] [--timeout-s 0.5]

sim-devices serves a simulated vehicle bench (service/simulated_bench.py) on a clock that follows the
wall clock, writes the bench configuration naming its devices (format: daq/bench_config/) and runs until
Ctrl-C or SIGTERM, then closes every device and exits 0. probe prints model/state, status and one reading
per device (or, with --json, {"devices": [{"name", "kind", "url", "ok", "reading" | "error"}]}) and exits
1 if any device failed.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from service.cli.errors import EXIT_FAILED, CliError

# service.simulated_bench.VEHICLE_PRESETS' names and daq.probe.DEFAULT_TIMEOUT_S, named here so that
# `shockbench --help` does not import the device stack (tests/service/test_cli_lazy_imports.py checks they
# are the same)
VEHICLE_PRESET_NAMES = ("quarter-car", "axle")
PROBE_TIMEOUT_S = 0.5

if TYPE_CHECKING:
    import signal
    import threading

    from daq.bench_config import BenchConfig
    from daq.probe import DeviceReport

STOP_POLL_S = 0.2
"""How often sim-devices looks at its stop flag (signals set it; this bounds the reaction time)."""


def register(sub: argparse._SubParsersAction) -> None:
    sim = sub.add_parser(
        "sim-devices",
        help="serve a simulated bench (lasers, plate exciter) and write its bench configuration",
        description="Serve a simulated bench on real transports (TCP sockets, ptys, Modbus TCP or CAN), "
        "write the bench configuration naming its devices, and run until Ctrl-C or SIGTERM.",
    )
    sim.add_argument(
        "--config",
        required=True,
        type=Path,
        metavar="BENCH.toml",
        help="where to write the bench configuration (overwritten)",
    )
    sim.add_argument(
        "--vehicle-preset",
        choices=list(VEHICLE_PRESET_NAMES),
        default="quarter-car",
        help="vehicle on the plate (default: quarter-car)",
    )
    sim.add_argument("--seed", type=int, default=0, help="seed of the laser noise (default: 0)")
    sim.add_argument(
        "--exciter",
        choices=["modbus", "can"],
        default="modbus",
        help="plate drive protocol: Modbus TCP on 127.0.0.1, or CAN (default: modbus)",
    )
    sim.add_argument(
        "--lasers",
        choices=["tcp", "pty", "mixed"],
        default="tcp",
        help="amplifier transports: TCP sockets, ptys, or alternately (default: tcp)",
    )
    sim.add_argument(
        "--can-url",
        metavar="URL",
        help="CAN bus of the drive, e.g. can://socketcan/vcan0 (default: a python-can 'virtual' "
        "channel, which only this process can reach)",
    )
    sim.add_argument(
        "--step-s",
        type=float,
        default=None,
        help="integration step of the simulated vehicle, s (default 0.001; 0.002 halves the CPU an axle "
        "needs to keep up with real time, at the price of a few tens of micrometres at 20 Hz)",
    )
    sim.set_defaults(handler=run_sim_devices)

    probe = sub.add_parser(
        "probe",
        help="connect to every device of a bench configuration and print one reading each",
        description="Connect to every device of a bench configuration and print its model or state, "
        "status and one reading. Exits 1 if any device failed.",
    )
    probe.add_argument("--config", required=True, type=Path, metavar="BENCH.toml", help="bench configuration")
    probe.add_argument("--json", action="store_true", help="print a JSON document instead of a table")
    probe.add_argument(
        "--timeout-s",
        type=float,
        default=PROBE_TIMEOUT_S,
        help=f"laser reply timeout per attempt, unless the URL sets one (default: {PROBE_TIMEOUT_S})",
    )
    probe.set_defaults(handler=run_probe)


# ---- sim-devices --------------------------------------------------------------------------------------


def run_sim_devices(args: argparse.Namespace) -> int:
    import can

    from daq.bench_config import write_bench_config
    from estimator.errors import one_line
    from service.simulated_bench import SimulatedBench, vehicle_preset

    can_interface, can_channel = _can_bus(args.can_url, args.exciter)
    if not args.config.parent.is_dir():
        raise CliError(f"directory {str(args.config.parent)!r} does not exist")
    bench = SimulatedBench(
        vehicle_preset(args.vehicle_preset),
        realtime=True,
        exciter=args.exciter,
        lasers=args.lasers,
        seed=args.seed,
        name=f"simulated {args.vehicle_preset}",
        can_interface=can_interface or "virtual",
        can_channel=can_channel,
        step_s=args.step_s,
    )
    with _stop_on_signals() as stop:
        try:
            config = bench.start()
        except (OSError, can.CanError) as exc:  # a port, pty or CAN bus that cannot be had
            raise CliError(f"cannot start the simulated bench: {one_line(exc)}") from exc
        try:
            write_bench_config(
                config, args.config, comment="written by `shockbench sim-devices`: live until it stops"
            )
            _print_served(config, args)
            while not stop.wait(STOP_POLL_S):
                pass
        finally:
            bench.close()
    print("sim-devices: stopped", flush=True)
    return 0


def _can_bus(url: str | None, exciter: str) -> tuple[str | None, str | None]:
    from drivers.exciter.urls import CanTarget, parse_exciter_url

    if url is None:
        return None, None
    if exciter != "can":
        raise CliError("--can-url needs --exciter can")
    target = parse_exciter_url(url)
    if not isinstance(target, CanTarget):
        raise CliError(f"--can-url must be a can:// URL, got {url!r}")
    return target.interface, target.channel


@contextmanager
def _stop_on_signals() -> Iterator[threading.Event]:
    """An event that SIGINT and SIGTERM set (instead of KeyboardInterrupt / termination), for a clean stop.
    Handlers can only be installed from the main thread; elsewhere the event is only set by the caller."""
    import signal  # here and in _quiet_logger: every command imports this module, few need these
    import threading

    stop = threading.Event()
    previous: dict[signal.Signals, Any] = {}
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            previous[signum] = signal.signal(signum, lambda *_: stop.set())
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def _print_served(config: BenchConfig, args: argparse.Namespace) -> None:
    out = [f"{config.name} ({config.model}), clock following the wall clock, seed {args.seed}"]
    out.append(f"  exciter  {config.exciter.name:<14} {config.exciter.url}")
    out += [
        f"  laser    {laser.name:<14} {laser.url}   {laser.channel} {laser.head}" for laser in config.lasers
    ]
    if config.exciter.url.startswith("can://virtual/"):
        out.append(
            "note: the CAN drive is on a python-can 'virtual' bus, which other processes cannot reach; "
            "use --can-url can://socketcan/vcan0 for them"
        )
    out.append(f"bench configuration written to {args.config}")
    out.append("Ctrl-C or SIGTERM stops the devices")
    print("\n".join(out), flush=True)


# ---- probe --------------------------------------------------------------------------------------------


def run_probe(args: argparse.Namespace) -> int:
    from daq.bench_config import load_bench_config
    from daq.probe import all_ok, probe_bench

    if not args.timeout_s > 0:
        raise CliError(f"--timeout-s must be > 0, got {args.timeout_s}")
    config = load_bench_config(args.config)
    with _quiet_logger("pymodbus"):  # failures are reported per device; its own log would repeat them
        reports = probe_bench(config, args.timeout_s)
    if args.json:
        json.dump({"devices": [report.to_json() for report in reports]}, sys.stdout, indent=2)
        print()
    else:
        for report in reports:
            print(
                f"{'ok' if report.ok else 'FAILED':<7} {report.kind:<8} {report.name:<14} "
                f"{_summary(report)}   {report.url}"
            )
        good = sum(report.ok for report in reports)
        print(f"{good} of {len(reports)} devices ok")
    return 0 if all_ok(reports) else EXIT_FAILED


@contextmanager
def _quiet_logger(name: str) -> Iterator[None]:
    import logging

    logger = logging.getLogger(name)
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


def _summary(report: DeviceReport) -> str:
    r = report.reading
    if r is None:
        return str(report.error)
    if report.kind == "exciter":
        return f"{r['state']}, {r['frequency_Hz']:.2f} Hz, plate at {r['position_m'] * 1e3:+.3f} mm"
    return (
        f"{r['model']}, status {r['operating_status']:02X}/{r['related_info']:02X}, "
        f"reads {r['position_m'] * 1e3:+.3f} mm ({r['channel']} {r['channel_position_m'] * 1e3:+.3f} mm)"
    )
