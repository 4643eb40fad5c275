"""Benchmark: coverage of the 95% intervals of `identify` (estimator.uncertainty) over simulated recordings,
and what computing them costs.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_coverage.py [--draws 24]

The draws are tests/estimator/band_coverage.draws (fixed seeds, 5 µm sensor noise, 15 s sweeps): in turn a
quarter car with every constant stated (cases.random_quarter_car), a wide-range quarter car identified from
its mass alone at 1 kHz, and one at 500 Hz (cases.random_wide_quarter_car). For each quantity it prints how
often its interval held the truth (the curve at each grid point against the true damper force at that
velocity), the curve band's half-width in % of peak force, and the median time of identify with and without
the intervals (output error off in both, so the difference is the intervals' own cost).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "estimator"))

from band_coverage import Coverage, check, draws  # the test's draws and checks, shared
from cases import mass_only

from estimator.identify import IdentifyOptions, identify


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=24)
    args = parser.parse_args()
    coverage = Coverage()
    with_bands: list[float] = []
    without: list[float] = []
    for case, from_mass_only in draws(args.draws):
        vehicle = mass_only(case.vehicle.known) if from_mass_only else case.vehicle.known
        recording = case.result.recording
        start = time.perf_counter()
        identify(recording, vehicle, IdentifyOptions(output_error=False, intervals=False))
        without.append(time.perf_counter() - start)
        start = time.perf_counter()
        result = identify(recording, vehicle, IdentifyOptions(output_error=False))
        with_bands.append(time.perf_counter() - start)
        check(case, result, coverage)
        print(f"{case.name}{' (mass only)' if from_mass_only else ''}: {with_bands[-1]:.2f} s", flush=True)
    print(f"\ncoverage of the 95% intervals over {args.draws} simulated recordings:\n{coverage.table()}")
    print(f"  pooled: {coverage.rate() * 100:.1f}%")
    print(
        f"identify (output error off): median {np.median(without):.2f} s without intervals, "
        f"{np.median(with_bands):.2f} s with (x{np.median(np.array(with_bands) / np.array(without)):.2f})"
    )


if __name__ == "__main__":
    main()
