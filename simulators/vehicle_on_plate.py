"""A simulated bench with a vehicle on the plate, advancing in simulated time: what the simulated devices
read and drive. Implements simulators.coupling.PlatePhysics.

The plate follows the exciter's commands (simulators.plate.SimulatedPlate); the vehicle's equations of motion
(estimator.dynamics) are integrated with Runge-Kutta in steps of at most `step_s` up to the clock's current
time whenever a position is asked for, so a reading always reflects the plate motion up to that instant. An
axle stands with both wheels on plates driven by the one exciter (in phase).

The last `history_s` of integration steps are kept, so a device that samples on its own clock (a buffered
laser amplifier catching up on the samples due since its last read) can ask for a position at a past
instant: `position_m(channel, at_s)` interpolates linearly between the two steps around at_s
(error below 0.1 µm for a 4 mm, 20 Hz plate motion at the default step; the plate itself is exact).
"""

from __future__ import annotations

import itertools
import math
import threading
from collections import deque

import numpy as np

from estimator.dynamics import rk4_step
from estimator.sweep import SweepSettings
from simulators.coupling import PlateStatus, SimulatedClock
from simulators.plate import SimulatedPlate
from simulators.vehicle_sim import SimulatedVehicle

PLATE_VELOCITY_DT_S = 1e-5
REST_STATE_TOLERANCE = 1e-12
"""State entries (m, m/s, N) below this count as the vehicle at rest: integration is skipped while the plate
rests too, so an idle simulated bench costs nothing."""
"""Half-width of the central difference that gives the plate velocity from its position law."""


