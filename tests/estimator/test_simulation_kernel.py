"""The compiled output-error simulation (estimator.simulation_kernel) against the Python reference integrator
(estimator.dynamics.integrate_rk4): random models with fixed seeds, quarter car and axle, every effect the
doctor simulates (spring hinges and Stribeck friction among them), populations of several columns, one
diverging model; the trajectories agree to 1e-9 relative (to each trajectory's amplitude up to that step).

Every test runs with both forms of the kernel: the extension built ahead of time (built here by
compile_ahead when the tree has none for the present source) and numba's just-in-time compile (once per
machine, numba's on-disk cache). The cases are short (1.5 s at 1 kHz) so that the Python reference stays
cheap.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import estimator.simulation_kernel as simulation_kernel
from estimator.damper import CurveBatch, PiecewiseLinearCurve
from estimator.dynamics import (
    HINGES,
    AxlePhysics,
    CornerPhysics,
    QuarterCarPhysics,
    integrate_rk4,
)
from estimator.runge_kutta_steps import sample_substeps
from estimator.simulation_kernel import integrate_compiled
from estimator.vehicle import TyreModel
from service.kernel_build import compile_ahead

SAMPLE_TIME_S = 0.001
DURATION_S = 1.5
RELATIVE_TOLERANCE = 1e-9
GRAVITY_M_S2 = 9.81


LOADER = simulation_kernel._kernel
"""The module's kernel loader (the fixture below replaces it while each test runs)."""


@pytest.fixture(scope="module")
def extension_kernel():
    """The ahead-of-time extension's integrate function, built by compile_ahead if missing."""
    assert compile_ahead() == "extension"
    kind, integrate = simulation_kernel._kernel()
    assert kind == "extension"
    return integrate


@pytest.fixture(autouse=True, params=["extension", "numba"])
def kernel(request, monkeypatch, extension_kernel) -> str:
    """Runs the test with the extension built ahead of time, then with numba's just-in-time kernel."""
    if request.param == "extension":
        integrate = extension_kernel
    else:
        from estimator.simulation_kernel_numba import _integrate as integrate
    monkeypatch.setattr(simulation_kernel, "_kernel", lambda: (request.param, integrate))
    return request.param


def test_the_extension_loads_without_numba_and_only_for_its_source(tmp_path) -> None:
    """A fresh process finds the extension for the present source and never imports numba; the
    extension's name carries the digest of the kernel's source, so an edited source falls back to numba."""
    import subprocess
    import sys

    code = "import sys, estimator.simulation_kernel as k; print(k.kernel_in_use(), 'numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["extension", "False"]
    assert simulation_kernel.extension_name().endswith(simulation_kernel.source_digest())


def test_without_an_extension_for_the_present_source_numba_runs_the_kernel(monkeypatch) -> None:
    """A tree whose extension is missing or was built from another source (another digest) falls back to
    numba's just-in-time kernel instead of running a stale one."""
    other_source = simulation_kernel.EXTENSION_PREFIX + "0" * 16
    monkeypatch.setattr(simulation_kernel, "extension_name", lambda: other_source)
    simulation_kernel._extension.cache_clear()
    LOADER.cache_clear()
    try:
        assert LOADER()[0] == "numba"
        assert simulation_kernel.compiled_filters() is None  # the filters solve with LAPACK then
    finally:
        simulation_kernel._extension.cache_clear()
        LOADER.cache_clear()


