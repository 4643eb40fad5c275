"""Benchmark: what `identify --refine` trades on recordings whose vehicle has an effect the model lacks. The
refinement (estimator.output_error.refine_on_output_error: a short DE on the free-simulation gap) lowers the
gap the model leaves; does the damper curve it reports stay the vehicle's damper, or take up the missing
effect?

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_refine_curve.py --per-class 6 --jobs 2 \
        --cache /tmp/foreign-dev-cache

On the foreign world's DEV draws (simulators.foreign: Stribeck and LuGre friction, bump stops, sensor lags,
averages and gains, lagging dampers, asymmetric axles, wrong stated rates, unrecorded forces; draws simulated
into `--cache` or read from there, read back with the project's readers), each recording is identified from
its vehicle file as `shockbench identify` does, and again with `--refine`. Per draw: the gap (validate's,
% of the response RMS) and the worst corner's damper curve against the draw's true damper table (RMS over the
excited velocities, % of the table's peak there: the tests' measure, cases.curve_error_percent). The DEV
namespace is used: this measures an option, it designs nothing (the frozen held-out draws are for the
doctor's figures). The lab rig world's counterpart is bench_lab_rig.py's curve columns.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimator"))

from cases import PointwiseForce, curve_error_percent  # the tests' measure of a curve against the truth

from simulators.foreign.draws import CLASSES, draw
from simulators.foreign.manifest import draw_files, namespace_entropy


@dataclass(frozen=True)
class Pair:
    """One draw identified without and with the refinement: gaps in % of the response RMS, the worst
    corner's curve error in % of its true damper's peak."""

    draw_id: str
    label: str
    gap_percent: float
    refined_gap_percent: float
    curve_percent: float
    refined_curve_percent: float

    @property
    def changed(self) -> bool:
        """The refinement moved the model (its DE found a lower gap than the equation fit's)."""
        return self.refined_gap_percent < self.gap_percent


def run_draw(label: str, index: int, cache: str, entropy: int) -> Pair:
    """Identify one DEV draw both ways (a worker process)."""
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.identify import IdentifyOptions, identify
    from estimator.validation import validate

    truth = draw_files("dev", entropy, label, index, cache)
    recording, vehicle = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
    corners = draw(entropy, label, index).vehicle.base.corners
    figures = []
    for refine in (False, True):
        result = identify(recording, vehicle, IdentifyOptions(intervals=False, refine_output_error=refine))
        errors = [
            curve_error_percent(curve, PointwiseForce(corner.damper.force), velocity)
            for curve, corner, velocity in zip(
                result.model.curves, corners, result.system.velocity_m_s, strict=True
            )
        ]
        figures += [100.0 * validate(result.model, recording).gap_ratio, max(errors)]
    gap, curve, refined_gap, refined_curve = figures
    return Pair(truth["id"], label, gap, refined_gap, curve, refined_curve)


def print_report(pairs: list[Pair]) -> None:
    print("\n| draw | gap: identify → --refine | curve against the true damper: identify → --refine |")
    print("|---|---|---|")
    for p in pairs:
        print(
            f"| {p.draw_id} | {p.gap_percent:.1f}% → {p.refined_gap_percent:.1f}% | "
            f"{p.curve_percent:.2f}% → {p.refined_curve_percent:.2f}% |"
        )
    print(
        "\n| class | draws | refinement moved the model | of those: curve farther from the damper | "
        "median gap → | median curve error → |"
    )
    print("|---|---:|---:|---:|---|---|")
    for label in [*CLASSES, "all"]:
        group = [p for p in pairs if label in ("all", p.label)]
        moved = [p for p in group if p.changed]
        if not group:
            continue
        worse = sum(p.refined_curve_percent > p.curve_percent for p in moved)
        print(f"| {label} | {len(group)} | {len(moved)} | {worse}/{len(moved)} | {_medians(moved)} |")


def _medians(moved: list[Pair]) -> str:
    """ "gap → refined gap | curve → refined curve" medians over the draws the refinement moved."""
    if not moved:
        return "— | —"
    gap = statistics.median(p.gap_percent for p in moved)
    refined_gap = statistics.median(p.refined_gap_percent for p in moved)
    curve = statistics.median(p.curve_percent for p in moved)
    refined_curve = statistics.median(p.refined_curve_percent for p in moved)
    return f"{gap:.1f}% → {refined_gap:.1f}% | {curve:.2f}% → {refined_curve:.2f}%"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-class", type=int, default=6, help="DEV draws 0..N-1 of each class")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes")
    parser.add_argument("--cache", required=True, help="folder of the simulated draws (made if missing)")
    args = parser.parse_args()
    if args.per_class < 1:
        parser.error("--per-class must be at least 1")
    entropy = namespace_entropy("dev")
    print(
        f"machine: {platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}; "
        f"DEV draws 0-{args.per_class - 1} of {len(CLASSES)} classes, {args.jobs} jobs"
    )
    start = time.perf_counter()
    Path(args.cache).mkdir(parents=True, exist_ok=True)
    work = [(label, index) for label in CLASSES for index in range(args.per_class)]
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [pool.submit(run_draw, label, index, args.cache, entropy) for label, index in work]
        pairs = [f.result() for f in futures]
    print_report(pairs)
    print(f"total wall time {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
