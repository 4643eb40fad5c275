"""Benchmark: the model doctor on the foreign world (simulators/foreign, issue 29 item 4), whose effects take
forms the doctor's catalogue does not (Stribeck and LuGre/Dahl friction, bump stops with clearance, sensor
lags and moving averages, gain errors, lagging dampers, asymmetric axles, unrecorded forces).

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_doctor_heldout.py --split heldout \
        --per-class 40 --jobs 2 --cache /tmp/foreign-heldout-cache
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_doctor_heldout.py --split dev \
        --per-class 10 --jobs 2 --cache /tmp/foreign-dev-cache

Designing happens on `--split dev` (draw indices 0-9999 of the DEV namespace); only `--split heldout` (the
draws frozen in benchmarks/heldout/manifest.json, each checked against its hash before it is scored) counts
for published figures. Each draw is simulated into `--cache` (or read from there: simulators.foreign.manifest
.draw_files), read back with the project's readers (daq.formats) and diagnosed in-process as
`shockbench diagnose` does (estimator.doctor.diagnose, Maxwell tyre; benchmarks/bench_doctor_independent.py's
call). Outcomes are cached as JSON lines in the cache folder, keyed by the doctor's source digest, so a re-run
of the same doctor re-scores without re-diagnosing.

Scoring (EFFECT_NAMES below): an effect is *found* when the doctor names one of its accepted names, or, for an
effect no current catalogue family describes (`unexplained_ok`), when it ends "unexplained". A draw is a *hit*
when every hidden effect is found, nothing else is named (tyre_liftoff is tolerated where the tyre left the
plate), and it ends "unexplained" only if one of its effects is outside the catalogue (then the names it tried
before giving up are not held against it). Clean: a hit is silence; anything else is a false alarm. Draws
whose force effect never acted (a bump stop never touched: size 0) are left out and counted. The report: per
class the hit rate with its 95% Wilson interval, the false-alarm rate on clean recordings, detection against
effect size (a logistic fit of found vs log size by maximum likelihood, the size found half the time with a
bootstrap 95% interval), and whether, where the effects were named right, the gap fell to the clean floor (the
95th percentile of gap after / expected gap on silent clean draws).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize
from scipy.stats import binomtest

from simulators.foreign.draws import CLASSES, SIZE_UNITS
from simulators.foreign.manifest import MANIFEST, draw_files, load_manifest, namespace_entropy

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Accepted:
    """The doctor's names that count as finding a physical effect: `now` in today's catalogue, `future` the
    names issue 29's doctor may use; unexplained_ok: no catalogue family describes it, so "unexplained" finds
    it (the "add it and show the gap shrink" half of the promise cannot be kept for it)."""

    now: tuple[str, ...]
    future: tuple[str, ...] = ()
    unexplained_ok: bool = False

    @property
    def names(self) -> frozenset[str]:
        return frozenset(self.now + self.future)


EFFECT_NAMES: dict[str, Accepted] = {
    "stribeck_friction": Accepted(("coulomb_friction",), ("low_speed_friction", "stribeck_friction")),
    "hysteretic_friction": Accepted(("coulomb_friction",), ("low_speed_friction", "hysteretic_friction")),
    "bump_stop": Accepted(("progressive_spring",), ("spring_curve", "bump_stop")),
    "sensor_lag": Accepted(("channel_delay",), ("sensor_dynamics",)),
    "sensor_average": Accepted(("channel_delay",), ("sensor_dynamics",)),
    "sensor_gain": Accepted((), ("sensor_gain",), unexplained_ok=True),
    "spring_rate": Accepted(("spring_stiffness",), ("spring_curve",)),
    "tyre_rate": Accepted(("tyre_stiffness",)),
    "asymmetric_axle": Accepted((), ("axle_asymmetry",), unexplained_ok=True),
    "damper_lag": Accepted((), (), unexplained_ok=True),
    "unrecorded_force": Accepted((), (), unexplained_ok=True),
}
"""Physical effect (simulators.foreign.draws) → the doctor's names that find it. A name in several rows (for
example channel_delay) finds any of them. Names are compared without their channel suffix."""
TOLERATED_WITH_LIFTOFF = "tyre_liftoff"


@dataclass(frozen=True)
class Outcome:
    draw_id: str
    label: str
    effects: tuple[str, ...]
    sizes: tuple[float, ...]
    named: tuple[str, ...]
    unexplained: bool
    airborne_fraction: float
    gap_before_m: float | None
    gap_after_m: float | None
    expected_gap_m: float | None
    doctor_s: float

    def found(self, effect: str) -> bool:
        accepted = EFFECT_NAMES[effect]
        return bool(accepted.names & set(self.named)) or (accepted.unexplained_ok and self.unexplained)

    @property
    def spurious(self) -> tuple[str, ...]:
        """Names that find none of the hidden effects. Where the draw holds an effect outside the catalogue
        and the doctor ends "unexplained", the names it tried before are not held against it (as
        bench_doctor_independent.py scores its outside class)."""
        if self.unexplained and any(EFFECT_NAMES[e].unexplained_ok for e in self.effects):
            return ()
        allowed = set().union(*(EFFECT_NAMES[e].names for e in self.effects)) if self.effects else set()
        if self.airborne_fraction > 0.0:
            allowed.add(TOLERATED_WITH_LIFTOFF)
        return tuple(n for n in self.named if n not in allowed)

    @property
    def realised(self) -> bool:
        return all(s > 0.0 for s in self.sizes)

    @property
    def hit(self) -> bool:
        if not self.effects:
            return not self.unexplained and not self.spurious
        outside = any(EFFECT_NAMES[e].unexplained_ok for e in self.effects)
        return (
            all(self.found(e) for e in self.effects)
            and not self.spurious
            and (outside or not self.unexplained)
        )

    @property
    def named_right(self) -> bool:
        """Every hidden effect named by an accepted name and nothing else (the final verdict aside)."""
        return (
            bool(self.effects)
            and not self.spurious
            and all(EFFECT_NAMES[e].names & set(self.named) for e in self.effects)
        )

    @property
    def gap_ratio(self) -> float | None:
        if self.gap_after_m is None or not self.expected_gap_m or not math.isfinite(self.expected_gap_m):
            return None
        return self.gap_after_m / self.expected_gap_m


def doctor_digest() -> str:
    digest = hashlib.sha256()
    for path in sorted((ROOT / "estimator" / "doctor").glob("*.py")):
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def run_draw(
    split: str, label: str, index: int, cache: str, expected_sha256: str | None, entropy: int
) -> Outcome:
    """Simulate (or read), check against the frozen hash, read back, diagnose one draw (a worker process);
    entropy: the split's namespace (simulators.foreign.manifest.namespace_entropy)."""
    from daq.formats.recording_csv import read_recording_csv
    from daq.formats.vehicle_file import read_vehicle
    from estimator.doctor import DiagnoseOptions, diagnose
    from estimator.vehicle import TyreModel
    from simulators.foreign.world import channels_sha256

    truth = draw_files(split, entropy, label, index, cache)
    recording, vehicle = read_recording_csv(truth["csv"]), read_vehicle(truth["toml"])
    if expected_sha256 is not None:
        digest = channels_sha256(recording.sample_time_s, recording.channels)
        if digest != expected_sha256:
            raise RuntimeError(f"{truth['id']}: the recording does not match the frozen manifest's hash")
    start = time.perf_counter()
    result = diagnose(recording, vehicle, DiagnoseOptions(tyre=TyreModel.MAXWELL))
    doctor_s = time.perf_counter() - start
    data = result.to_json()
    return Outcome(
        truth["id"],
        label,
        tuple(e["effect"] for e in truth["effects"]),
        tuple(float(e["size"]) for e in truth["effects"]),
        tuple(sorted({n.split("(")[0] for n in result.effects_named})),
        bool(result.unexplained),
        float(truth["airborne_fraction"]),
        data["gap_before_m"],  # type: ignore[arg-type]
        data["gap_after_m"],  # type: ignore[arg-type]
        data["expected_gap_m"],  # type: ignore[arg-type]
        doctor_s,
    )