def assert_same_trajectories(reference: np.ndarray, compiled: np.ndarray) -> None:
    """Equal to RELATIVE_TOLERANCE of each state variable's (per column) largest magnitude so far, at every
    step where the reference is finite; the steps where the state is not finite are the same in both."""
    assert compiled.shape == reference.shape
    finite = np.isfinite(reference)
    scale = np.maximum(np.maximum.accumulate(np.where(finite, np.abs(reference), 0.0), axis=0), 1e-12)
    with np.errstate(invalid="ignore"):  # inf - inf where both diverged; those steps are compared below
        relative = np.where(finite, np.abs(compiled - reference) / scale, 0.0)
    print(f"largest relative difference {np.max(relative):.3g}")
    assert np.max(relative) <= RELATIVE_TOLERANCE, f"largest relative difference {np.max(relative):.3g}"
    assert np.array_equal(np.all(finite, axis=1), np.all(np.isfinite(compiled), axis=1))


def _plate(rng: np.random.Generator, columns: int | None) -> tuple[np.ndarray, np.ndarray]:
    """A 3-18 Hz chirp of 4-8 mm amplitude (per column when `columns` is given), and its rate."""
    t = np.arange(round(DURATION_S / SAMPLE_TIME_S) + 1) * SAMPLE_TIME_S
    shape = (columns, 1) if columns else ()
    amplitude = rng.uniform(0.004, 0.008, shape)
    start, end = rng.uniform(2.0, 4.0, shape), rng.uniform(14.0, 18.0, shape)
    phase = 2 * np.pi * (start * t + 0.5 * (end - start) / DURATION_S * t**2)
    frequency = start + (end - start) / DURATION_S * t
    return amplitude * np.sin(phase), amplitude * 2 * np.pi * frequency * np.cos(phase)


def _curve_forces(rng: np.random.Generator, grid: np.ndarray, columns: int) -> np.ndarray:
    """Dissipative, asymmetric curves: force = c·v with c 800-3000 N·s/m in extension, less in compression."""
    extension = rng.uniform(800.0, 3000.0, columns)
    compression = extension * rng.uniform(0.3, 0.8, columns)
    slope = np.where(grid[:, None] > 0, extension, compression)
    return slope * grid[:, None] * (1.0 + 0.1 * rng.standard_normal((grid.size, columns)))


def _grid(rng: np.random.Generator) -> np.ndarray:
    return np.sort(np.concatenate([[0.0], rng.uniform(-1.0, 1.0, rng.integers(6, 20))]))


def _corner(
    rng: np.random.Generator, columns: int, static_load_N: np.ndarray, tyre_model: TyreModel, effects: bool
) -> CornerPhysics:
    grid = _grid(rng)
    present = (rng.random(columns) < 0.6) if effects else np.zeros(columns, dtype=bool)

    def some(low: float, high: float) -> np.ndarray:
        return np.where(rng.random(columns) < 0.6, rng.uniform(low, high, columns), 0.0) * effects

    return CornerPhysics(
        damper=CurveBatch(grid, _curve_forces(rng, grid, columns)),
        spring_stiffness_N_per_m=rng.uniform(15e3, 40e3, columns),
        tyre_stiffness_N_per_m=rng.uniform(150e3, 300e3, columns),
        tyre_model=tyre_model,
        tyre_damping_Ns_per_m=rng.uniform(100.0, 600.0, columns),
        maxwell_time_constant_s=float(rng.uniform(0.01, 0.05)),
        coulomb_friction_N=some(20.0, 150.0),
        cubic_spring_N_per_m3=some(1e6, 3e7),
        tyre_liftoff=present,
        static_wheel_load_N=static_load_N,
        tyre_dashpot_Ns_per_m=some(50.0, 400.0),
    )


def _quarter_car(seed: int, columns: int, tyre_model: TyreModel, effects: bool) -> QuarterCarPhysics:
    rng = np.random.default_rng(seed)
    sprung, unsprung = rng.uniform(150.0, 500.0, columns), rng.uniform(25.0, 60.0, columns)
    # a lightly loaded wheel (a fraction of the quarter's weight) lifts off within the short chirp
    load = rng.uniform(0.2, 1.0, columns) * (sprung + unsprung) * GRAVITY_M_S2
    corner = _corner(rng, columns, load, tyre_model, effects)
    return QuarterCarPhysics(corner, sprung, unsprung)


