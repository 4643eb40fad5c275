"""Benchmark: `identify --solver de` on vehicles lighter than a motorcycle (the lab quarter-car rig world,
simulators/lab_rig), with the search box scaled to the vehicle's mass (estimator.de_search.box_scale) and,
side by side in the same run, with the box as drawn for cars and motorcycles (box_scale held at 1).

    .venv/bin/python benchmarks/bench_de_light.py --rigs 10 --cache /tmp/de-light

Per rig, drawn at random from the dev seeds (0-999; --seed picks the draw): mass-only identify on run A
(every rate free) by DE, its certified gap (how far its objective is above the exact solver's lower bound,
as a fraction of the objective) and its model validated on run B (held-out gap, % of B's response RMS).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np
from bench_lab_rig import rig_files  # the lab rig's runs, written and cached as that benchmark does

from daq.formats.recording_csv import read_recording_csv
from daq.formats.vehicle_file import read_vehicle
from estimator import de_search
from estimator.identify import IdentifyOptions, identify
from estimator.identify_options import Solver
from estimator.model_io import model_from_json
from estimator.recording import Recording
from estimator.validation import validate
from estimator.vehicle import VehicleParameters

WITHIN = 0.01  # a certified gap counted as "at the optimum"
RUN_S = 16.0  # input length of each run (s), bench_lab_rig's default


def runs(seed: int, folder: Path) -> tuple[Recording, Recording, VehicleParameters]:
    """Runs A and B of lab rig `seed` (bench_lab_rig's files: simulated once, kept in `folder`, which a
    bench_lab_rig --cache folder can be) and its mass-only vehicle file."""
    _, files, _ = rig_files(seed, str(folder), RUN_S)
    a, b = (read_recording_csv(files[run].csv) for run in "AB")
    return a, b, read_vehicle(files["A"].mass_only_toml)


def de_outcome(a: Recording, b: Recording, vehicle: VehicleParameters) -> tuple[float, float, float]:
    """DE's certified gap, the held-out gap on B and DE's wall time (s)."""
    start = time.perf_counter()
    result = identify(a, vehicle, IdentifyOptions(solver=Solver.DE, intervals=False))
    seconds = time.perf_counter() - start
    out = json.loads(json.dumps(result.to_json()))
    return out["certified_gap"], validate(model_from_json(out), b).gap_ratio, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rigs", type=int, default=10)
    parser.add_argument("--seed", type=int, default=2026, help="of the random draw of dev rigs")
    parser.add_argument("--cache", default="/tmp/de-light", help="folder that keeps the simulated runs")
    args = parser.parse_args()
    folder = Path(args.cache)
    folder.mkdir(parents=True, exist_ok=True)
    seeds = sorted(int(s) for s in np.random.default_rng(args.seed).choice(1000, args.rigs, replace=False))
    scaled_box = de_search.box_scale
    rows = []
    print("| rig | mass (kg) | certified gap: box as drawn / scaled | held-out on B: as drawn / scaled |")
    print("|---:|---:|---|---|")
    for seed in seeds:
        a, b, vehicle = runs(seed, folder)
        de_search.box_scale = lambda _vehicle: 1.0  # the box as drawn for cars and motorcycles
        drawn = de_outcome(a, b, vehicle)
        de_search.box_scale = scaled_box
        scaled = de_outcome(a, b, vehicle)
        rows.append((drawn, scaled))
        print(
            f"| {seed} | {vehicle.mass_kg:.2f} | {100 * drawn[0]:.2f}% / {100 * scaled[0]:.3f}% | "
            f"{100 * drawn[1]:.0f}% / {100 * scaled[1]:.0f}% |",
            flush=True,
        )
    for name, k in (("as drawn", 0), ("scaled", 1)):
        gaps = [r[k][0] for r in rows]
        print(
            f"box {name}: certified gap within {WITHIN:.0%} on {sum(g <= WITHIN for g in gaps)}/{len(rows)}, "
            f"median {100 * statistics.median(gaps):.3f}%, largest {100 * max(gaps):.2f}%; DE median "
            f"{statistics.median(r[k][2] for r in rows):.1f} s a rig"
        )


if __name__ == "__main__":
    main()
