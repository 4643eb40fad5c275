"""`shockbench reanalyse --compare RUN_A RUN_B` (issue 33): what a new estimator version changes, judged on
the fleet's stored recordings before it is rolled out.

A run is a stored re-analysis (service.store.reanalysis_runs) by its id, or "original": the lanes' own
identification results. Recordings are matched by their sha256; for each one both runs identified:

- curve: how far B's damper curve moved from A's, the RMS of the force difference over the velocities
  both curves cover (each curve linear between its points), in % of A's peak force; the largest corner
  counts for an axle;
- masses: B's sprung and unsprung masses less A's, in kg and in % of A's;
- verdict: each result's inspection figures judged by the same thresholds (estimator.verdict's defaults,
  so a change of thresholds between the runs is not mistaken for the estimator's), and how many steps
  (pass, check, fail) it moved; a flip is a verdict that changed;
- status: a recording one run identified and the other did not is listed apart.

Per vehicle (the stored recording's vehicle id) and over the fleet: the median, 95th percentile and the
largest of each change, and the flips; then the recordings with the largest curve change first. The plot
(`--plot PNG`) shows the distribution of the curve and sprung mass changes and the verdict flips.
"""

from __future__ import annotations

import statistics
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from estimator.errors import UserError
from service.store.database import Database

SEVERITY = {"pass": 0, "check": 1, "fail": 2}


class CompareError(UserError, ValueError):
    """A run that is not stored, or nothing to compare; one line."""


@dataclass(frozen=True)
class Change:
    """How one recording's result moved from run A to run B."""

    name: str
    vehicle: str
    curve_percent: float
    sprung_kg: float
    sprung_percent: float
    unsprung_kg: float
    unsprung_percent: float
    verdict_a: str
    verdict_b: str

    @property
    def flipped(self) -> bool:
        return self.verdict_a != self.verdict_b

    @property
    def verdict_steps(self) -> int:
        return SEVERITY[self.verdict_b] - SEVERITY[self.verdict_a]


@dataclass(frozen=True)
class Spread:
    median: float
    p95: float
    largest: float

    @classmethod
    def of(cls, values: Sequence[float]) -> Spread:
        if not values:
            return cls(0.0, 0.0, 0.0)
        ordered = sorted(values)
        p95 = ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]
        return cls(statistics.median(ordered), p95, ordered[-1])


@dataclass(frozen=True)
class Group:
    """The changes of one vehicle, or of the fleet."""

    name: str
    recordings: int
    curve_percent: Spread
    sprung_percent: Spread
    unsprung_percent: Spread
    flips: Counter[str]
    verdict_steps: int
    """Sum of the verdicts' moves (positive: stricter)."""


@dataclass
class Comparison:
    a: str
    b: str
    changes: list[Change]
    """Largest curve change first."""
    fleet: Group
    vehicles: list[Group]
    """Largest curve change first."""
    only_a: list[str] = field(default_factory=list)
    """Recordings A identified and B did not (failed or missing)."""
    only_b: list[str] = field(default_factory=list)


def _curve_rms_percent(a: Mapping[str, Any], b: Mapping[str, Any]) -> float:
    import numpy as np

    worst = 0.0
    for curve_a, curve_b in zip(a.get("curves", []), b.get("curves", []), strict=False):
        va, fa = np.asarray(curve_a["velocity_m_s"], float), np.asarray(curve_a["force_N"], float)
        vb, fb = np.asarray(curve_b["velocity_m_s"], float), np.asarray(curve_b["force_N"], float)
        lo, hi = max(va.min(), vb.min()), min(va.max(), vb.max())
        peak = float(np.max(np.abs(fa)))
        if hi <= lo or peak <= 0:
            continue
        grid = np.linspace(lo, hi, 200)
        rms = float(np.sqrt(np.mean((np.interp(grid, vb, fb) - np.interp(grid, va, fa)) ** 2)))
        worst = max(worst, 100 * rms / peak)
    return worst


def _verdict(result: Mapping[str, Any]) -> str:
    from estimator.verdict import judge

    inspection = result.get("inspection")
    return judge(inspection).outcome.value if isinstance(inspection, dict) else "pass"


def _mass(result: Mapping[str, Any], which: str) -> float:
    value = result.get("masses_kg", {}).get(which)
    return float(value) if value is not None else float("nan")


def _percent(delta: float, base: float) -> float:
    return 100 * delta / base if base else 0.0


def change_of(name: str, vehicle: str, a: Mapping[str, Any], b: Mapping[str, Any]) -> Change:
    sprung = _mass(b, "sprung") - _mass(a, "sprung")
    unsprung = _mass(b, "unsprung") - _mass(a, "unsprung")
    return Change(
        name=name,
        vehicle=vehicle,
        curve_percent=_curve_rms_percent(a, b),
        sprung_kg=sprung,
        sprung_percent=_percent(sprung, _mass(a, "sprung")),
        unsprung_kg=unsprung,
        unsprung_percent=_percent(unsprung, _mass(a, "unsprung")),
        verdict_a=_verdict(a),
        verdict_b=_verdict(b),
    )


def group_of(name: str, changes: Sequence[Change]) -> Group:
    return Group(
        name=name,
        recordings=len(changes),
        curve_percent=Spread.of([c.curve_percent for c in changes]),
        sprung_percent=Spread.of([abs(c.sprung_percent) for c in changes]),
        unsprung_percent=Spread.of([abs(c.unsprung_percent) for c in changes]),
        flips=Counter(f"{c.verdict_a}->{c.verdict_b}" for c in changes if c.flipped),
        verdict_steps=sum(c.verdict_steps for c in changes),
    )