def wilson(successes: int, trials: int) -> str:
    if trials == 0:
        return "—"
    low, high = binomtest(successes, trials).proportion_ci(0.95, method="wilson")
    return f"{successes}/{trials} = {100 * successes / trials:.0f}% [{100 * low:.0f}, {100 * high:.0f}]"


def _logistic_fit(log_size: np.ndarray, found: np.ndarray) -> tuple[float, float] | None:
    """(a, b) of P(found) = 1/(1 + exp(−(a + b·log size))) by maximum likelihood; None if it separates."""
    if found.all() or not found.any():
        return None

    def negative_log_likelihood(p: np.ndarray) -> float:
        z = p[0] + p[1] * log_size
        return float(np.sum(np.logaddexp(0.0, z) - found * z))

    fit = minimize(
        negative_log_likelihood,
        np.array([0.0, 1.0]),
        method="Nelder-Mead",
        options={"xatol": 1e-8, "fatol": 1e-10, "maxiter": 4000},
    )
    if fit.fun < 1e-6 or abs(fit.x[1]) > 1e3:
        return None  # perfectly separated: no finite maximum
    return float(fit.x[0]), float(fit.x[1])


def half_detection_size(sizes: np.ndarray, found: np.ndarray, rng: np.random.Generator) -> str:
    """The size found half the time (logistic fit on log size) with a 95% bootstrap interval, or why not."""
    if sizes.size < 4:
        return "too few draws"
    low, high = float(sizes.min()), float(sizes.max())
    if found.all():
        return f"below the smallest drawn size ({low:.3g}): all found"
    if not found.any():
        return f"not reached (none found up to {high:.3g})"
    log_size = np.log(sizes)
    fit = _logistic_fit(log_size, found)
    if fit is None:
        edge = (float(sizes[~found].max()), float(sizes[found].min()))
        return f"separated: all found above {edge[1]:.3g}, none below {edge[0]:.3g}"
    a, b = fit
    if b <= 0.0:
        return f"not reached (detection does not rise with size; slope {b:.2f})"
    middle = math.exp(-a / b)
    estimates = []
    for _ in range(300):
        pick = rng.integers(sizes.size, size=sizes.size)
        again = _logistic_fit(log_size[pick], found[pick])
        if again is not None and again[1] > 0:  # a resample with a flat slope puts the size beyond reach
            estimates.append(math.exp(min(-again[0] / again[1], 700.0)))
    if middle > high:
        return f"not reached (extrapolated {middle:.3g} > largest drawn {high:.3g})"
    if len(estimates) < 100:
        return f"{middle:.3g} (bootstrap fits too few: {len(estimates)}/300)"
    q = np.quantile(estimates, [0.025, 0.975])
    return f"{middle:.3g} [{q[0]:.3g}, {min(q[1], 1e9):.3g}]"


