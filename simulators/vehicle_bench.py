"""A simulated bench with a vehicle on the plate, advancing in simulated time: what the simulated devices
read and drive. Implements simulators.coupling.BenchPhysics.

The plate follows the exciter's commands (simulators.plate.SimulatedPlate); the vehicle's equations of motion
(estimator.dynamics) are integrated with Runge-Kutta in steps of at most `step_s` up to the clock's current
time whenever a position is asked for, so a reading always reflects the plate motion up to that instant. An
axle stands with both wheels on plates driven by the one exciter (in phase).
"""

from __future__ import annotations

import threading

import numpy as np

from drivers.exciter.sweep import SweepSettings
from estimator.dynamics import rk4_step
from simulators.coupling import PlateStatus, SimulatedClock
from simulators.plate import SimulatedPlate
from simulators.vehicle_sim import SimulatedVehicle

PLATE_VELOCITY_DT_S = 1e-5
"""Half-width of the central difference that gives the plate velocity from its position law."""


class VehicleBench:
    def __init__(
        self,
        vehicle: SimulatedVehicle,
        clock: SimulatedClock | None = None,
        step_s: float = 0.0005,
        sample_time_s: float = 0.001,
    ) -> None:
        self.clock = clock or SimulatedClock()
        self.plate = SimulatedPlate(self.clock)
        self.vehicle = vehicle
        self.physics = vehicle.physics(sample_time_s)
        self.step_s = step_s
        self._lock = threading.Lock()
        self._state = np.zeros(self.physics.state_size)
        self._time_s = self.clock.now_s()
        self._outputs: dict[str, float] = {}
        self._refresh_outputs()

    def _plate_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        x = self.plate.position_m(t)
        v = (
            self.plate.position_m(t + PLATE_VELOCITY_DT_S) - self.plate.position_m(t - PLATE_VELOCITY_DT_S)
        ) / (2 * PLATE_VELOCITY_DT_S)
        if self.vehicle.known.is_axle:
            return np.array([x, x]), np.array([v, v])
        return np.asarray(x), np.asarray(v)

    def _advance(self) -> None:
        now = self.clock.now_s()
        while self._time_s < now - 1e-12:
            h = min(self.step_s, now - self._time_s)
            t = self._time_s
            (p0, r0), (pm, rm), (p1, r1) = self._plate_at(t), self._plate_at(t + h / 2), self._plate_at(t + h)
            self._state = rk4_step(self.physics.derivatives, self._state, h, (p0, pm, p1), (r0, rm, r1))
            self._time_s = t + h
        self._refresh_outputs()

    def _refresh_outputs(self) -> None:
        out = {name: float(value) for name, value in self.physics.outputs(self._state).items()}
        plate = self.plate.position_m(self._time_s)
        if self.vehicle.known.is_axle:
            out |= {"x_r_l": plate, "x_r_r": plate}
        else:
            out["x_r"] = plate
        self._outputs = out

    def position_m(self, channel: str) -> float:
        with self._lock:
            self._advance()
            try:
                return self._outputs[channel]
            except KeyError:
                raise KeyError(
                    f"unknown channel {channel!r}; this bench has {sorted(self._outputs)}"
                ) from None

    def start_sweep(self, settings: SweepSettings) -> None:
        with self._lock:
            self._advance()
            self.plate.start_sweep(settings)

    def stop(self, emergency: bool = False) -> None:
        with self._lock:
            self._advance()
            self.plate.stop(emergency)

    def plate_status(self) -> PlateStatus:
        with self._lock:
            self._advance()
            return self.plate.status()

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self._outputs)