def _axle(seed: int, columns: int) -> AxlePhysics:
    rng = np.random.default_rng(seed)
    sprung, unsprung = rng.uniform(500.0, 1000.0, columns), rng.uniform(30.0, 60.0, columns)
    load = rng.uniform(0.2, 1.0, columns) * (0.5 * sprung + unsprung) * GRAVITY_M_S2  # lightly loaded
    return AxlePhysics(
        _corner(rng, columns, load, TyreModel.MAXWELL, effects=True),
        _corner(rng, columns, load, TyreModel.MAXWELL, effects=True),
        sprung,
        unsprung,
        rng.uniform(150.0, 400.0, columns),
        float(rng.uniform(1.3, 1.6)),
        rng.uniform(0.0, 20e3, columns),
    )


def _both(physics, initial_state, plate_m, rate_m_s) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(over="ignore", invalid="ignore"):
        reference = integrate_rk4(physics.derivatives, initial_state, SAMPLE_TIME_S, plate_m, rate_m_s)
    return reference, integrate_compiled(physics, initial_state, SAMPLE_TIME_S, plate_m, rate_m_s)


def _lifted_off(physics, states: np.ndarray, plate_m: np.ndarray, rate_m_s: np.ndarray) -> np.ndarray:
    """Per column: whether some corner's contact force reached zero (lift-off clipped it)."""
    state = np.moveaxis(states, 0, 1)
    corners = [physics.corner] if isinstance(physics, QuarterCarPhysics) else [physics.left, physics.right]
    forces = physics.contact_forces_N(state, plate_m, rate_m_s)
    lifted = np.zeros(state.shape[-1], dtype=bool)
    for corner, force in zip(corners, forces.values(), strict=True):
        lifted |= np.any(force <= -corner.static_wheel_load_N + 1e-9, axis=0) & np.asarray(
            corner.tyre_liftoff
        )
    return lifted


@pytest.mark.parametrize("seed", [11, 12])
def test_quarter_car_population_with_every_effect(seed: int) -> None:
    """Six columns, each its own plate (as the doctor drives them), friction, cubic spring, lift-off and
    tyre dashpot present in some columns and absent in others."""
    columns = 6
    physics = _quarter_car(seed, columns, TyreModel.MAXWELL, effects=True)
    plate, rate, state0 = _quarter_car_drive(seed + 100, columns)
    reference, compiled = _both(physics, state0, plate, rate)
    assert np.all(np.isfinite(reference))
    assert_same_trajectories(reference, compiled)
    corner = physics.corner
    # every effect is exercised somewhere in the population, and lift-off really clipped the force
    assert np.any(corner.coulomb_friction_N) and np.any(corner.coulomb_friction_N == 0)
    assert np.any(corner.cubic_spring_N_per_m3) and np.any(corner.tyre_dashpot_Ns_per_m)
    lifted = _lifted_off(physics, reference, plate.T, rate.T)
    print(f"seed {seed}: lift-off in {lifted.sum()} of {int(np.sum(corner.tyre_liftoff))} lift-off columns")
    assert lifted.any()


