"""The signals the effect families are made of, and how a family's force enters the equations of motion
(estimator.equations: per selected sample, residual forces in N): filtered by the same equation low-pass,
so that the equations still hold exactly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from estimator.digital_filters import first_order_filter
from estimator.equations import LinearResiduals
from estimator.recording import Recording
from estimator.signals import lowpass
from estimator.vehicle import VehicleParameters

INTERVAL_POINTS = 16
"""Points per sample interval at which interval_mean evaluates its function."""


@dataclass(frozen=True)
class Corner:
    """One corner's signals over the whole recording (m, m/s): deflection ζ = x_s − x_t and its rate
    (kinematics low-pass), ζ and the tyre deflection δ = x_t − x_r as measured (for the equations' spring
    terms), δ low-passed (where the tyre leaves the plate) and its rate."""

    deflection_m: np.ndarray
    velocity_m_s: np.ndarray
    spring_deflection_m: np.ndarray
    tyre_deflection_m: np.ndarray
    tyre_deflection_smooth_m: np.ndarray
    tyre_rate_m_s: np.ndarray


class EquationSignals:
    """Signals of one recording (as corrected for the model's channel errors) and the system built on it."""

    def __init__(self, recording: Recording, vehicle: VehicleParameters, system: LinearResiduals) -> None:
        self.recording = recording
        self.vehicle = vehicle
        self.system = system
        self.sample_time_s = recording.sample_time_s
        kin, raw = system.kinematics, recording.channels
        self.corners: list[Corner] = []
        for suffix in ("_l", "_r") if vehicle.is_axle else ("",):
            body, wheel, plate = kin[f"x_s{suffix}"], kin[f"x_t{suffix}"], kin[f"x_r{suffix}"]
            self.corners.append(
                Corner(
                    deflection_m=body.position_m - wheel.position_m,
                    velocity_m_s=body.velocity_m_s - wheel.velocity_m_s,
                    spring_deflection_m=raw[f"x_s{suffix}"] - raw[f"x_t{suffix}"],
                    tyre_deflection_m=raw[f"x_t{suffix}"] - raw[f"x_r{suffix}"],
                    tyre_deflection_smooth_m=wheel.position_m - plate.position_m,
                    tyre_rate_m_s=wheel.velocity_m_s - plate.velocity_m_s,
                )
            )

    @property
    def equations(self) -> tuple[str, ...]:
        if self.vehicle.is_axle:
            return ("left wheel", "right wheel", "heave", "roll")
        return ("body", "wheel")

    def eq(self, series: np.ndarray) -> np.ndarray:
        """The equation low-pass of a full-length series, at the system's selected samples."""
        filtered = lowpass(series, self.system.filters.equation_cutoff_Hz, self.sample_time_s)
        return filtered[self.system.sample_index]

    def maxwell_regressor(self, rate_m_s: np.ndarray) -> np.ndarray:
        """g with f_v = C_d·g for the Maxwell element τ·ḟ_v + f_v = C_d·δ̇, τ = Δt·ϑ/(1−ϑ), by the bilinear
        transform, not the paper's backward Euler (eq 4): it matches the continuous element simulated."""
        dt = self.sample_time_s
        tau = self.vehicle.maxwell_time_constant_s(dt)
        pole = (2.0 * tau - dt) / (2.0 * tau + dt)
        gain = dt / (2.0 * tau + dt)
        return first_order_filter((gain, gain), -pole, rate_m_s)

    def suspension_column(self, per_corner: list[np.ndarray]) -> np.ndarray:
        """(equations, samples) column of a force in each suspension, like the damper (a series a corner)."""
        parts = [self.eq(series) for series in per_corner]
        if not self.vehicle.is_axle:
            return np.stack([parts[0], -parts[0]])
        left, right = parts
        return np.stack([-left, -right, left + right, left - right])

    def tyre_column(self, per_corner: list[np.ndarray]) -> np.ndarray:
        """(equations, samples) column of a force in each tyre (in its wheel equation, beside K_t·δ)."""
        parts = [self.eq(series) for series in per_corner]
        zero = np.zeros_like(parts[0])
        if not self.vehicle.is_axle:
            return np.stack([zero, parts[0]])
        return np.stack([parts[0], parts[1], zero, zero])


def with_columns(
    system: LinearResiduals, columns: dict[str, np.ndarray], offset: np.ndarray
) -> LinearResiduals:
    """The system with extra unknowns appended (each column (equations, samples)) and a new offset."""
    matrix = system.matrix
    if columns:
        matrix = np.concatenate([matrix, np.stack(list(columns.values()), axis=2)], axis=2)
    names = [*system.parameter_names, *columns]
    return replace(system, matrix=matrix, offset=offset, parameter_names=names, tyre_theta=None, _flat=None)


def interval_mean(function: Callable[[np.ndarray], np.ndarray], series: np.ndarray) -> np.ndarray:
    """Per sample, the mean of function(series(t)) over its own interval (the series linear between samples):
    a force that steps at a zero crossing acts for its share of the interval, not a sample early or late."""
    before = np.concatenate([series[:1], series[:-1]])
    after = np.concatenate([series[1:], series[-1:]])
    total = np.zeros_like(series, dtype=float)
    for k in range(INTERVAL_POINTS):
        fraction = (k + 0.5) / INTERVAL_POINTS - 0.5
        neighbour = before if fraction < 0.0 else after
        total += function(series + (neighbour - series) * abs(fraction))
    return total / INTERVAL_POINTS
