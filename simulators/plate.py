"""The plate of a simulated bench: runs a commanded sweep in simulated time, with controlled and emergency
stops. Alone it is an empty bench (`EmptyPlate`); the vehicle bench puts a car on it."""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass

import numpy as np

from estimator.sweep import SweepSettings
from simulators.coupling import PlateState, PlateStatus, SimulatedClock
from simulators.excitation import sweep_frequency_Hz, sweep_position_m

CONTROLLED_STOP_RAMP_S = 0.5
"""A controlled stop ramps the amplitude linearly to zero over this time, then the plate rests at zero."""


@dataclass
class _Run:
    settings: SweepSettings
    started_s: float
    stop_requested_s: float | None = None


class SimulatedPlate:
    """Plate kinematics: position follows the sweep law; after the sweep ends the plate stops by itself."""

    def __init__(self, clock: SimulatedClock) -> None:
        self.clock = clock
        self._lock = threading.Lock()
        self._run: _Run | None = None
        self._ended: deque[tuple[float, _Run]] = deque(maxlen=4)
        """Recently ended runs with the time each ended: a device sampling on its own clock may still ask
        where the plate was during one of them."""
        self._held_position_m = 0.0
        self._fault_code = 0

    def start_sweep(self, settings: SweepSettings) -> None:
        with self._lock:
            if self._fault_code:
                raise RuntimeError(f"plate in fault {self._fault_code}; reset first")
            self._run = _Run(settings, self.clock.now_s())

    def stop(self, emergency: bool = False) -> None:
        with self._lock:
            if self._run is None:
                return
            now = self.clock.now_s()
            if emergency:
                self._held_position_m = self._position_locked(now)
                self._end_run(now)
            elif self._run.stop_requested_s is None:
                self._run.stop_requested_s = now

    def set_fault(self, code: int) -> None:
        """Fault injection: the drive trips (plate halts where it is) and reports `code` until reset."""
        with self._lock:
            now = self.clock.now_s()
            self._held_position_m = self._position_locked(now) if self._run else self._held_position_m
            self._end_run(now)
            self._fault_code = code

    def reset_fault(self) -> None:
        with self._lock:
            self._fault_code = 0

    def _envelope(self, run: _Run, now: float) -> float:
        """Amplitude factor 0..1: ramps down after a stop request, zero after the sweep has ended."""
        if now - run.started_s > run.settings.duration_s:
            return 0.0
        if run.stop_requested_s is None:
            return 1.0
        return max(0.0, 1.0 - (now - run.stop_requested_s) / CONTROLLED_STOP_RAMP_S)

    def _end_run(self, now: float) -> None:
        if self._run is not None:
            self._ended.append((now, self._run))
        self._run = None

    def _position_locked(self, now: float) -> float:
        run = self._run
        if run is not None and now < run.started_s:  # asked about a moment before this run began
            run = None
        if run is None:
            ended = next((r for end_s, r in reversed(self._ended) if r.started_s <= now < end_s), None)
            if ended is None:
                return self._held_position_m
            run = ended
        return float(self._envelope(run, now) * sweep_position_m(run.settings, now - run.started_s))

    def position_m(self, t_s: float | None = None) -> float:
        with self._lock:
            return self._position_locked(self.clock.now_s() if t_s is None else t_s)

    def status_at_rest(self) -> bool:
        """No run (sweep or ramp-down) is under way and the plate is held at zero."""
        with self._lock:
            return self._run is None and self._held_position_m == 0.0

    def status(self) -> PlateStatus:
        with self._lock:
            now = self.clock.now_s()
            if self._fault_code:
                return PlateStatus(PlateState.FAULT, 0.0, self._held_position_m, self._fault_code)
            run = self._run
            if run is None or self._envelope(run, now) == 0.0:
                if run is not None:  # finished: settle at rest
                    self._held_position_m = 0.0
                    self._end_run(now)
                return PlateStatus(PlateState.IDLE, 0.0, self._held_position_m)
            state = PlateState.RUNNING if run.stop_requested_s is None else PlateState.STOPPING
            freq = float(sweep_frequency_Hz(run.settings, now - run.started_s))
            return PlateStatus(state, freq, self._position_locked(now))


class EmptyPlate:
    """Nothing on the plate: x_r moves, x_t and x_s stay at zero. Implements PlatePhysics; exists so that
    the exciter and amplifier simulators (and the drivers' tests) run without integrating a vehicle."""

    def __init__(self, clock: SimulatedClock | None = None) -> None:
        self.clock = clock or SimulatedClock()
        self.plate = SimulatedPlate(self.clock)

    def positions_m(self, channel: str, times_s: np.ndarray) -> np.ndarray:
        return np.array([self.position_m(channel, float(t)) for t in times_s])

    def position_m(self, channel: str, at_s: float | None = None) -> float:
        if channel.startswith("x_r"):
            return self.plate.position_m(at_s)
        if channel.startswith(("x_s", "x_t")):
            return 0.0
        raise KeyError(f"unknown channel {channel!r}")

    def start_sweep(self, settings: SweepSettings) -> None:
        self.plate.start_sweep(settings)

    def stop(self, emergency: bool = False) -> None:
        self.plate.stop(emergency)

    def plate_status(self) -> PlateStatus:
        return self.plate.status()