def compare(
    a: str,
    b: str,
    results_a: Mapping[str, dict[str, Any] | None],
    results_b: Mapping[str, dict[str, Any] | None],
    names: Mapping[str, tuple[str, str]],
) -> Comparison:
    """The comparison of two runs' identify results (sha256 -> result, None when it failed); `names`:
    sha256 -> (recording name, vehicle)."""
    changes, only_a, only_b = [], [], []
    for sha in sorted(set(results_a) | set(results_b)):
        name, vehicle = names.get(sha, (sha[:12], "(unknown)"))
        ra, rb = results_a.get(sha), results_b.get(sha)
        if ra is not None and rb is not None:
            changes.append(change_of(name, vehicle, ra, rb))
        elif ra is not None and sha in results_b:
            only_a.append(name)
        elif rb is not None and sha in results_a:
            only_b.append(name)
    if not changes:
        raise CompareError(f"runs {a} and {b} have no identified recording in common")
    changes.sort(key=lambda c: (-c.curve_percent, c.name))
    by_vehicle: dict[str, list[Change]] = {}
    for c in changes:
        by_vehicle.setdefault(c.vehicle, []).append(c)
    vehicles = sorted(
        (group_of(v, cs) for v, cs in by_vehicle.items()), key=lambda g: (-g.curve_percent.largest, g.name)
    )
    return Comparison(a, b, changes, group_of("fleet", changes), vehicles, sorted(only_a), sorted(only_b))


def _results(database: Database, run: str) -> dict[str, dict[str, Any] | None]:
    from service.store.reanalysis_runs import ORIGINAL, RunStore

    runs = RunStore(database)
    if run == ORIGINAL:
        return runs.original_results()
    if not run.isdigit() or runs.get(int(run)) is None:
        known = ", ".join(str(r.id) for r in runs.runs()) or "none"
        raise CompareError(f"run {run!r} is not stored (runs: {known}; or 'original')")
    return runs.results(int(run))


def compare_runs(database: Database, a: str, b: str) -> Comparison:
    """Run B against run A, as stored in `database` (module docstring)."""
    from service.store.recordings import RecordingStore

    names = {r.sha256: (r.name, r.vehicle_id or r.name) for r in RecordingStore(database).listing()}
    return compare(a, b, _results(database, a), _results(database, b), names)


def _spread(s: Spread) -> str:
    return f"{s.median:6.2f} {s.p95:6.2f} {s.largest:6.2f}"


def _flips(g: Group) -> str:
    return ", ".join(f"{k} {n}" for k, n in sorted(g.flips.items())) or "none"


def render(c: Comparison, top: int = 20) -> str:
    """The comparison as text: fleet, vehicles, the largest changes."""
    head = "median    p95    max"
    lines = [
        f"run {c.b} against run {c.a}: {c.fleet.recordings} recording(s) in common",
        f"{'':28} {'curve %':>20} {'sprung mass %':>20} {'unsprung mass %':>20}  verdict flips",
        f"{'':28} {head:>20} {head:>20} {head:>20}",
    ]
    for g in [c.fleet, *c.vehicles]:
        label = f"{g.name[:22]} ({g.recordings})"
        lines.append(
            f"{label:28} {_spread(g.curve_percent):>20} {_spread(g.sprung_percent):>20} "
            f"{_spread(g.unsprung_percent):>20}  {_flips(g)}"
        )
    lines.append(f"largest changes (of {len(c.changes)}):")
    for ch in c.changes[:top]:
        verdict = f"{ch.verdict_a}->{ch.verdict_b}" if ch.flipped else ch.verdict_b
        lines.append(
            f"  {ch.name}  [{ch.vehicle}]  curve {ch.curve_percent:.2f}%  sprung {ch.sprung_kg:+.2f} kg "
            f"({ch.sprung_percent:+.2f}%)  unsprung {ch.unsprung_kg:+.2f} kg ({ch.unsprung_percent:+.2f}%)  "
            f"verdict {verdict}"
        )
    flipped = [ch for ch in c.changes if ch.flipped]
    lines.append(
        f"verdict flips: {len(flipped)}"
        + "".join(f"\n  {ch.name}: {ch.verdict_a}->{ch.verdict_b}" for ch in flipped)
    )
    if c.only_a:
        lines.append(f"identified by run {c.a} only: {', '.join(c.only_a)}")
    if c.only_b:
        lines.append(f"identified by run {c.b} only: {', '.join(c.only_b)}")
    return "\n".join(lines)


def plot_changes(c: Comparison, path: Path) -> None:
    """A PNG of the distribution of the curve and sprung mass changes, and the verdicts' moves."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (curve, mass, verdict) = plt.subplots(1, 3, figsize=(13, 4))
    largest = max(c.fleet.curve_percent.largest, 1e-6)
    curve.hist([ch.curve_percent for ch in c.changes], bins=30, range=(0, 1.05 * largest), color="tab:blue")
    curve.set(xlabel="curve change, RMS (% of peak force)", ylabel="recordings", title="damper curve")
    widest = 1.05 * max(c.fleet.sprung_percent.largest, 1e-6)  # symmetric: a shift to one side shows
    mass.hist([ch.sprung_percent for ch in c.changes], bins=30, range=(-widest, widest), color="tab:orange")
    mass.set(xlabel="sprung mass change (%)", title="sprung mass")
    moves = Counter(ch.verdict_steps for ch in c.changes)
    steps = [-2, -1, 0, 1, 2]
    verdict.bar([str(s) for s in steps], [moves.get(s, 0) for s in steps], color="tab:green")
    verdict.set(xlabel="verdict steps moved (+: stricter)", title=f"verdicts ({c.fleet.flips.total()} flips)")
    figure.suptitle(f"run {c.b} against run {c.a}, {len(c.changes)} recordings")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=100)
    plt.close(figure)
