"""The time series the candidate effects are made of, and how an effect's force enters the equations.

The equations of motion (estimator.equations) are, per selected sample, a few residual forces in newtons:
quarter car [body, wheel]; axle [left wheel, right wheel, heave, roll/(b/2)]. A force acting in a suspension
(between body and wheel, like the damper) enters them as the damper basis does; a force acting in a tyre
(between wheel and plate) enters its wheel equation only. Every column is filtered by the same equation
low-pass as the rest of the system (estimator.signals), so the equations keep holding exactly after filtering.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimator.digital_filters import first_order_filter
from estimator.equations import LinearResiduals
from estimator.recording import Recording
from estimator.signals import lowpass
from estimator.vehicle import VehicleParameters

INTERVAL_POINTS = 16
"""Points per sample interval at which interval_mean evaluates its function."""

QUARTER_CAR_EQUATIONS = ("body", "wheel")
AXLE_EQUATIONS = ("left wheel", "right wheel", "heave", "roll")


@dataclass(frozen=True)
class Corner:
    """One suspension corner's signals over the whole recording (kinematics low-pass, metres and m/s).

    suffix: "" for a quarter car, "_l" or "_r" for the sides of an axle."""

    suffix: str
    deflection_m: np.ndarray
    """Suspension deflection ζ = x_s − x_t."""
    velocity_m_s: np.ndarray
    """Suspension velocity v = ẋ_s − ẋ_t (extension positive)."""
    spring_deflection_m: np.ndarray
    """ζ as measured (raw channels, for the equations' spring term K_s·ζ)."""
    tyre_deflection_m: np.ndarray
    """Tyre deflection δ = x_t − x_r as measured (raw channels, for the equations' tyre spring term)."""
    tyre_deflection_smooth_m: np.ndarray
    """δ after the kinematics low-pass (for deciding where the tyre leaves the plate)."""
    tyre_rate_m_s: np.ndarray
    """Tyre deflection rate δ̇."""


class EquationSignals:
    """Signals of one recording (as corrected for the model's channel errors) and the system built on it."""

    def __init__(self, recording: Recording, vehicle: VehicleParameters, system: LinearResiduals) -> None:
        self.recording = recording
        self.vehicle = vehicle
        self.system = system
        self.sample_time_s = recording.sample_time_s
        kin = system.kinematics
        self.corners: list[Corner] = []
        for suffix in ("_l", "_r") if vehicle.is_axle else ("",):
            body, wheel, plate = kin[f"x_s{suffix}"], kin[f"x_t{suffix}"], kin[f"x_r{suffix}"]
            raw = recording.channels
            self.corners.append(
                Corner(
                    suffix=suffix,
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
        return AXLE_EQUATIONS if self.vehicle.is_axle else QUARTER_CAR_EQUATIONS

    def eq(self, series: np.ndarray) -> np.ndarray:
        """The equation low-pass of a full-length series, at the system's selected samples."""
        filtered = lowpass(series, self.system.filters.equation_cutoff_Hz, self.sample_time_s)
        return filtered[self.system.sample_index]

    def maxwell_regressor(self, rate_m_s: np.ndarray) -> np.ndarray:
        """g with f_v = C_d·g for the Maxwell element τ·ḟ_v + f_v = C_d·δ̇, τ = Δt·ϑ/(1−ϑ).

        Deviation from the paper's eq (4) (backward Euler, which identify follows): the element is
        discretised by the bilinear transform, g_k = a·g_(k−1) + b·(δ̇_k + δ̇_(k−1)) with
        a = (2τ − Δt)/(2τ + Δt), b = Δt/(2τ + Δt). It matches the continuous element the output error
        simulates; with eq (4) the simulated sweeps of the tests come out with C_d about 6% high and twice
        the gap."""
        dt = self.sample_time_s
        tau = self.vehicle.maxwell_time_constant_s(dt)
        pole = (2.0 * tau - dt) / (2.0 * tau + dt)
        gain = dt / (2.0 * tau + dt)
        return first_order_filter((gain, gain), -pole, rate_m_s)

    def suspension_column(self, per_corner: list[np.ndarray]) -> np.ndarray:
        """(equations, samples) column of a force acting in each suspension (pushes the wheel up and the body
        down, like the damper); per_corner holds one full-length series per corner."""
        parts = [self.eq(series) for series in per_corner]
        if not self.vehicle.is_axle:
            return np.stack([parts[0], -parts[0]])
        left, right = parts
        return np.stack([-left, -right, left + right, left - right])

    def tyre_column(self, per_corner: list[np.ndarray]) -> np.ndarray:
        """(equations, samples) column of a force the wheel exerts on its tyre (adds to K_t·δ in the wheel
        equation, as the tyre's viscous force does)."""
        parts = [self.eq(series) for series in per_corner]
        zero = np.zeros_like(parts[0])
        if not self.vehicle.is_axle:
            return np.stack([zero, parts[0]])
        return np.stack([parts[0], parts[1], zero, zero])


def restrict(system: LinearResiduals, keep: np.ndarray) -> LinearResiduals:
    """The same system on a subset of its selected samples (keep: boolean over system.sample_index)."""
    return LinearResiduals(
        matrix=system.matrix[:, keep],
        offset=system.offset[:, keep],
        parameter_names=system.parameter_names,
        grids_m_s=system.grids_m_s,
        curve_slices=system.curve_slices,
        tyre_model=system.tyre_model,
        filters=system.filters,
        sample_index=system.sample_index[keep],
        velocity_m_s=[v[keep] for v in system.velocity_m_s],
        kinematics=system.kinematics,
    )


def with_columns(
    system: LinearResiduals, columns: dict[str, np.ndarray], offset: np.ndarray
) -> LinearResiduals:
    """The system with extra unknowns appended (each column (equations, samples)) and a new offset."""
    if not columns:
        matrix = system.matrix
    else:
        matrix = np.concatenate([system.matrix, np.stack(list(columns.values()), axis=2)], axis=2)
    return LinearResiduals(
        matrix=matrix,
        offset=offset,
        parameter_names=[*system.parameter_names, *columns],
        grids_m_s=system.grids_m_s,
        curve_slices=system.curve_slices,
        tyre_model=system.tyre_model,
        filters=system.filters,
        sample_index=system.sample_index,
        velocity_m_s=system.velocity_m_s,
        kinematics=system.kinematics,
    )


def interval_mean(function: Callable[[np.ndarray], np.ndarray], series: np.ndarray) -> np.ndarray:
    """Per sample, the mean of function(series(t)) over the sample's own interval (half a sample time either
    side), with the series linear between samples (INTERVAL_POINTS points per interval; the ends held). A
    force that steps where the series crosses zero (Coulomb friction against the suspension velocity) acts
    for the part of the interval on either side of the crossing; taken at the sample instants it switches a
    whole sample early or late. At 2 ms sampling on the independent world the zero crossings of the fast
    half of the sweep fall between samples, with the velocity tens of mm/s either side: a car with 109 N of
    friction fitted 103 N at 2.9 standard errors with the pointwise column, 108 N at 3.4 with this one."""
    before = np.concatenate([series[:1], series[:-1]])
    after = np.concatenate([series[1:], series[-1:]])
    total = np.zeros_like(series, dtype=float)
    for k in range(INTERVAL_POINTS):
        fraction = (k + 0.5) / INTERVAL_POINTS - 0.5
        neighbour = before if fraction < 0.0 else after
        total += function(series + (neighbour - series) * abs(fraction))
    return total / INTERVAL_POINTS