class VehicleOnPlate:
    """The physics of a vehicle standing on the plate, on a simulated clock. Exists beside EmptyPlate because
    the simulated devices of a whole bench (service.simulated_bench) need the car's motion, not only the
    plate's; it is the bench's physics, not a bench (the devices and their configuration are
    SimulatedBench's)."""

    def __init__(
        self,
        vehicle: SimulatedVehicle,
        clock: SimulatedClock | None = None,
        step_s: float = 0.0005,
        sample_time_s: float = 0.001,
        history_s: float = 2.0,
    ) -> None:
        self.clock = clock or SimulatedClock()
        self.plate = SimulatedPlate(self.clock)
        self.vehicle = vehicle
        self.physics = vehicle.physics(sample_time_s)
        self.step_s = step_s
        self._lock = threading.Lock()
        self._state = np.zeros(self.physics.state_size)
        self._time_s = self.clock.now_s()
        self.time_origin_s = self._time_s
        """Steps fall on time_origin_s + k * step_s: a device sampling on the same grid reads exact states."""
        history_steps = max(2, int(history_s / step_s) + 2)
        self._output_names = tuple(self.physics.outputs(self._state))
        self._history_times_s: deque[float] = deque([self._time_s], maxlen=history_steps)
        self._history_outputs: deque[np.ndarray] = deque(
            [self._vehicle_outputs(self._state)], maxlen=history_steps
        )
        self._next: tuple[float, np.ndarray, np.ndarray] | None = None  # (from time, state, outputs)
        plates = ("x_r_l", "x_r_r") if vehicle.known.is_axle else ("x_r",)
        self._channels = (*self._output_names, *plates)

    def _vehicle_outputs(self, state: np.ndarray) -> np.ndarray:
        outputs = self.physics.outputs(state)
        return np.array([float(outputs[name]) for name in self._output_names])

    def _at_rest(self) -> bool:
        """The plate rests at zero and the vehicle has settled: stepping would change nothing."""
        return self.plate.status_at_rest() and float(np.max(np.abs(self._state))) < REST_STATE_TOLERANCE

    def _plate_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        x = self.plate.position_m(t)
        v = (
            self.plate.position_m(t + PLATE_VELOCITY_DT_S) - self.plate.position_m(t - PLATE_VELOCITY_DT_S)
        ) / (2 * PLATE_VELOCITY_DT_S)
        if self.vehicle.known.is_axle:
            return np.array([x, x]), np.array([v, v])
        return np.asarray(x), np.asarray(v)

    def _step(self, state: np.ndarray, t: float, h: float) -> np.ndarray:
        (p0, r0), (pm, rm), (p1, r1) = self._plate_at(t), self._plate_at(t + h / 2), self._plate_at(t + h)
        return rk4_step(self.physics.derivatives, state, h, (p0, pm, p1), (r0, rm, r1))

    def _next_step(self) -> tuple[np.ndarray, np.ndarray]:
        """(state, outputs) one whole step after the committed time, computed once per step."""
        if self._next is None or self._next[0] != self._time_s:
            state = self._step(self._state, self._time_s, self.step_s)
            self._next = (self._time_s, state, self._vehicle_outputs(state))
        return self._next[1], self._next[2]

    def _advance(self) -> None:
        """Commit whole steps up to the clock's present. A position inside the step under way is
        interpolated between the committed state and the next one (computed once, and committed when the
        clock gets there), so frequent reads on a wall clock cost no extra integration."""
        now = self.clock.now_s()
        if self._time_s < now - 1e-12 and self._at_rest():  # idle bench: time passes, nothing moves
            if len(self._history_times_s) >= 2 and self._history_times_s[-2] > self._time_s - self.step_s:
                self._history_times_s[-1] = now  # one entry per step at most: the history keeps its span
            else:
                self._history_times_s.append(now)
                self._history_outputs.append(self._history_outputs[-1])
            steps = math.floor((now - self.time_origin_s) / self.step_s + 1e-9)
            self._time_s = max(self._time_s, self.time_origin_s + steps * self.step_s)  # stay on the grid
        while self._time_s + self.step_s <= now + 1e-12:
            self._state, outputs = self._next_step()
            self._time_s += self.step_s
            self._history_times_s.append(self._time_s)
            self._history_outputs.append(outputs)

    def position_m(self, channel: str, at_s: float | None = None) -> float:
        """Displacement of `channel` (m) now, or at the past instant at_s (s) within the kept history."""
        t = self.clock.now_s() if at_s is None else at_s
        return float(self.positions_m(channel, np.array([t]))[0])

    def positions_m(self, channel: str, times_s: np.ndarray) -> np.ndarray:
        """Displacements of `channel` (m) at many recent instants (ascending, none after the present): what
        an amplifier catching up on its own clock asks for, in one call."""
        times_s = np.asarray(times_s, dtype=float)
        with self._lock:
            self._advance()
            if channel.startswith("x_r") and channel in self._channels:
                return np.array([self.plate.position_m(float(t)) for t in times_s])
            try:
                column = self._output_names.index(channel)
            except ValueError:
                raise KeyError(
                    f"unknown channel {channel!r}; this bench has {sorted(self._channels)}"
                ) from None
            if times_s.size == 0:
                return times_s.copy()
            # the history holds about one entry per step, but an idle bench's entries fall where it was read,
            # closer than a step at times: count back by steps, then further until the first time is covered
            entries = len(self._history_times_s)
            keep = min(entries, max(0, int((self._time_s - float(times_s[0])) / self.step_s) + 3))
            while keep < entries and self._history_times_s[entries - keep] > float(times_s[0]):
                keep = min(entries, 2 * keep + 1)
            hist_t = list(itertools.islice(self._history_times_s, entries - keep, None))
            hist_v = [
                v[column]
                for v in itertools.islice(self._history_outputs, len(self._history_outputs) - keep, None)
            ]
            if float(times_s[0]) < hist_t[0] - 1e-12:
                raise ValueError(
                    f"position at t = {times_s[0]:.6f} s asked for; the history starts at {hist_t[0]:.6f} s"
                )
            if float(times_s[-1]) > self._time_s + 1e-12:  # the step under way, interpolated
                hist_t.append(self._time_s + self.step_s)
                hist_v.append(float(self._next_step()[1][column]))
            return np.interp(times_s, hist_t, hist_v)

    def start_sweep(self, settings: SweepSettings) -> None:
        with self._lock:
            self._advance()
            self.plate.start_sweep(settings)
            self._next = None  # the next step was computed with the old plate law

    def stop(self, emergency: bool = False) -> None:
        with self._lock:
            self._advance()
            self.plate.stop(emergency)
            self._next = None

    def plate_status(self) -> PlateStatus:
        """The plate's state now. The plate follows its law on the clock (and has its own lock): no
        integration of the vehicle is needed, so a drive asking for its status every few milliseconds never
        waits behind an amplifier's catch-up, which on a loaded machine held its watchdog up past 0.5 s."""
        return self.plate.status()

    @property
    def channels(self) -> tuple[str, ...]:
        return self._channels