def print_report(outcomes: list[Outcome]) -> None:
    rng = np.random.default_rng(29)
    unrealised = [o for o in outcomes if not o.realised]
    scored = [o for o in outcomes if o.realised]
    clean = [o for o in scored if o.label == "clean"]
    silent = [o.gap_ratio for o in clean if o.hit and o.gap_ratio is not None]
    floor = float(np.quantile(silent, 0.95)) if silent else None
    print(
        "| class | draws | hit rate [95% Wilson] | effect found, size at 50% detection [95% bootstrap] | "
        "named right: gap at the clean floor |"
    )
    print("|---|---:|---|---|---|")
    for label in CLASSES:
        rows = [o for o in scored if o.label == label]
        if not rows:
            continue
        hits = sum(o.hit for o in rows)
        if label == "clean":
            alarms = len(rows) - hits
            rates = f"silent {wilson(hits, len(rows))}; false alarms {wilson(alarms, len(rows))}"
            print(f"| clean | {len(rows)} | {rates} | | |")
            continue
        curves = []
        for effect in sorted({e for o in rows for e in o.effects}):
            if label == "pair":
                continue
            pairs = [(o.sizes[o.effects.index(effect)], o.found(effect)) for o in rows if effect in o.effects]
            sizes = np.array([p[0] for p in pairs])
            found = np.array([p[1] for p in pairs])
            text = half_detection_size(sizes, found, rng)
            curves.append(f"{effect}: found {int(found.sum())}/{found.size}, {text} ({SIZE_UNITS[effect]})")
        right = [o for o in rows if o.named_right]
        at_floor = sum(
            1 for o in right if floor is not None and o.gap_ratio is not None and o.gap_ratio <= floor
        )
        detection = "; ".join(curves) or "—"
        print(
            f"| {label} | {len(rows)} | {wilson(hits, len(rows))} | {detection} | {at_floor}/{len(right)} |"
        )
    if floor is not None:
        print(
            f"\nclean floor: gap after / expected gap, 95th percentile of {len(silent)} silent clean draws:",
            end="",
        )
        print(f" {floor:.2f}")
    if unrealised:
        names = ", ".join(o.draw_id for o in unrealised)
        print(f"left out, the effect never acted (size 0): {len(unrealised)} ({names})")
    times = [o.doctor_s for o in scored]
    print(f"doctor wall time per draw: median {np.median(times):.1f} s, max {max(times):.1f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("dev", "heldout"), required=True)
    parser.add_argument("--per-class", type=int, default=40, help="draws per class, from --first-index")
    parser.add_argument(
        "--first-index",
        type=int,
        default=0,
        help="the first draw index (held-out: a later part of the manifest's, left unseen by a design)",
    )
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--cache", type=Path, required=True, help="folder for recordings and outcomes")
    parser.add_argument("--classes", default=",".join(CLASSES))
    parser.add_argument(
        "--manifest",
        type=Path,
        default=MANIFEST,
        help="held-out: the frozen manifest (a later freeze, e.g. manifest-2.json, needs its own --cache)",
    )
    args = parser.parse_args()
    labels = [c.strip() for c in args.classes.split(",") if c.strip()]
    if unknown := [c for c in labels if c not in CLASSES]:
        parser.error(f"unknown class {unknown[0]!r}; expected some of {', '.join(CLASSES)}")
    hashes: dict[str, str] = {}
    if args.split == "heldout":
        manifest = load_manifest(args.manifest)
        if args.first_index + args.per_class > manifest["per_class"]:
            parser.error(f"the manifest freezes {manifest['per_class']} draws per class (indices from 0)")
        hashes = {i: d["sha256"] for i, d in manifest["draws"].items()}
    entropy = namespace_entropy(args.split, args.manifest)
    indices = range(args.first_index, args.first_index + args.per_class)
    work = [(label, i) for i in indices for label in labels]
    digest = doctor_digest()
    results = args.cache / args.split / f"outcomes-{digest}.jsonl"
    results.parent.mkdir(parents=True, exist_ok=True)
    done: dict[str, Outcome] = {}
    if results.exists():
        for line in results.read_text().splitlines():
            row = json.loads(line)
            row.update({k: tuple(row[k]) for k in ("effects", "sizes", "named")})
            done[row["draw_id"]] = Outcome(**row)
    print(
        f"machine: {platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}; "
        f"split {args.split}, {args.per_class} per class, {args.jobs} jobs, doctor {digest}"
    )
    start = time.perf_counter()
    todo = [(label, i) for label, i in work if f"{args.split}/{label}/{i}" not in done]
    with ProcessPoolExecutor(args.jobs) as pool:
        futures = [
            pool.submit(
                run_draw, args.split, label, i, str(args.cache), hashes.get(f"heldout/{label}/{i}"), entropy
            )
            for label, i in todo
        ]
        for count, future in enumerate(as_completed(futures), start=1):
            outcome = future.result()
            done[outcome.draw_id] = outcome
            with results.open("a") as handle:
                handle.write(json.dumps(asdict(outcome)) + "\n")
            print(f"[{count}/{len(todo)}] ({outcome.doctor_s:.0f} s)", file=sys.stderr)
    outcomes = [done[f"{args.split}/{label}/{i}"] for label, i in work]
    print_report(outcomes)
    elapsed = time.perf_counter() - start
    print(f"total wall time {elapsed:.0f} s ({len(todo)} diagnosed, {len(work) - len(todo)} from the cache)")


if __name__ == "__main__":
    main()
