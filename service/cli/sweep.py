"""`shockbench sweep`: one sweep end to end, recorded to an HDF5 file.

    shockbench sweep --vehicle V.toml --out RUN.h5 --simulated               # simulated bench, in-process
    shockbench sweep --config BENCH.toml --vehicle V.toml --out RUN.h5       # the devices BENCH.toml names

With --simulated and no --config, the simulated devices (the preset vehicle of the vehicle file's model on
the plate, lasers on TCP, a Modbus drive) are started in this process on a manual clock that the sweep
moves: deterministic, and as fast as the machine allows. With --config the devices run on their own (a real
bench, or `shockbench sim-devices`) and the sweep follows the wall clock.

Exit codes: 0 the recording is complete; 1 the sweep ended early (the recording is kept, marked incomplete
with the reason, printed on stderr); 2 the sweep could not begin (bad input, a device missing): nothing
moved and nothing was written; 130 interrupted (the plate was stopped, the recording kept).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from daq.sweep.timing import TIMING_NAMES, SweepTiming
from estimator.sweep import SETTING_NAMES, SweepSettings
from service.cli.declared import Shown, add_options, options, values
from service.cli.errors import EXIT_FAILED, CliError

SWEEP_OPTIONS = options(SweepSettings, SETTING_NAMES, {"amplitude_m": Shown("mm", 1e3)})
"""--start-hz, --stop-hz, --amplitude-mm, --duration-s and --law: SweepSettings' declarations
(estimator.sweep), the amplitude shown in mm."""

TIMING_OPTIONS = options(SweepTiming, TIMING_NAMES)
"""--settle-s and --rest-s: daq.sweep.timing's declarations (standard library only: `--help` stays light)."""

if TYPE_CHECKING:
    from daq.formats.vehicle_file import VehicleFile
    from daq.sweep.model import SweepOutcome, SweepRequest
    from daq.sweep.pacing import Pacing


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "sweep",
        help="run a sweep on the bench and record it (HDF5)",
        description="Zero the sensors at rest, run the plate's sine sweep, record the sweep and the settling "
        "at 1 ms, stop the plate, and write the recording (export it to CSV with `shockbench export`).",
    )
    parser.add_argument("--config", type=Path, metavar="BENCH.toml", help="bench configuration")
    parser.add_argument("--vehicle", type=Path, required=True, metavar="V.toml", help="vehicle file")
    parser.add_argument("--out", type=Path, required=True, metavar="PATH", help="recording to write (.h5)")
    parser.add_argument(
        "--simulated",
        action="store_true",
        help="without --config: start a simulated bench in this process and sweep it",
    )
    add_options(parser, SWEEP_OPTIONS)
    add_options(parser, TIMING_OPTIONS)
    parser.add_argument(
        "--operator",
        type=operator_name,
        default="",
        help="who runs the sweep (kept in the recording; no control characters)",
    )
    parser.add_argument("--seed", type=int, default=0, help="--simulated: seed of the laser noise")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(handler=run_sweep_command)


def operator_name(text: str) -> str:
    """--operator as given, unless it holds a control character or a bidirectional override (which
    would reach a terminal raw wherever the name is shown): argparse's one-line error, exit 2."""
    from service.free_text import problem

    found = problem(text)
    if found is not None:
        raise argparse.ArgumentTypeError(f"the operator's name {found}")
    return text


def _request(args: argparse.Namespace, vehicle: VehicleFile) -> SweepRequest:
    from daq.sweep.model import SweepRequest

    sweep = SweepSettings(**values(args, SWEEP_OPTIONS))
    return SweepRequest(sweep, vehicle=vehicle, operator=args.operator, **values(args, TIMING_OPTIONS))


def run_sweep_command(args: argparse.Namespace) -> int:
    import asyncio

    from daq.bench_config import load_bench_config
    from daq.formats.vehicle_file import load_vehicle_file
    from daq.sweep.pacing import RealtimePacing, SimulatedPacing
    from daq.sweep.plan import plan_sweep
    from daq.sweep.run import run_sweep
    from service.cli.progress import SweepProgressBar
    from service.simulated_bench import SimulatedBench, vehicle_preset

    vehicle = load_vehicle_file(args.vehicle)  # read once, here; the plan carries it to the recording
    request = _request(args, vehicle)
    bar = None if args.quiet else SweepProgressBar()
    bench: SimulatedBench | None = None
    pacing: Pacing
    if args.config is not None:
        config = load_bench_config(args.config)
        pacing = RealtimePacing()
    elif args.simulated:
        bench = SimulatedBench(vehicle_preset(str(vehicle.parameters.model)), seed=args.seed)
        config = bench.start()
        pacing = SimulatedPacing(bench)
    else:
        raise CliError("give --config BENCH.toml, or --simulated to sweep a simulated bench")
    try:
        plan = plan_sweep(config, request, vehicle_field="--vehicle")
        outcome = asyncio.run(run_sweep(config, plan, args.out, pacing=pacing, progress=bar))
    finally:
        if bar is not None:
            bar.close()
        if bench is not None:
            bench.close()
    return _report(outcome)


def _report(outcome: SweepOutcome) -> int:
    print(outcome.summary())
    if not outcome.complete:
        print(f"shockbench sweep: sweep ended early: {outcome.reason}", file=sys.stderr)
        return EXIT_FAILED
    return 0
