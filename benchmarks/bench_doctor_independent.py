"""Benchmark: the model doctor on recordings of the independent world (simulators/independent), which shares
no code with the estimator or the project's own simulator.

    .venv/bin/python benchmarks/bench_doctor_independent.py --per-class 3 --jobs 2
    .venv/bin/python benchmarks/bench_doctor_independent.py --classes clean,pair --per-class 1

For every class (clean; each single effect; two at once; outside the catalog) it draws `--per-class` cases
with fixed seeds (simulators.independent.cases.draw_case, from `--first-seed`), writes each as a recording
CSV and vehicle TOML to a temporary folder (or to `--cache DIR`, kept for re-runs of the doctor on the same
draws), reads them back with the project's readers (daq.formats) and runs the doctor in-process
(estimator.doctor.diagnose, the call `shockbench diagnose` makes, starting tyre Maxwell). It prints one line
per case, a confusion matrix (hidden class × what the doctor said), the hit rates, the gaps before and after
against the doctor's own expected gap, and the wall time per doctor run.

What counts as a hit: clean → nothing named and not unexplained; one effect → exactly that effect's family
named (FAMILY_OF) and not unexplained; pair → exactly both families named and not unexplained; outside →
unexplained. A light corner with a soft damper can hop off the plate in any class: where the tyre is off the
plate in at least 0.5% of the samples, tyre_liftoff counts as present too (marked "+ lift-off" in the case
table).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import tempfile
import time
from collections import Counter, defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from estimator.doctor import DiagnoseOptions
from simulators.independent.cases import CLASSES, MIN_AIRBORNE_FRACTION, draw_case, simulate_case
from simulators.independent.files import write_recording

FAMILY_OF = {
    "coulomb_friction": "low_speed_friction",
    "progressive_spring": "spring_curve",
    "spring_stiffness": "spring_curve",
    "channel_delay": "sensor_dynamics",
}
"""The independent world's effect classes whose catalogue family has another name (estimator.doctor.catalog:
a wrong rate and a progressive spring are both the spring's curve, a pure delay is a sensor's dynamics)."""


@dataclass(frozen=True)
class Outcome:
    label: str
    seed: int
    description: str
    hidden: tuple[str, ...]
    named: tuple[str, ...]
    unexplained: bool
    gap_before_m: float | None
    gap_after_m: float | None
    expected_gap_m: float | None
    airborne_fraction: float
    simulate_s: float
    doctor_s: float
    conclusion: str
    residual_ratio: float | None = None
    """The final model's equation residual over that of a model without missing effects (None in results
    written before it was recorded)."""
    p_value: float | None = None
    """The goodness-of-fit test's p-value (None in results written before the statistical doctor)."""

    @property
    def families(self) -> set[str]:
        """The families named: "sensor_dynamics(x_t, lag)" -> "sensor_dynamics"."""
        return {name.split("(", 1)[0] for name in self.named}

    @property
    def expected_families(self) -> set[str]:
        """The families the effects present take in the doctor's catalogue (FAMILY_OF)."""
        return {FAMILY_OF.get(effect, effect) for effect in self.present}

    @property
    def said(self) -> str:
        """The doctor's answer: unexplained (and what it named first), nothing, or the effects named."""
        if self.unexplained:
            return "unexplained" + (f" (after {', '.join(self.named)})" if self.named else "")
        return "+".join(sorted(self.named)) if self.named else "nothing"

    @property
    def incidental_liftoff(self) -> bool:
        """The tyre left the plate although the class did not ask for it (a light, softly damped corner)."""
        return self.airborne_fraction >= MIN_AIRBORNE_FRACTION and "tyre_liftoff" not in self.hidden

    @property
    def realised(self) -> bool:
        """The recording holds its class: a tyre_liftoff draw whose tyre stays on the plate even with the
        damper worn to an eighth (cases.simulate_case; a motorcycle whose tyre damping alone keeps the wheel
        down, 2 of tyre_liftoff draws 0-39) is no lift-off case, and the report leaves it out of the rates
        and names it."""
        return "tyre_liftoff" not in self.hidden or self.airborne_fraction >= MIN_AIRBORNE_FRACTION

    @property
    def present(self) -> tuple[str, ...]:
        """What the recording holds: the hidden effects, plus tyre_liftoff where the tyre left the plate."""
        return (*self.hidden, "tyre_liftoff") if self.incidental_liftoff else self.hidden

    @property
    def named_right(self) -> bool:
        """Exactly the effects present were named (the final verdict aside)."""
        return "outside" not in self.hidden and self.families == self.expected_families

    @property
    def hit(self) -> bool:
        if "outside" in self.hidden:
            return self.unexplained
        return not self.unexplained and self.families == self.expected_families


