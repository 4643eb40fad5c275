"""The identification by differential evolution: the physical search box of the paper's unknowns
(de_bounds), the objective as DE sees it in decorrelated or raw coordinates (DEProblem, de_problem), and
the run (run_de). The exact solver certifies how close DE got (estimator.identify)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from estimator.equations import STIFFNESS_NAMES, TYRE_DAMPING, LinearResiduals, population_sum_of_norms
from estimator.identify_options import Coordinates, IdentifyOptions
from estimator.solvers.differential_evolution import DEProgress, DifferentialEvolution
from estimator.vehicle import VehicleConstant, VehicleParameters

SPRUNG_FRACTION_BOUNDS = (0.5, 0.99)
"""DE search range of the sprung mass as a fraction of the mass carried by the wheel(s)."""
TYRE_DAMPING_MAX_NS_PER_M = 5000.0
STIFFNESS_BOUNDS_N_PER_M = {
    VehicleConstant.SPRING: (1e3, 3e5),
    VehicleConstant.TYRE: (3e4, 2e6),
    VehicleConstant.BAR: (0.0, 2e5),
}
"""DE search ranges of free stiffnesses: wheel rates from a motorcycle fork (14 kN/m in the paper) to a
truck; tyres from a motorcycle (101 kN/m) to a truck; anti-roll bars at the wheel."""
LIGHTEST_WHEEL_LOAD_KG = 80.0
"""The lightest mass per wheel the boxes above were drawn for (a motorcycle's corner: 70 kg of body and 10
kg of wheel). A lighter vehicle, a lab's quarter-car rig of a few kilograms, has its stiffness and tyre
damping boxes scaled by its mass per wheel over this (box_scale): a box with the same natural frequencies
√(k/m) and damping ratios c/(2√(k·m)) as the motorcycle's. Unscaled, a 3 kg rig's 3 kN/m tyre lay a tenth
below the tyre box, and DE ended within 1% of the exact optimum on 1 of 10 dev lab rigs (10/10 scaled,
benchmarks/bench_de_light.py)."""
DAMPER_FORCE_MARGIN = 1.5
"""DE searches damper points within ± this × the largest force the body equation can ask of the damper."""


def box_scale(vehicle: VehicleParameters) -> float:
    """What the stiffness and tyre damping boxes are multiplied by: the mass per wheel over
    LIGHTEST_WHEEL_LOAD_KG, at most 1 (every vehicle from a motorcycle up keeps the boxes as drawn)."""
    per_wheel_kg = vehicle.mass_kg / (2 if vehicle.is_axle else 1)
    return min(1.0, per_wheel_kg / LIGHTEST_WHEEL_LOAD_KG)


def de_bounds(system: LinearResiduals, vehicle: VehicleParameters) -> np.ndarray:
    """Physical search box, by unknown: sprung mass fraction, roll inertia, tyre damping, free stiffnesses
    (those two scaled for a vehicle lighter than a motorcycle, box_scale), and the damper forces' box for
    the damper points and a rig's frame guides' frictions (forces too)."""
    mass, scale = vehicle.mass_kg, box_scale(vehicle)
    stiffness_of = {name: constant for constant, name in STIFFNESS_NAMES.items()}
    body_equation = 2 if vehicle.is_axle else 0  # heave, or the quarter car's body
    # the body equation bounds what the dampers can be asked for: |F_d| <~ M·|ẍ_s| + |spring and bar|
    body = np.abs(system.matrix[body_equation, :, 0]) * mass + np.abs(system.offset[body_equation])
    for index, name in enumerate(system.parameter_names):
        if name in stiffness_of:
            upper = STIFFNESS_BOUNDS_N_PER_M[stiffness_of[name]][1] * scale
            body = body + upper * np.abs(system.matrix[body_equation, :, index])
    force_limit = DAMPER_FORCE_MARGIN * float(np.max(body))
    bounds: list[tuple[float, float]] = []
    for name in system.parameter_names:
        if name == "sprung_mass_kg":
            bounds.append((SPRUNG_FRACTION_BOUNDS[0] * mass, SPRUNG_FRACTION_BOUNDS[1] * mass))
        elif name == "roll_inertia_kg_m2":
            bounds.append((0.0, mass * float(vehicle.track_m) ** 2 / 2.0))
        elif name == TYRE_DAMPING:
            bounds.append((0.0, TYRE_DAMPING_MAX_NS_PER_M * scale))
        elif name in stiffness_of:
            lower, upper = STIFFNESS_BOUNDS_N_PER_M[stiffness_of[name]]
            bounds.append((lower * scale, upper * scale))
        else:
            bounds.append((-force_limit, force_limit))
    return np.array(bounds)


@dataclass(frozen=True)
class DEProblem:
    """The paper's objective as DE sees it: search box and the map from search coordinates to θ."""

    system: LinearResiduals
    transform: np.ndarray
    centre: np.ndarray
    bounds: np.ndarray

    def theta(self, z: np.ndarray) -> np.ndarray:
        return self.centre + z @ self.transform.T

    def objective(self, z: np.ndarray) -> np.ndarray:
        """GF in float64 for one point (p,) or a population (P, p) of search coordinates."""
        return self.system.objective(self.theta(z))

    def population_objective32(self) -> Callable[[np.ndarray], np.ndarray]:
        """GF of a whole population in float32 (half the memory traffic; DE only ranks with it)."""
        flat = np.ascontiguousarray(self.system.matrix.reshape(-1, self.system.n_params).T)
        equations = self.system.matrix.shape[0]
        flat32 = (self.transform.T @ flat).astype(np.float32)
        offset32 = (self.system.offset.reshape(-1) + self.centre @ flat).astype(np.float32)

        def objective(z: np.ndarray) -> np.ndarray:
            return population_sum_of_norms(z.astype(np.float32), flat32, offset32, equations)

        return objective


def de_problem(system: LinearResiduals, vehicle: VehicleParameters, coordinates: Coordinates) -> DEProblem:
    bounds = de_bounds(system, vehicle)
    if coordinates is Coordinates.RAW:
        return DEProblem(system, np.eye(system.n_params), np.zeros(system.n_params), bounds)
    flat = system.matrix.reshape(-1, system.n_params)
    chol = np.linalg.cholesky(flat.T @ flat)
    half = np.abs(chol.T) @ ((bounds[:, 1] - bounds[:, 0]) / 2.0)  # the θ box seen in z, enclosed
    return DEProblem(system, np.linalg.inv(chol.T), bounds.mean(axis=1), np.column_stack([-half, half]))


def run_de(
    system: LinearResiduals,
    vehicle: VehicleParameters,
    options: IdentifyOptions,
    progress: Callable[[DEProgress], bool | None] | None = None,
    cancel: threading.Event | None = None,
) -> tuple[np.ndarray, int, bool]:
    """DE on the paper's objective; returns θ, generations run, and whether it was cancelled."""
    problem = de_problem(system, vehicle, options.de_coordinates)
    solver = DifferentialEvolution(
        problem.population_objective32(), problem.bounds, options.de, progress, cancel
    )
    result = solver.solve()
    return problem.theta(result.theta), result.generations, result.cancelled
