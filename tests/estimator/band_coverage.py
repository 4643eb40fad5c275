"""How often the 95% intervals of `identify` (estimator.uncertainty) hold the truth on simulated recordings:
shared by tests/estimator/test_confidence_bands.py and benchmarks/bench_coverage.py.

The curve's truth at a grid point is the true damper force at that velocity (the simulator's table). The
identified curve is piecewise linear between its points, so where the true curve bends between them its
points differ from the true force there by a representation bias; the bands carry an allowance for it
(estimator.uncertainty.representation_bias), and any bias left counts against the coverage reported here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from cases import Case, mass_only, quarter_car_case, wide_quarter_car_case

from estimator.identify import IdentificationResult, IdentifyOptions, identify


@dataclass
class Coverage:
    """Per quantity, whether each interval held the truth; the curve's half-widths in % of peak force."""

    inside: dict[str, list[bool]] = field(default_factory=dict)
    curve_half_width_percent: list[float] = field(default_factory=list)

    def add(self, name: str, low: float, high: float, truth: float) -> None:
        self.inside.setdefault(name, []).append(bool(low <= truth <= high))

    def rate(self, names: list[str] | None = None) -> float:
        """Fraction inside, pooled over the quantities `names` (default every quantity)."""
        pooled = [hit for name, hits in self.inside.items() if names is None or name in names for hit in hits]
        return float(np.mean(pooled))

    def table(self) -> str:
        rows = [
            f"  {name:<16} {np.mean(hits) * 100:5.1f}% of {len(hits)}" for name, hits in self.inside.items()
        ]
        widths = np.array(self.curve_half_width_percent)
        rows.append(
            f"  curve half-width: median {np.median(widths):.2f}%, 90th percentile "
            f"{np.percentile(widths, 90):.2f}% of peak force"
        )
        return "\n".join(rows)


def check(case: Case, result: IdentificationResult, coverage: Coverage) -> None:
    """Add one identification's intervals against the simulated truth."""
    found = result.intervals_json()
    truth = case.vehicle
    for index, (curve, true_curve) in enumerate(zip(result.curves, case.truths, strict=True)):
        band = result.curve_band(index)
        assert band is not None
        true_force = true_curve.force(curve.curve.velocity_m_s)
        peak = float(np.max(np.abs(true_force)))
        for low, high, value in zip(*band, true_force, strict=True):
            coverage.add("curve points", low, high, value)
        coverage.curve_half_width_percent += list(100 * (band[1] - band[0]) / 2 / peak)
    masses = found["masses_kg_interval"]
    assert isinstance(masses, dict)
    wheels = 2 if truth.known.is_axle else 1
    coverage.add("sprung mass", *masses["sprung"], truth.sprung_mass_kg)
    coverage.add("unsprung mass", *masses["unsprung"], (truth.known.mass_kg - truth.sprung_mass_kg) / wheels)
    damping = found["tyre_damping_Ns_per_m_interval"]
    assert isinstance(damping, list)
    coverage.add("tyre damping", *damping, truth.tyre_damping_Ns_per_m)
    stiffness = found["stiffness_N_per_m_interval"]
    assert isinstance(stiffness, dict)
    stated = {"spring": truth.known.spring_stiffness_N_per_m, "tyre": truth.known.tyre_stiffness_N_per_m}
    for name, interval in stiffness.items():
        coverage.add(f"{name} stiffness", *interval, float(stated[name]))


def draws(count: int) -> list[tuple[Case, bool]]:
    """`count` simulated recordings (5 µm noise), fixed seeds, in turn: a quarter car with every constant
    stated, a wide-range quarter car from its mass alone at 1 kHz, and one at 500 Hz. (case, mass only)."""
    out: list[tuple[Case, bool]] = []
    for number in range(count):
        seed = 100 + number
        if number % 3 == 0:
            out.append((quarter_car_case(seed), False))
        else:
            out.append((wide_quarter_car_case(seed, 0.001 if number % 3 == 1 else 0.002), True))
    return out


def identify_case(case: Case, from_mass_only: bool) -> IdentificationResult:
    vehicle = mass_only(case.vehicle.known) if from_mass_only else case.vehicle.known
    return identify(case.result.recording, vehicle, IdentifyOptions(output_error=False))