def recording_files(label: str, seed: int, folder: str, sweep_s: float) -> tuple[Path, Path, float, float]:
    """The recording CSV and vehicle TOML of one case in `folder`, with the share of samples the tyre is off
    the plate and the simulation's wall time (s). A folder that already holds them (`--cache`) is read, not
    simulated again: the doctor can then be re-run on the same draws."""
    from estimator import vehicle as vehicle_module

    stem = Path(folder) / f"{label}_{seed}_{sweep_s:g}s"
    csv_path, toml_path, facts_path = (stem.with_suffix(s) for s in (".csv", ".toml", ".json"))
    if facts_path.exists():
        facts = json.loads(facts_path.read_text())
        return csv_path, toml_path, facts["airborne_fraction"], facts["simulate_s"]
    case = draw_case(label, seed, sweep_s=sweep_s)
    # the vehicle file's ϑ is referred to the recording's sample time (README today) unless the project
    # names a fixed reference sample time
    reference = getattr(vehicle_module, "REFERENCE_SAMPLE_TIME_S", None)
    case = replace(case, settings=replace(case.settings, theta_reference_s=reference))
    start = time.perf_counter()
    world = simulate_case(case)
    simulate_s = time.perf_counter() - start
    write_recording(world, csv_path, toml_path)
    facts = {"airborne_fraction": world.airborne_fraction, "simulate_s": simulate_s}
    facts_path.write_text(json.dumps(facts))
    return csv_path, toml_path, world.airborne_fraction, simulate_s


def run_case(label: str, seed: int, folder: str, sweep_s: float) -> Outcome:
    """Simulate (or read from a cache folder), write, read back, diagnose one case (runs in a worker
    process)."""
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.doctor import DiagnoseOptions, diagnose
    from estimator.vehicle import TyreModel

    case = draw_case(label, seed, sweep_s=sweep_s)
    csv_path, toml_path, airborne_fraction, simulate_s = recording_files(label, seed, folder, sweep_s)
    recording, vehicle = read_recording_csv(csv_path), read_vehicle(toml_path)
    start = time.perf_counter()
    result = diagnose(recording, vehicle, DiagnoseOptions(tyre=TyreModel.MAXWELL))
    doctor_s = time.perf_counter() - start
    data = result.to_json()
    return Outcome(
        label,
        seed,
        case.description,
        case.hidden,
        tuple(result.effects_named),
        bool(result.unexplained),
        data["gap_before_m"],  # type: ignore[arg-type]
        data["gap_after_m"],  # type: ignore[arg-type]
        data["expected_gap_m"],  # type: ignore[arg-type]
        airborne_fraction,
        simulate_s,
        doctor_s,
        result.conclusion,
        data["residual_ratio"],  # type: ignore[arg-type]
        result.p_value,
    )


def _micro(value: float | None) -> str:
    return "—" if value is None else f"{value * 1e6:.1f}"


