"""How simulated devices are coupled to the simulated bench physics.

Simulated devices (laser amplifiers, plate exciters) speak the real protocols on real transports; what they
report comes from a `PlatePhysics`: the exciter commands its plate, the amplifiers read its channel positions.
Time is a `SimulatedClock`, advanced explicitly in tests (deterministic, no sleeps) or following the wall
clock when the devices are served to a real client (`shockbench sim-devices`).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Protocol

import numpy as np

from estimator.sweep import SweepSettings


class SimulatedClock:
    """Simulated time in seconds. Manual by default (tests call advance); `follow_wall_clock` ties it to
    time.monotonic for interactive use."""

    def __init__(self, start_s: float = 0.0, follow_wall_clock: bool = False) -> None:
        self._lock = threading.Lock()
        self._manual_s = start_s
        self._wall_origin = time.monotonic() - start_s if follow_wall_clock else None

    def now_s(self) -> float:
        if self._wall_origin is not None:
            return time.monotonic() - self._wall_origin
        with self._lock:
            return self._manual_s

    def advance(self, dt_s: float) -> float:
        """Move manual time forward by dt_s (>= 0) and return the new time."""
        if self._wall_origin is not None:
            raise RuntimeError("a wall-clock SimulatedClock cannot be advanced by hand")
        if dt_s < 0:
            raise ValueError("time only moves forward")
        with self._lock:
            self._manual_s += dt_s
            return self._manual_s


class PlateState(StrEnum):
    IDLE = "idle"
    RUNNING = "running"
    STOPPING = "stopping"
    FAULT = "fault"


@dataclass
class PlateStatus:
    """What a plate exciter controller knows about its plate at one instant."""

    state: PlateState
    frequency_Hz: float
    position_m: float
    fault_code: int = 0
    extra: dict[str, float] = field(default_factory=dict)


class PlatePhysics(Protocol):
    """The plate and what stands on it, as the simulated devices see it (all at clock.now_s()). The one
    interface between physics (EmptyPlate, VehicleOnPlate) and devices (exciters, amplifiers), so a device
    is tested on the bare plate and served on a vehicle alike."""

    clock: SimulatedClock

    def position_m(self, channel: str, at_s: float | None = None) -> float:
        """Displacement of a named channel ('x_s', 'x_t', 'x_r', or with '_l'/'_r' for an axle) in metres,
        upward positive, from the static position, now or at a recent past instant at_s (s; what a device
        sampling on its own clock needs). Sensor noise is added by the amplifier, not here."""
        ...

    def positions_m(self, channel: str, times_s: np.ndarray) -> np.ndarray:
        """position_m at many recent instants (ascending, none in the future), in one call."""
        ...

    def start_sweep(self, settings: SweepSettings) -> None: ...

    def stop(self, emergency: bool = False) -> None:
        """Controlled stop (amplitude ramps down) or emergency stop (plate halts at once)."""
        ...

    def plate_status(self) -> PlateStatus: ...
