"""Physical bounds of a job's input: what a vehicle on this bench and a recording of it can be.

The estimator takes any positive number; the service does not, because a value no vehicle has (a mass of
9.2e18 kg, a stiffness of 1e-300 N/m) either "succeeds" with a result that means nothing or fails deep in
numpy with a message nobody can act on. The bounds span lab rigs of a few kilograms up to truck axles,
with a margin (README, "The bench service"). A value outside them is refused at submit (422) with the
key, the value and the range, and the same check runs again in the worker before identifying.

Recordings: every value is finite (the CSV reader already refuses NaN and infinity); displacements lie
within ±MAX_DISPLACEMENT_M of the static position (the plate moves a few millimetres, a suspension travels
at most a few decimetres); the recording lasts at least MIN_DURATION_S; the grid's sample time lies within
SAMPLE_TIME_BOUNDS_S. Whether the grid can carry the sweep is estimator.bandwidth's question.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from estimator.bandwidth import InsufficientBandwidthError, check_bandwidth
from estimator.recording import Recording
from estimator.vehicle import VehicleParameters
from service.jobs.input_error import InputError


@dataclass(frozen=True)
class Bound:
    low: float
    high: float
    unit: str

    def holds(self, value: float) -> bool:
        return math.isfinite(value) and self.low <= value <= self.high

    def describe(self) -> str:
        return f"{self.low:g} to {self.high:g} {self.unit}"


VEHICLE_BOUNDS: dict[str, Bound] = {
    "mass_kg": Bound(1.0, 20_000.0, "kg"),
    "spring_stiffness_N_per_m": Bound(100.0, 1e7, "N/m"),
    "tyre_stiffness_N_per_m": Bound(100.0, 1e8, "N/m"),
    "track_m": Bound(0.05, 3.0, "m"),
    "anti_roll_bar_stiffness_N_per_m": Bound(0.0, 1e7, "N/m"),
}
"""Vehicle-file keys -> accepted range. mass_kg: a lab rig of a kilogram to a truck axle's 20 t carried
mass; stiffnesses: a lab spring of 100 N/m to a truck's; track_m: a rig's 5 cm to a truck's 3 m."""

MAX_DISPLACEMENT_M = 1.0
"""Largest |displacement| accepted in a recording (m)."""
MIN_DURATION_S = 1.0
"""Shortest recording accepted (s): less holds no sweep worth identifying."""
SAMPLE_TIME_BOUNDS_S = Bound(1e-5, 0.5, "s")
"""The grid's sample time: 100 kHz to 2 Hz (the bandwidth check then judges it against the sweep)."""


def check_vehicle_bounds(vehicle: VehicleParameters, field: str = "vehicle") -> None:
    """InputError naming the key, its value and the accepted range, for the first value out of bounds."""
    for key, bound in VEHICLE_BOUNDS.items():
        value = getattr(vehicle, key)
        if value is None:
            continue
        if not bound.holds(float(value)):
            raise InputError(
                field,
                f"{key} = {float(value):g} is outside the accepted {bound.describe()} "
                "(lab rigs of a few kilograms up to truck axles)",
            )


def check_recording_bounds(recording: Recording, field: str = "recording") -> None:
    """InputError for a recording no bench makes: too short, a grid out of range, a non-finite or too large
    displacement (naming the channel and the time of the first such sample), or too coarse a grid for its
    sweep (estimator.bandwidth)."""
    dt = recording.sample_time_s
    if not SAMPLE_TIME_BOUNDS_S.holds(dt):
        raise InputError(
            field, f"sample time {dt:g} s is outside the accepted {SAMPLE_TIME_BOUNDS_S.describe()}"
        )
    duration = float(recording.time_s[-1] - recording.time_s[0])
    if not duration >= MIN_DURATION_S:
        raise InputError(
            field, f"the recording lasts {duration:g} s; at least {MIN_DURATION_S:g} s is needed"
        )
    for name, values in recording.channels.items():
        bad = np.flatnonzero(~(np.abs(values) <= MAX_DISPLACEMENT_M))  # NaN and inf included
        if bad.size:
            i = int(bad[0])
            raise InputError(
                field,
                f"channel {name} reads {float(values[i]):g} m at t = {float(recording.time_s[i]):g} s; "
                f"displacements beyond ±{MAX_DISPLACEMENT_M:g} m are not a vehicle on the plate",
            )
    try:
        check_bandwidth(recording)
    except InsufficientBandwidthError as exc:
        raise InputError(field, str(exc)) from None


def check_physical_bounds(recording: Recording, vehicle: VehicleParameters) -> None:
    """Both checks; every job kind runs it at submit and again in the worker."""
    check_vehicle_bounds(vehicle)
    check_recording_bounds(recording)


def check_recording_fits(recording: Recording, vehicle: VehicleParameters) -> None:
    """InputError (field recording) when the recording's channels are not those of the vehicle file's
    model: an axle recording with a quarter-car file, or the other way round. Every job kind checks this."""
    if vehicle.is_axle != recording.is_axle:
        has = "axle" if recording.is_axle else "quarter-car"
        raise InputError(
            "recording",
            f"the recording has {has} channels but the vehicle file is for a {vehicle.model.value}",
        )
