"""The figures inspection lanes report today, computed from the same sweep for comparison.

- EUSAMA adhesion: minimum tyre-plate contact force over the static wheel load, in percent (0 when the wheel
  leaves the plate). The contact force is the static load plus the dynamic tyre force −K_t·δ − f_v, with f_v
  from the identified tyre model.
- Phase shift (the "phase-shift method"): φ(f) = 180° − |arg(F_c/x_r)|, the phase between plate displacement
  and contact force folded so that a tyre that follows the plate like a spring gives 180° and a wheel hopping
  free of damping approaches 0°. Reported is the minimum over the sweep's frequencies at or above
  PHASE_MIN_FREQUENCY_HZ (below it the contact force is mostly the inertia of the whole vehicle and the
  phase says nothing about the damper). Complex amplitudes come from demodulating both signals with the
  plate's own phase (Hilbert transform) over sliding windows.
- Damping ratio: of the body mode with the energy-equivalent linear damper, c_eq = Σ F_d(v)·v / Σ v² over
  the measured suspension velocities, ζ = c_eq / (2·sqrt(K·M_s)) with the sprung mass of the corner.
- Axle: the same per side, and the left/right imbalance (EUSAMA difference in points, c_eq difference in %
  of the larger).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimator.digital_filters import analytic_signal
from estimator.order_statistics import median

PHASE_MIN_FREQUENCY_HZ = 5.0
PHASE_WINDOW_S = 0.5
PHASE_STEP_S = 0.1


@dataclass(frozen=True)
class CornerInspection:
    eusama_percent: float
    phase_shift_min_deg: float
    damping_ratio: float
    equivalent_damping_Ns_per_m: float

    def as_dict(self) -> dict[str, float]:
        return {
            "eusama_percent": self.eusama_percent,
            "phase_shift_min_deg": self.phase_shift_min_deg,
            "damping_ratio": self.damping_ratio,
            "equivalent_damping_Ns_per_m": self.equivalent_damping_Ns_per_m,
        }


def eusama_percent(static_load_N: float, dynamic_force_N: np.ndarray) -> float:
    contact = static_load_N + np.asarray(dynamic_force_N)
    return float(100.0 * max(0.0, float(np.min(contact))) / static_load_N)


def phase_shift_min_deg(
    plate_m: np.ndarray,
    force_N: np.ndarray,
    sample_time_s: float,
    min_frequency_Hz: float = PHASE_MIN_FREQUENCY_HZ,
) -> float:
    """Minimum of 180° − |arg(F/x_r)| over windows whose plate frequency is >= min_frequency_Hz (nan when the
    sweep never gets there)."""
    analytic = analytic_signal(plate_m - np.mean(plate_m))
    phase = np.unwrap(np.angle(analytic))
    frequency = np.gradient(phase, sample_time_s) / (2 * np.pi)
    reference = np.exp(-1j * phase)
    window, step = int(PHASE_WINDOW_S / sample_time_s), int(PHASE_STEP_S / sample_time_s)
    force = force_N - np.mean(force_N)
    amplitude = np.abs(analytic)
    starts = np.arange(0, plate_m.size - window, step)
    if starts.size == 0:
        return float("nan")
    windows = starts[:, None] + np.arange(window)  # every window at once
    skipped = (median(frequency[windows], axis=1) < min_frequency_Hz) | (
        median(amplitude[windows], axis=1) < 0.2 * np.max(amplitude)
    )
    kept = windows[~skipped]
    a_plate = np.mean(plate_m[kept] * reference[kept], axis=1)
    a_force = np.mean(force[kept] * reference[kept], axis=1)
    usable = np.abs(a_plate) != 0
    if not np.any(usable):
        return float("nan")
    shifts = 180.0 - np.abs(np.degrees(np.angle(a_force[usable] / a_plate[usable])))
    return float(np.min(shifts))


def equivalent_damping(force_N: np.ndarray, velocity_m_s: np.ndarray) -> float:
    """The linear damping coefficient that dissipates the same energy over the measured velocities."""
    return float(np.sum(force_N * velocity_m_s) / np.sum(velocity_m_s**2))


def corner_inspection(
    *,
    static_load_N: float,
    dynamic_force_N: np.ndarray,
    plate_m: np.ndarray,
    sample_time_s: float,
    damper_force_N: np.ndarray,
    velocity_m_s: np.ndarray,
    spring_stiffness_N_per_m: float,
    sprung_mass_kg: float,
) -> CornerInspection:
    c_eq = equivalent_damping(damper_force_N, velocity_m_s)
    return CornerInspection(
        eusama_percent=eusama_percent(static_load_N, dynamic_force_N),
        phase_shift_min_deg=phase_shift_min_deg(plate_m, dynamic_force_N, sample_time_s),
        damping_ratio=float(c_eq / (2.0 * np.sqrt(spring_stiffness_N_per_m * sprung_mass_kg))),
        equivalent_damping_Ns_per_m=c_eq,
    )


def imbalance(left: CornerInspection, right: CornerInspection) -> dict[str, float]:
    larger = max(abs(left.equivalent_damping_Ns_per_m), abs(right.equivalent_damping_Ns_per_m), 1e-12)
    return {
        "eusama_difference_points": abs(left.eusama_percent - right.eusama_percent),
        "damping_difference_percent": 100.0
        * abs(left.equivalent_damping_Ns_per_m - right.equivalent_damping_Ns_per_m)
        / larger,
    }