def _quarter_car_drive(seed: int, columns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A plate per column (samples, columns), its rate, and a small random initial state."""
    rng = np.random.default_rng(seed)
    plate, rate = _plate(rng, columns)
    state0 = np.vstack([rng.normal(0, 1e-3, (4, columns)), np.zeros((1, columns))])
    return plate, rate, state0


def _axle_drive(seed: int, columns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Left and right plates stacked (2, samples, columns), their rates, and a small random initial state."""
    rng = np.random.default_rng(seed)
    left, left_rate = _plate(rng, columns)
    right, right_rate = _plate(rng, columns)
    state0 = np.vstack([rng.normal(0, 1e-3, (8, columns)), np.zeros((2, columns))])
    return np.stack([left, right]), np.stack([left_rate, right_rate]), state0


def test_axle_population_with_anti_roll_bar_and_every_effect() -> None:
    """Five axle models: own curves left and right (different grids), anti-roll bar, roll inertia, and the
    effects per corner and column; the plate is stacked (left, right) per column."""
    columns = 5
    physics = _axle(21, columns)
    plate, rate, state0 = _axle_drive(121, columns)
    reference, compiled = _both(physics, state0, plate, rate)
    assert np.all(np.isfinite(reference))
    assert_same_trajectories(reference, compiled)
    # the roll degree of freedom is excited (left and right plates differ), so the bar acts; wheels lift off
    assert np.max(np.abs(reference[:, 2, :])) > 1e-4
    lifted = _lifted_off(physics, reference, plate[:, :, :].transpose(0, 2, 1), rate.transpose(0, 2, 1))
    print(f"axle: lift-off in {lifted.sum()} of {columns} columns")
    assert lifted.any()


@pytest.mark.parametrize("tyre_model", [TyreModel.MAXWELL, TyreModel.KELVIN_VOIGT, TyreModel.SPRING])
def test_one_identified_model_each_tyre_model(tyre_model: TyreModel) -> None:
    """As estimator.output_error drives one identified model: one piecewise-linear curve, scalar
    parameters, a 1-D state and one plate."""
    rng = np.random.default_rng(31)
    grid = _grid(rng)
    curve = PiecewiseLinearCurve(grid, _curve_forces(rng, grid, 1)[:, 0])
    corner = CornerPhysics(
        damper=curve,
        spring_stiffness_N_per_m=25e3,
        tyre_stiffness_N_per_m=200e3,
        tyre_model=tyre_model,
        tyre_damping_Ns_per_m=350.0,
        maxwell_time_constant_s=0.03,
    )
    physics = QuarterCarPhysics(corner, 320.0, 42.0)
    plate, rate = _plate(rng, None)
    reference, compiled = _both(physics, np.array([1e-3, 0.0, -5e-4, 0.01, 0.0]), plate, rate)
    assert reference.shape == (plate.size, 5)
    assert_same_trajectories(reference, compiled)


def test_axle_one_model_shared_plate_and_population_of_curves() -> None:
    """As the output-error refinement drives an axle: CurveBatch columns, one (left, right) plate for all."""
    columns = 4
    rng = np.random.default_rng(41)
    corners = []
    for _ in range(2):
        grid = _grid(rng)
        corners.append(
            CornerPhysics(
                damper=CurveBatch(grid, _curve_forces(rng, grid, columns)),
                spring_stiffness_N_per_m=30e3,
                tyre_stiffness_N_per_m=250e3,
                tyre_model=TyreModel.MAXWELL,
                tyre_damping_Ns_per_m=rng.uniform(200.0, 500.0, columns),
                maxwell_time_constant_s=0.03,
            )
        )
    physics = AxlePhysics(corners[0], corners[1], 700.0, 45.0, 250.0, 1.45, 8e3)
    left, left_rate = _plate(rng, None)
    right, right_rate = _plate(rng, None)
    state0 = np.zeros((10, columns))
    reference, compiled = _both(physics, state0, np.stack([left, right]), np.stack([left_rate, right_rate]))
    assert_same_trajectories(reference, compiled)


def test_a_diverging_model_in_a_population() -> None:
    """A column with a strongly negative tyre dashpot (unstable) overflows; the others are unaffected and
    agree with the reference, and the diverged column is not finite in both from the same step on."""
    columns = 4
    base = _quarter_car(51, columns, TyreModel.MAXWELL, effects=False)
    dashpot = np.array([0.0, -60e3, 0.0, 0.0])
    physics = QuarterCarPhysics(
        CornerPhysics(
            damper=base.corner.damper,
            spring_stiffness_N_per_m=base.corner.spring_stiffness_N_per_m,
            tyre_stiffness_N_per_m=base.corner.tyre_stiffness_N_per_m,
            tyre_model=TyreModel.MAXWELL,
            tyre_damping_Ns_per_m=base.corner.tyre_damping_Ns_per_m,
            maxwell_time_constant_s=base.corner.maxwell_time_constant_s,
            tyre_dashpot_Ns_per_m=dashpot,
        ),
        base.sprung_mass_kg,
        base.unsprung_mass_kg,
    )
    plate, rate = _plate(np.random.default_rng(151), None)
    reference, compiled = _both(physics, np.zeros((5, columns)), plate, rate)
    finite_reference = np.all(np.isfinite(reference), axis=(0, 1))
    assert finite_reference.tolist() == [True, False, True, True]
    first_bad = int(np.flatnonzero(~np.all(np.isfinite(reference[:, :, 1]), axis=1))[0])
    assert first_bad > 10  # it grew for a while before overflowing: the growth is compared too
    assert np.all(np.isfinite(compiled[:first_bad, :, 1]))
    assert np.all(np.isnan(compiled[first_bad + 1 :, :, 1]))
    assert_same_trajectories(reference, compiled)


def test_inputs_it_cannot_simulate_are_refused() -> None:
    physics = _quarter_car(61, 3, TyreModel.MAXWELL, effects=False)
    plate, rate = _plate(np.random.default_rng(161), None)
    with pytest.raises(ValueError, match="initial state"):
        integrate_compiled(physics, np.zeros((4, 3)), SAMPLE_TIME_S, plate, rate)
    with pytest.raises(ValueError, match="columns"):
        integrate_compiled(physics, np.zeros((5, 2)), SAMPLE_TIME_S, plate, rate)
    with pytest.raises(ValueError, match="plate drive"):
        integrate_compiled(physics, np.zeros((5, 3)), SAMPLE_TIME_S, np.zeros((2, 3, plate.size)), rate)


def _with_shapes(
    corner: CornerPhysics, seed: int, columns: int, shared_hinges: bool = False
) -> CornerPhysics:
    """The corner with spring hinges (1 to HINGES, knots of either sign within the few millimetres the chirp
    deflects the spring, rates up to 4x the spring's; in some columns none) and Stribeck friction (in some
    columns; one column with a peak but no velocity, which is no Stribeck term). shared_hinges: one (H,)
    set of hinges for every column, as a model's corner carries them."""
    rng = np.random.default_rng(seed)
    count = int(rng.integers(1, HINGES + 1))
    shape = (count,) if shared_hinges else (count, columns)
    knots = rng.uniform(0.0003, 0.003, shape) * rng.choice([-1.0, 1.0], shape)
    rates = rng.uniform(0.3, 4.0, shape) * np.mean(corner.spring_stiffness_N_per_m)
    if not shared_hinges:
        rates[:, rng.random(columns) < 0.3] = 0.0  # no hinge in some columns
        rates[rng.random(shape) < 0.2] = 0.0  # and some hinges of a column unused (padding)
    peak = np.where(rng.random(columns) < 0.7, rng.uniform(10.0, 60.0, columns), 0.0)
    velocity = rng.uniform(0.005, 0.05, columns)
    velocity[0], peak[0] = 0.0, 80.0  # a peak without a velocity: absent, not a division by zero
    return replace(
        corner,
        spring_hinge_knots_m=knots,
        spring_hinge_rates_N_per_m=rates,
        stribeck_peak_N=peak,
        stribeck_velocity_m_s=velocity,
    )


def _hinges_engaged(corner: CornerPhysics, deflection_m: np.ndarray) -> bool:
    """Whether the deflection (steps, columns) went beyond some hinge's knot on its side."""
    force = corner.spring_hinge_force_N(deflection_m)
    return bool(np.any(force != 0.0))


@pytest.mark.parametrize("seed", [13, 15])
def test_quarter_car_population_with_spring_hinges_and_stribeck_friction(seed: int) -> None:
    """Six columns with hinges (own knots and rates per column, none in some) and Stribeck friction beside
    the other effects; the hinges engage during the chirp."""
    columns = 6
    base = _quarter_car(seed, columns, TyreModel.MAXWELL, effects=True)
    physics = replace(base, corner=_with_shapes(base.corner, seed + 500, columns))
    plate, rate, state0 = _quarter_car_drive(seed + 100, columns)
    reference, compiled = _both(physics, state0, plate, rate)
    assert np.all(np.isfinite(reference))
    assert_same_trajectories(reference, compiled)
    assert _hinges_engaged(physics.corner, reference[:, 0] - reference[:, 2])
    # the shapes change the motion: the same models without them move otherwise
    plain, _ = _both(base, state0, plate, rate)
    assert np.max(np.abs(plain - reference)) > 1e-5


def test_axle_population_with_spring_hinges_and_stribeck_friction() -> None:
    """Five axle models: the left corner with hinges per column, the right with one set for all (H,), both
    with Stribeck friction, beside the bar and the other effects."""
    columns = 5
    base = _axle(22, columns)
    physics = replace(
        base,
        left=_with_shapes(base.left, 522, columns),
        right=_with_shapes(base.right, 523, columns, shared_hinges=True),
    )
    plate, rate, state0 = _axle_drive(122, columns)
    reference, compiled = _both(physics, state0, plate, rate)
    assert np.all(np.isfinite(reference))
    assert_same_trajectories(reference, compiled)
    half = 0.5 * physics.track_m
    zeta_l = reference[:, 0] + half * reference[:, 2] - reference[:, 4]
    zeta_r = reference[:, 0] - half * reference[:, 2] - reference[:, 6]
    assert _hinges_engaged(physics.left, zeta_l) and _hinges_engaged(physics.right, zeta_r)


def test_one_model_with_a_bump_stop_and_stribeck_friction() -> None:
    """As validate drives a model with effects (estimator.model_io): one curve, scalar parameters, two hinges
    (a stop each way with clearance) and a Stribeck peak, a 1-D state."""
    rng = np.random.default_rng(32)
    grid = _grid(rng)
    corner = CornerPhysics(
        damper=PiecewiseLinearCurve(grid, _curve_forces(rng, grid, 1)[:, 0]),
        spring_stiffness_N_per_m=25e3,
        tyre_stiffness_N_per_m=200e3,
        tyre_damping_Ns_per_m=350.0,
        maxwell_time_constant_s=0.03,
        coulomb_friction_N=40.0,
        spring_hinge_knots_m=np.array([0.001, -0.0015]),
        spring_hinge_rates_N_per_m=np.array([80e3, 50e3]),
        stribeck_peak_N=60.0,
        stribeck_velocity_m_s=0.01,
    )
    physics = QuarterCarPhysics(corner, 320.0, 42.0)
    plate, rate = _plate(rng, None)
    reference, compiled = _both(physics, np.array([1e-3, 0.0, -5e-4, 0.01, 0.0]), plate, rate)
    assert_same_trajectories(reference, compiled)
    assert _hinges_engaged(corner, reference[:, 0] - reference[:, 2])


def _with_hysteresis(corner: CornerPhysics, seed: int, columns: int) -> CornerPhysics:
    """The corner's friction made hysteretic (Dahl, presliding 0.1-0.5 mm) in some columns, left smooth in
    others, with friction in every column and a Stribeck peak in some (the peak steps with the same sign)."""
    rng = np.random.default_rng(seed)
    presliding = np.where(rng.random(columns) < 0.6, rng.uniform(1e-4, 5e-4, columns), 0.0)
    presliding[:2] = 2e-4, 0.0  # both kinds present whatever the draw
    peak = np.where(rng.random(columns) < 0.4, rng.uniform(10.0, 40.0, columns), 0.0)
    return replace(
        corner,
        coulomb_friction_N=rng.uniform(40.0, 150.0, columns),
        presliding_m=presliding,
        stribeck_peak_N=peak,
        stribeck_velocity_m_s=rng.uniform(0.005, 0.03, columns),
    )


def _substepped(physics, initial_state, plate_m, rate_m_s, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """_both at `steps` Runge-Kutta steps per sample: Dahl's state decays at |v|/z, up to 3000/s here."""
    plate, rate = sample_substeps(plate_m, steps), sample_substeps(rate_m_s, steps)  # time is the last axis
    with np.errstate(over="ignore", invalid="ignore"):
        reference = integrate_rk4(physics.derivatives, initial_state, SAMPLE_TIME_S / steps, plate, rate)
    return reference, integrate_compiled(physics, initial_state, SAMPLE_TIME_S / steps, plate, rate)


def _hysteretic_run(physics, base, drive, extra_states: int) -> np.ndarray:
    """The reference trajectories of `physics` (`base` made hysteretic: extra_states more, Dahl's h) at 4
    steps a sample from the drive's state with h = 0, checked finite and followed by the compiled kernel."""
    assert physics.state_size == base.state_size + extra_states
    plate, rate, state0 = drive
    state0 = np.vstack([state0, np.zeros((extra_states, state0.shape[1]))])
    reference, compiled = _substepped(physics, state0, plate, rate, 4)
    assert np.all(np.isfinite(reference))
    assert_same_trajectories(reference, compiled)
    return reference


def test_quarter_car_population_with_hysteretic_friction() -> None:
    """Six columns, Dahl friction in some and the smoothed sign in the others (the models of
    test_quarter_car_population_with_every_effect's seed 11, whose random curves are dissipative enough
    without the smoothed sign's damping at rest): the compiled kernel follows
    the reference, Dahl's h (the sixth state) saturates at ±1 while sliding, and the hysteresis changes the
    motion against the same friction with the velocity's sign."""
    columns = 6
    base = _quarter_car(11, columns, TyreModel.MAXWELL, effects=True)
    physics = replace(base, corner=_with_hysteresis(base.corner, 511, columns))
    assert base.state_size == 5
    plate, rate, state0 = drive = _quarter_car_drive(111, columns)
    reference = _hysteretic_run(physics, base, drive, 1)
    dahl = np.asarray(physics.corner.presliding_m) > 0.0
    h = reference[:, 5]
    assert np.all(np.max(np.abs(h[:, dahl]), axis=0) > 0.99) and np.all(np.abs(h) <= 1.0 + 1e-9)
    assert np.all(h[:, ~dahl] == 0.0)  # no hysteresis there: h stays at its start
    smooth = replace(physics, corner=replace(physics.corner, presliding_m=0.0))
    other, _ = _substepped(smooth, state0, plate, rate, 4)
    moved = np.max(np.abs(other[:, 0] - reference[:, 0]), axis=0)
    print(f"body motion changed by hysteresis: {moved * 1e6} µm")
    assert np.all(moved[dahl] > 1e-6) and np.all(moved[~dahl] < 1e-12)


def test_axle_population_with_hysteretic_friction_on_one_side() -> None:
    """An axle whose left corner is hysteretic (in some columns) and right is not: 12 states, h_l in the
    eleventh, h_r in the twelfth staying 0; the compiled kernel follows the reference."""
    columns = 4
    base = _axle(23, columns)
    physics = replace(base, left=_with_hysteresis(base.left, 524, columns))
    assert base.state_size == 10
    reference = _hysteretic_run(physics, base, _axle_drive(123, columns), 2)
    dahl = np.asarray(physics.left.presliding_m) > 0.0
    assert np.all(np.max(np.abs(reference[:, 10][:, dahl]), axis=0) > 0.99)
    assert np.all(reference[:, 11] == 0.0)
