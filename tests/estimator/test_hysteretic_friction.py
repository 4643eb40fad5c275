"""Hysteretic (Dahl) friction, estimator.dynamics: the law's state along a measured deflection, which the
model doctor's equations use (hysteresis_interval_mean), against the ODE the simulation integrates
(hysteresis_rate), on random paths with fixed seeds."""

from __future__ import annotations

import numpy as np
import pytest

from estimator.friction import hysteresis_interval_mean, hysteresis_rate


def _fine_dahl(deflection_m: np.ndarray, presliding_m: float, per_sample: int) -> np.ndarray:
    """h of ḣ = (v − |v|·h)/z by explicit Euler on the path refined `per_sample` times (linear between
    samples), at every fine point: the reference, slow and simple."""
    fine_t = np.arange((deflection_m.size - 1) * per_sample + 1) / per_sample
    path = np.interp(fine_t, np.arange(deflection_m.size), deflection_m)
    h = np.zeros(path.size)
    for k in range(path.size - 1):
        step = path[k + 1] - path[k]  # v·dt: the law is rate-independent, time cancels
        h[k + 1] = h[k] + float(hysteresis_rate(np.array(step), np.array(h[k]), np.array(presliding_m)))
    return h


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_interval_mean_of_dahls_state_follows_the_ode_on_a_random_path(seed: int) -> None:
    """A random smooth deflection (a few mm, sampled at 1 kHz, reversals every few samples to every few
    hundred) and z of 0.05-0.5 mm: per sample, the closed form's mean over the sample's interval agrees
    with the mean of the ODE integrated 400 times finer within 0.5% of the friction force (Euler's error
    at that refinement)."""
    rng = np.random.default_rng(seed)
    samples, per_sample = 400, 400
    t = np.arange(samples) * 1e-3
    deflection = sum(
        rng.uniform(2e-4, 2e-3) * np.sin(2 * np.pi * rng.uniform(1.0, 60.0) * t + rng.uniform(0, 6.3))
        for _ in range(4)
    )
    presliding = float(np.exp(rng.uniform(np.log(5e-5), np.log(5e-4))))
    fine = _fine_dahl(deflection, presliding, per_sample)
    centre = np.arange(samples) * per_sample
    half = per_sample // 2
    expected = np.array([np.mean(fine[max(c - half, 0) : min(c + half, fine.size - 1) + 1]) for c in centre])
    got = hysteresis_interval_mean(deflection, presliding)
    print(
        f"seed {seed}: z {presliding * 1e3:.3f} mm, largest difference {np.max(np.abs(got - expected)):.2e}"
    )
    assert np.max(np.abs(got - expected)) < 5e-3
    assert np.all(np.abs(got) <= 1.0)


def test_a_reversed_friction_builds_up_over_the_presliding_displacement() -> None:
    """After sliding one way (h at −1 within 1e-6), a reversal moved by z, 2z, 3z brings h to
    1 − 2·e^(−1), 1 − 2·e^(−2), 1 − 2·e^(−3): the force-deflection loop's shape, whatever the sampling."""
    presliding = 1e-4
    down = np.linspace(0.0, -20 * presliding, 201)
    for per_step in (1e-6, 2.5e-5):  # fine and coarse sampling of the way back (z a whole number of steps)
        up = down[-1] + np.arange(1, round(3 * presliding / per_step) + 1) * per_step
        path = np.concatenate([down, up])
        fine = _fine_dahl(path, presliding, 50)[::50]
        assert fine[200] == pytest.approx(-1.0, abs=1e-6)
        for multiple in (1, 2, 3):
            index = 200 + round(multiple * presliding / per_step)
            assert fine[index] == pytest.approx(1 - 2 * np.exp(-multiple), abs=2e-3)