def print_report(outcomes: list[Outcome]) -> None:
    unrealised = [o for o in outcomes if not o.realised]
    outcomes = [o for o in outcomes if o.realised]
    print("\n## Cases\n")
    print(
        "| class | seed | hidden (size) | said | gap before / after / expected (µm) | airborne | doctor (s) |"
    )
    print("|---|---:|---|---|---|---:|---:|")
    for o in outcomes:
        gaps = f"{_micro(o.gap_before_m)} / {_micro(o.gap_after_m)} / {_micro(o.expected_gap_m)}"
        mark = "" if o.hit else " ✗"
        print(
            f"| {o.label} | {o.seed} | {o.description}{' + lift-off' if o.incidental_liftoff else ''} | "
            f"{o.said}{mark} | {gaps} | "
            f"{100 * o.airborne_fraction:.1f}% | {o.doctor_s:.0f} |"
        )
    said_columns = ["nothing", "unexplained"]
    for o in outcomes:
        for name in sorted(o.families):
            if name not in said_columns:
                said_columns.append(name)
    print("\n## Confusion matrix (rows: hidden class; columns: what the doctor said)\n")
    print("Each effect the doctor named counts in its column, `unexplained` when it ended so (after")
    print("naming or not), `nothing` when it named nothing and was content. `named right`: exactly the")
    print("effects present were named, whatever the final verdict; `hits`: named right and not")
    print("unexplained (outside: unexplained).\n")
    print("| hidden \\ said | " + " | ".join(said_columns) + " | named right | hits |")
    print("|---|" + "---:|" * (len(said_columns) + 2))
    for label in dict.fromkeys(o.label for o in outcomes):
        rows = [o for o in outcomes if o.label == label]
        counts: Counter[str] = Counter()
        for o in rows:
            counts.update(o.families)
            if o.unexplained:
                counts["unexplained"] += 1
            elif not o.named:
                counts["nothing"] += 1
        cells = [str(counts[c]) if counts[c] else "·" for c in said_columns]
        right = sum(o.named_right for o in rows)
        print(
            f"| {label} | "
            + " | ".join(cells)
            + f" | {right}/{len(rows)} | {sum(o.hit for o in rows)}/{len(rows)} |"
        )
    if unrealised:
        print(
            "\nleft out, the class not realised (the tyre never left the plate): "
            + ", ".join(f"{o.label} {o.seed}" for o in unrealised)
        )
    hits = sum(o.hit for o in outcomes)
    print(f"\nhit rate: {hits}/{len(outcomes)} = {100 * hits / len(outcomes):.0f}%")
    effects = [o for o in outcomes if o.label not in ("clean", "outside")]
    if effects:
        right = sum(o.named_right for o in effects)
        print(f"effects named right (verdict aside): {right}/{len(effects)} of the cases with effects")
    groups: dict[str, list[Outcome]] = defaultdict(list)
    for o in outcomes:
        kind = o.label if o.label in ("clean", "pair", "outside") else "single effect"
        groups[kind].append(o)
    for kind, rows in groups.items():
        print(f"  {kind}: {sum(o.hit for o in rows)}/{len(rows)}")
    alpha = DiagnoseOptions().alpha
    for label in ("clean", "outside"):
        rows = [o for o in outcomes if o.label == label]
        gap_ratios = [
            o.gap_after_m / o.expected_gap_m
            for o in rows
            if o.gap_after_m is not None and o.expected_gap_m and np.isfinite(o.expected_gap_m)
        ]
        p_values = [o.p_value for o in rows if o.p_value is not None]
        if gap_ratios and p_values:
            print(
                f"{label}: gap after / the final model's bootstrap mean {min(gap_ratios):.2f}-"
                f"{max(gap_ratios):.2f} (median {statistics.median(gap_ratios):.2f}); goodness-of-fit p "
                f"{min(p_values):.2g}-{max(p_values):.2g}, below α = {alpha:g} in "
                f"{sum(p < alpha for p in p_values)}/{len(p_values)}"
            )
    doctor = [o.doctor_s for o in outcomes]
    simulate = [o.simulate_s for o in outcomes]
    print(
        f"wall time per doctor run: median {statistics.median(doctor):.0f} s (min {min(doctor):.0f}, "
        f"max {max(doctor):.0f}); per simulation median {statistics.median(simulate):.1f} s"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-class", type=int, default=3, help="cases per class (seeds FIRST..FIRST+N-1)")
    parser.add_argument("--first-seed", type=int, default=0, help="the first seed of every class")
    parser.add_argument(
        "--cache",
        default=None,
        help="folder that keeps the simulated recordings: cases found there are not simulated again",
    )
    parser.add_argument("--jobs", type=int, default=1, help="worker processes")
    parser.add_argument("--classes", default=",".join(CLASSES), help="comma-separated subset of classes")
    parser.add_argument("--sweep-s", type=float, default=12.0, help="sweep length (s), 10-30")
    parser.add_argument(
        "--results", default=None, help="append each case's outcome to this file (JSON lines)"
    )
    parser.add_argument(
        "--from-results", default=None, help="print the report of a --results file, run nothing"
    )
    args = parser.parse_args()
    if args.from_results:
        lines = Path(args.from_results).read_text().splitlines()
        outcomes = [
            Outcome(**{**row, "hidden": tuple(row["hidden"]), "named": tuple(row["named"])})
            for row in map(json.loads, lines)
        ]
        order = {label: i for i, label in enumerate(CLASSES)}
        print_report(sorted(outcomes, key=lambda o: (order[o.label], o.seed)))
        return
    labels = [c.strip() for c in args.classes.split(",") if c.strip()]
    unknown = [c for c in labels if c not in CLASSES]
    if unknown:
        parser.error(f"unknown class {unknown[0]!r}; expected some of {', '.join(CLASSES)}")
    print(
        f"machine: {platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}; "
        f"{args.per_class} per class from seed {args.first_seed}, {args.jobs} jobs, "
        f"{args.sweep_s:.0f} s sweeps 0-20 Hz ±4 mm"
    )
    # seed by seed over all classes, so that a run cut short still covers every class
    seeds = range(args.first_seed, args.first_seed + args.per_class)
    work = [(label, seed) for seed in seeds for label in labels]
    start = time.perf_counter()
    if args.cache:
        Path(args.cache).mkdir(parents=True, exist_ok=True)
    with (
        tempfile.TemporaryDirectory(prefix="doctor-independent-") as temporary,
        ProcessPoolExecutor(args.jobs) as pool,
    ):
        folder = args.cache or temporary
        futures = [pool.submit(run_case, label, seed, folder, args.sweep_s) for label, seed in work]
        for done, future in enumerate(as_completed(futures), start=1):
            o = future.result()
            print(f"[{done}/{len(work)}] {o.label} {o.seed}: {o.said} ({o.doctor_s:.0f} s)", file=sys.stderr)
            if args.results:
                with open(args.results, "a") as handle:
                    handle.write(json.dumps(asdict(o)) + "\n")
        outcomes = [f.result() for f in futures]
    order = {label: i for i, label in enumerate(CLASSES)}
    print_report(sorted(outcomes, key=lambda o: (order[o.label], o.seed)))
    print(f"total wall time {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
