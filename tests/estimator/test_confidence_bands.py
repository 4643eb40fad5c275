"""The 95% intervals of `identify` (estimator.uncertainty) on simulated recordings with 5 µm noise: they hold
the truth about as often as they claim, and are not made wide to do so."""

from __future__ import annotations

import numpy as np
from band_coverage import Coverage, check, draws, identify_case

DRAWS = 9
"""Three each: every constant stated; mass only at 1 kHz; mass only at 500 Hz (band_coverage.draws)."""


def test_the_bands_hold_the_truth_about_95_percent_of_the_time_and_are_narrow() -> None:
    coverage = Coverage()
    for case, from_mass_only in draws(DRAWS):
        result = identify_case(case, from_mass_only)
        check(case, result, coverage)
    print(f"\ncoverage of the 95% intervals over {DRAWS} simulated recordings:\n{coverage.table()}")
    pooled = coverage.rate()
    print(f"  pooled: {pooled * 100:.1f}%")
    assert 0.75 <= pooled <= 1.0, coverage.table()
    assert coverage.rate(["curve points"]) >= 0.75, coverage.table()
    assert coverage.rate(["sprung mass", "unsprung mass", "tyre damping"]) >= 0.3, coverage.table()
    # not bought with absurd widths: the bands are a small fraction of the force they bound
    assert np.median(coverage.curve_half_width_percent) < 5.0, coverage.table()
    assert np.max(coverage.curve_half_width_percent) < 25.0, coverage.table()


def test_the_intervals_are_in_the_json_beside_the_values() -> None:
    case, from_mass_only = draws(2)[1]
    result = identify_case(case, from_mass_only)
    out = result.to_json()
    curve = out["curves"][0]  # type: ignore[index]
    low, force, high = (np.array(curve[key]) for key in ("force_N_low", "force_N", "force_N_high"))
    assert np.all(low < force) and np.all(force < high)
    masses, interval = out["masses_kg"], out["masses_kg_interval"]  # type: ignore[index]
    for name in ("sprung", "unsprung"):
        assert interval[name][0] < masses[name] < interval[name][1]  # type: ignore[index]
    stiffness = out["stiffness_N_per_m_interval"]
    assert set(stiffness) == {"spring", "tyre"}  # type: ignore[arg-type]
    for name, (lo, hi) in stiffness.items():  # type: ignore[union-attr]
        assert lo < out["stiffness_N_per_m"][name] < hi  # type: ignore[index]
    damping_low, damping_high = out["tyre_damping_Ns_per_m_interval"]  # type: ignore[misc]
    assert damping_low < out["tyre_damping_Ns_per_m"] < damping_high  # type: ignore[operator]
