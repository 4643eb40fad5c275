"""Benchmark: accuracy of identification from a mass-only vehicle file over many vehicles drawn at random.

    .venv/bin/python benchmarks/bench_mass_only.py [--draws 40] [--axles 6]

Each quarter car is drawn as in tests/estimator (cases.random_wide_quarter_car: mass 250-600 kg, sprung
share 82-93%, spring 15-60 kN/m, tyre 150-350 kN/m, tyre damping 600-2000 N·s/m, relaxation time 15-50 ms,
the real SUV damper table of ../shared/realdata scaled 0.5-1.2), simulated with 5 µm sensor noise at 1 kHz
and at 500 Hz, and identified from its mass alone; axles (cases.random_axle: unequal real dampers, anti-roll
bar) from mass, track and bar. A hit is: every curve within 2% of peak force, both masses within 2%, both
stiffnesses within 5% (the test's criteria). Prints the hit rate and the median, 90th percentile and worst
error of each quantity.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimator"))

from cases import (  # the test cases' generators, shared with the tests
    axle_case_at,
    identification_errors,
    mass_only,
    wide_quarter_car_case,
)

from estimator.identify import IdentifyOptions, identify

LIMITS = {"curve": 2.0, "sprung mass": 2.0, "unsprung mass": 2.0, "spring": 5.0, "tyre": 5.0}


def _hit(errors: dict[str, float]) -> bool:
    return all(
        value <= LIMITS["curve" if name.startswith("curve") else name]
        for name, value in errors.items()
        if name.startswith("curve") or name in LIMITS
    )


def run(label: str, cases) -> None:
    table: dict[str, list[float]] = {}
    hits, seconds = 0, []
    for case in cases:
        start = time.perf_counter()
        stated = mass_only(case.vehicle.known)
        result = identify(case.result.recording, stated, IdentifyOptions(output_error=False))
        seconds.append(time.perf_counter() - start)
        errors = identification_errors(case, result)
        merged = {("curve" if k.startswith("curve") else k): v for k, v in errors.items()}
        merged["curve"] = max(v for k, v in errors.items() if k.startswith("curve"))
        for name, value in merged.items():
            table.setdefault(name, []).append(value)
        hits += _hit(errors)
        if not _hit(errors):
            print(f"  miss: {case.name}: " + ", ".join(f"{k} {v:.2f}%" for k, v in errors.items()))
    count = len(seconds)
    print(
        f"\n{label}: {hits}/{count} hits ({100 * hits / count:.0f}%), "
        f"identify median {np.median(seconds):.2f} s\n"
    )
    print("| error (%) | median | 90th percentile | worst | limit |")
    print("|---|---:|---:|---:|---:|")
    for name, values in table.items():
        limit = LIMITS.get(name)
        print(
            f"| {name} | {np.median(values):.2f} | {np.percentile(values, 90):.2f} | {np.max(values):.2f} | "
            f"{limit if limit is not None else '-'} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=40, help="quarter cars per sample rate (default 40)")
    parser.add_argument("--axles", type=int, default=6, help="axles per sample rate (default 6)")
    parser.add_argument("--seed", type=int, default=7, help="seed of the draw of vehicle seeds")
    args = parser.parse_args()
    seeds = [int(s) for s in np.random.default_rng(args.seed).integers(1_000, 1_000_000, size=args.draws)]
    axle_seeds = [int(s) for s in np.random.default_rng(args.seed + 1).integers(1_000, 1_000_000, args.axles)]
    for dt in (0.001, 0.002):
        rate = f"{1 / dt:.0f} Hz"
        run(f"quarter car, mass-only file, {rate}", (wide_quarter_car_case(s, dt) for s in seeds))
        run(f"axle, mass + track + bar, {rate}", (axle_case_at(s, dt) for s in axle_seeds))


if __name__ == "__main__":
    main()
