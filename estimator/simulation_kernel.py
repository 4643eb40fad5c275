"""The output-error simulation compiled: the fixed-step Runge-Kutta of estimator.dynamics (quarter car or
axle, piecewise-linear dampers, Maxwell / Kelvin-Voigt / spring tyre with a parallel dashpot, Coulomb
friction, cubic spring, tyre lift-off) for a population of models, one column each, run by numba.

Why: the recursion is per sample (the Maxwell state, the damper's segment), so numpy cannot vectorise it
over time; in a Python loop it was most of `shockbench identify` (about 2.5 s of 3.7 s on 12 s at 1 kHz) and
of the doctor. Compiled, each column is integrated in registers.

`integrate_compiled(physics, ...)` takes the same physics objects (estimator.dynamics.QuarterCarPhysics,
AxlePhysics) and drive as `integrate_rk4(physics.derivatives, ...)`, which stays the reference: the same
equations in the same order of operations, so the trajectories agree to rounding (tested to 1e-9 relative
in tests/estimator/test_simulation_kernel.py). Every parameter may be a number or one value per column;
the kernel receives them all per column and per corner, so a new per-model quantity is one more row.

Divergence: a column whose state stops being finite is filled with NaN from that step on (the reference
carries on with inf/NaN); callers treat both as a diverged model.

The compiled code is cached on disk (numba cache=True, in estimator/__pycache__ or numba's user cache), so
the compile (a few seconds) is paid once per machine and source version; `compile_ahead()` pays it early.
"""

from __future__ import annotations

import numba
import numpy as np

from estimator.damper import CurveBatch, PiecewiseLinearCurve
from estimator.dynamics import COULOMB_SMOOTHING_M_S, AxlePhysics, CornerPhysics, QuarterCarPhysics
from estimator.vehicle import TyreModel

# rows of the per-corner parameter table, shape (corners, CORNER_ROWS, columns)
SPRING_N_PER_M = 0
TYRE_N_PER_M = 1
TYRE_DAMPING_NS_PER_M = 2
MAXWELL_TIME_CONSTANT_S = 3
COULOMB_FRICTION_N = 4
CUBIC_SPRING_N_PER_M3 = 5
TYRE_LIFTOFF = 6  # 1.0 where the contact force is clipped at lift-off, 0.0 where not
STATIC_WHEEL_LOAD_N = 7
TYRE_DASHPOT_NS_PER_M = 8
CORNER_ROWS = 9

# rows of the per-column body table, shape (BODY_ROWS, columns)
SPRUNG_KG = 0
UNSPRUNG_KG = 1  # per wheel
ROLL_INERTIA_KG_M2 = 2
TRACK_M = 3
ANTI_ROLL_BAR_N_PER_M = 4
BODY_ROWS = 5

# tyre models as the kernel knows them (one per corner)
TYRE_CODES = {TyreModel.MAXWELL: 0, TyreModel.KELVIN_VOIGT: 1, TyreModel.SPRING: 2}
_MAXWELL, _KELVIN_VOIGT = 0, 1

STATE_SLOTS = 10
"""The kernel carries every model's state in 10 slots (the axle's); a quarter car leaves the last 5 at 0."""

# The per-step functions take and return tuples of floats and 1-D arrays only, and are inlined into the
# loop: passing numba arrays between functions costs reference counting at every call (25x slower here).
# They are compiled into _integrate, whose cache holds them.
_inline = numba.njit(error_model="numpy", inline="always")
_scalar = numba.njit(error_model="numpy")  # no arrays in or out: LLVM inlines these


@_inline
def _damper_N(velocity_m_s: float, grid_m_s, force_N, slope_Ns_per_m, knots: int) -> float:
    """CurveBatch.force for one column: the segment is the number of interior knots <= v (a NaN velocity
    lands in the last segment, as numpy's searchsorted puts it); end segments extend linearly."""
    low, high = 0, knots - 2
    while low < high:
        middle = (low + high) >> 1
        if velocity_m_s < grid_m_s[middle + 1]:
            high = middle
        else:
            low = middle + 1
    return force_N[low] + (velocity_m_s - grid_m_s[low]) * slope_Ns_per_m[low]


@_inline
def _suspension_N(deflection_m: float, velocity_m_s: float, corner, grid, force, slope, knots: int) -> float:
    """CornerPhysics.suspension_force_N for one column; `corner` is its row of the corner table."""
    force_N = _damper_N(velocity_m_s, grid, force, slope, knots) + corner[SPRING_N_PER_M] * deflection_m
    friction = corner[COULOMB_FRICTION_N]
    if friction != 0.0:
        force_N = force_N + friction * np.tanh(velocity_m_s / COULOMB_SMOOTHING_M_S)
    cubic = corner[CUBIC_SPRING_N_PER_M3]
    if cubic != 0.0:
        force_N = force_N + cubic * deflection_m**3.0
    return force_N


@_scalar
def _tyre_N(deflection_m: float, rate_m_s: float, maxwell_N: float, corner, code: int) -> float:
    """CornerPhysics.tyre_force_N for one column."""
    if code == _KELVIN_VOIGT:
        viscous = corner[TYRE_DAMPING_NS_PER_M] * rate_m_s
    elif code == _MAXWELL:
        viscous = maxwell_N
    else:
        viscous = 0.0
    dashpot = corner[TYRE_DASHPOT_NS_PER_M]
    if dashpot != 0.0:
        viscous = viscous + dashpot * rate_m_s
    force_N = -corner[TYRE_N_PER_M] * deflection_m - viscous
    if corner[TYRE_LIFTOFF] != 0.0:
        floor_N = -corner[STATIC_WHEEL_LOAD_N]
        if force_N < floor_N:  # a NaN force stays NaN, as with np.maximum
            force_N = floor_N
    return force_N


@_scalar
def _maxwell_rate(rate_m_s: float, maxwell_N: float, corner, code: int, tyre_N: float) -> float:
    """CornerPhysics.maxwell_rate for one column (tyre_N: its _tyre_N; off the plate the element relaxes)."""
    if code != _MAXWELL:
        return 0.0
    if corner[TYRE_LIFTOFF] != 0.0 and tyre_N <= -corner[STATIC_WHEEL_LOAD_N]:
        rate_m_s = 0.0
    return (corner[TYRE_DAMPING_NS_PER_M] * rate_m_s - maxwell_N) / corner[MAXWELL_TIME_CONSTANT_S]


@_inline
def _quarter_car_rates(state, plate_m, plate_rate_m_s, body, corner, code, grid, force, slope, knots):
    """QuarterCarPhysics.derivatives for one column (state in the first 5 of the 10 slots)."""
    x_s, v_s, x_t, v_t, f_v = state[0], state[1], state[2], state[3], state[4]
    q = _suspension_N(x_s - x_t, v_s - v_t, corner, grid, force, slope, knots)
    tyre = _tyre_N(x_t - plate_m, v_t - plate_rate_m_s, f_v, corner, code)
    return (
        v_s,
        -q / body[SPRUNG_KG],
        v_t,
        (q + tyre) / body[UNSPRUNG_KG],
        _maxwell_rate(v_t - plate_rate_m_s, f_v, corner, code, tyre),
        0.0,
        0.0,
        0.0,
        0.0,
        0.0,
    )


@_inline
def _axle_rates(
    state, plate_l, plate_r, rate_l, rate_r, body, left, right, code_l, code_r, damper_l, damper_r
):
    """AxlePhysics.derivatives for one column; damper_l, damper_r: (grid, force, slope, knots)."""
    x_g, v_g, roll, roll_rate = state[0], state[1], state[2], state[3]
    x_tl, v_tl, x_tr, v_tr, fv_l, fv_r = state[4], state[5], state[6], state[7], state[8], state[9]
    half = 0.5 * body[TRACK_M]
    zeta_l, zeta_r = x_g + half * roll - x_tl, x_g - half * roll - x_tr
    vel_l, vel_r = v_g + half * roll_rate - v_tl, v_g - half * roll_rate - v_tr
    bar = body[ANTI_ROLL_BAR_N_PER_M] * (zeta_l - zeta_r)
    grid_l, force_l, slope_l, knots_l = damper_l
    grid_r, force_r, slope_r, knots_r = damper_r
    q_l = _suspension_N(zeta_l, vel_l, left, grid_l, force_l, slope_l, knots_l) + bar
    q_r = _suspension_N(zeta_r, vel_r, right, grid_r, force_r, slope_r, knots_r) - bar
    tyre_l = _tyre_N(x_tl - plate_l, v_tl - rate_l, fv_l, left, code_l)
    tyre_r = _tyre_N(x_tr - plate_r, v_tr - rate_r, fv_r, right, code_r)
    unsprung = body[UNSPRUNG_KG]
    return (
        v_g,
        -(q_l + q_r) / body[SPRUNG_KG],
        roll_rate,
        -half * (q_l - q_r) / body[ROLL_INERTIA_KG_M2],
        v_tl,
        (q_l + tyre_l) / unsprung,
        v_tr,
        (q_r + tyre_r) / unsprung,
        _maxwell_rate(v_tl - rate_l, fv_l, left, code_l, tyre_l),
        _maxwell_rate(v_tr - rate_r, fv_r, right, code_r, tyre_r),
    )


@_inline
def _rates(axle: bool, state, plate_m, plate_rate_m_s, body, left, right, code_l, code_r, damper_l, damper_r):
    """The derivatives of the 10 state slots; plate_m, plate_rate_m_s: (left, right) (a quarter car: left)."""
    if axle:
        return _axle_rates(
            state, plate_m[0], plate_m[1], plate_rate_m_s[0], plate_rate_m_s[1],
            body, left, right, code_l, code_r, damper_l, damper_r,
        )  # fmt: skip
    grid, force, slope, knots = damper_l
    return _quarter_car_rates(
        state, plate_m[0], plate_rate_m_s[0], body, left, code_l, grid, force, slope, knots
    )


@_scalar
def _combine(state, scale: float, rates):
    """state + scale·rates, slot by slot."""
    return (
        state[0] + scale * rates[0], state[1] + scale * rates[1], state[2] + scale * rates[2],
        state[3] + scale * rates[3], state[4] + scale * rates[4], state[5] + scale * rates[5],
        state[6] + scale * rates[6], state[7] + scale * rates[7], state[8] + scale * rates[8],
        state[9] + scale * rates[9],
    )  # fmt: skip


@_scalar
def _rk4_update(state, sixth_h: float, k1, k2, k3, k4):
    """state + (h/6)·(k1 + 2·k2 + 2·k3 + k4), slot by slot, summed in rk4_step's order."""
    total = (
        k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0], k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1],
        k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2], k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3],
        k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4], k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5],
        k1[6] + 2.0 * k2[6] + 2.0 * k3[6] + k4[6], k1[7] + 2.0 * k2[7] + 2.0 * k3[7] + k4[7],
        k1[8] + 2.0 * k2[8] + 2.0 * k3[8] + k4[8], k1[9] + 2.0 * k2[9] + 2.0 * k3[9] + k4[9],
    )  # fmt: skip
    return _combine(state, sixth_h, total)


@_inline
def _row(table, corner: int, column: int):
    """One corner's parameters of one column, as a tuple indexed by the row constants."""
    return (
        table[corner, 0, column], table[corner, 1, column], table[corner, 2, column],
        table[corner, 3, column], table[corner, 4, column], table[corner, 5, column],
        table[corner, 6, column], table[corner, 7, column], table[corner, 8, column],
    )  # fmt: skip


@_inline
def _store(target, state) -> None:
    target[0], target[1], target[2], target[3], target[4] = state[0], state[1], state[2], state[3], state[4]
    target[5], target[6], target[7], target[8], target[9] = state[5], state[6], state[7], state[8], state[9]


@numba.njit(cache=True, error_model="numpy")
def _integrate(
    axle: bool,
    initial_state,
    step_s: float,
    plate_m,
    plate_rate_m_s,
    table,
    body,
    tyre_codes,
    grid_m_s,
    knots,
    force_N,
    slope_Ns_per_m,
    states,
) -> None:
    """integrate_rk4 (midpoints interpolated linearly) for every column into states[column, variable, step].

    initial_state (columns, variables); plate_m, plate_rate_m_s (corners, plate columns, samples), where
    plate columns is 1 (one drive for all) or one per column; table (corners, CORNER_ROWS, columns); body
    (BODY_ROWS, columns); grid_m_s (corners, knots), force_N and slope_Ns_per_m (corners, columns, knots)."""
    columns, variables = initial_state.shape
    last = plate_m.shape[0] - 1  # the right corner's index (0 for a quarter car)
    samples = plate_m.shape[2]
    half_h = 0.5 * step_s
    sixth_h = step_s / 6.0
    code_l, code_r = tyre_codes[0], tyre_codes[last]
    for column in range(columns):
        drive = 0 if plate_m.shape[1] == 1 else column
        left, right = _row(table, 0, column), _row(table, last, column)
        body_row = (
            body[0, column], body[1, column], body[2, column], body[3, column], body[4, column]
        )  # fmt: skip
        damper_l = (grid_m_s[0], force_N[0, column], slope_Ns_per_m[0, column], knots[0])
        damper_r = (grid_m_s[last], force_N[last, column], slope_Ns_per_m[last, column], knots[last])
        start = np.zeros(STATE_SLOTS)
        start[:variables] = initial_state[column]
        state = (
            start[0], start[1], start[2], start[3], start[4],
            start[5], start[6], start[7], start[8], start[9],
        )  # fmt: skip
        for i in range(variables):
            states[column, i, 0] = start[i]
        current = np.empty(STATE_SLOTS)
        zero = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        for k in range(samples - 1):
            p0 = (plate_m[0, drive, k], plate_m[last, drive, k])
            p1 = (plate_m[0, drive, k + 1], plate_m[last, drive, k + 1])
            r0 = (plate_rate_m_s[0, drive, k], plate_rate_m_s[last, drive, k])
            r1 = (plate_rate_m_s[0, drive, k + 1], plate_rate_m_s[last, drive, k + 1])
            pm = (0.5 * (p1[0] + p0[0]), 0.5 * (p1[1] + p0[1]))
            rm = (0.5 * (r1[0] + r0[0]), 0.5 * (r1[1] + r0[1]))
            # rk4_step's four stages, written as a loop so that _rates is inlined once (compile time)
            k1 = k2 = k3 = rates = zero
            for stage in range(4):
                if stage == 0:
                    trial, plate, rate = state, p0, r0
                elif stage == 3:
                    trial, plate, rate = _combine(state, step_s, rates), p1, r1
                else:
                    trial, plate, rate = _combine(state, half_h, rates), pm, rm
                rates = _rates(
                    axle, trial, plate, rate, body_row, left, right, code_l, code_r, damper_l, damper_r
                )
                if stage == 0:
                    k1 = rates
                elif stage == 1:
                    k2 = rates
                elif stage == 2:
                    k3 = rates
            state = _rk4_update(state, sixth_h, k1, k2, k3, rates)
            finite = True
            _store(current, state)  # constant indices: a tuple indexed at run time compiles slowly
            for i in range(variables):
                states[column, i, k + 1] = current[i]
                finite = finite and np.isfinite(current[i])
            if not finite:  # diverged: the rest of this column is NaN
                states[column, :, k + 2 :] = np.nan
                break


def _per_column(value: object, columns: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=float), (columns,))


def _damper_table(damper: object, columns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Knots (grid,), forces (columns, grid) and segment slopes (columns, grid - 1) of a corner's damper,
    computed as CurveBatch computes them."""
    if isinstance(damper, CurveBatch):
        grid, force = damper.velocity_m_s, damper.force_N
        if force.shape[1] != columns:
            raise ValueError(f"the damper curves have {force.shape[1]} columns, the state {columns}")
    elif isinstance(damper, PiecewiseLinearCurve):
        grid, force = damper.velocity_m_s, np.repeat(damper.force_N[:, None], columns, axis=1)
    else:
        raise TypeError(
            f"the compiled simulation takes piecewise-linear dampers, not {type(damper).__name__}"
        )
    slope = np.diff(force, axis=0) / np.diff(grid)[:, None]
    return grid, force.T, slope.T


def _corner_rows(corner: CornerPhysics, columns: int) -> np.ndarray:
    rows = np.empty((CORNER_ROWS, columns))
    rows[SPRING_N_PER_M] = _per_column(corner.spring_stiffness_N_per_m, columns)
    rows[TYRE_N_PER_M] = _per_column(corner.tyre_stiffness_N_per_m, columns)
    rows[TYRE_DAMPING_NS_PER_M] = _per_column(corner.tyre_damping_Ns_per_m, columns)
    rows[MAXWELL_TIME_CONSTANT_S] = _per_column(corner.maxwell_time_constant_s, columns)
    rows[COULOMB_FRICTION_N] = _per_column(corner.coulomb_friction_N, columns)
    rows[CUBIC_SPRING_N_PER_M3] = _per_column(corner.cubic_spring_N_per_m3, columns)
    rows[TYRE_LIFTOFF] = _per_column(np.asarray(corner.tyre_liftoff, dtype=bool), columns)
    rows[STATIC_WHEEL_LOAD_N] = _per_column(corner.static_wheel_load_N, columns)
    rows[TYRE_DASHPOT_NS_PER_M] = _per_column(corner.tyre_dashpot_Ns_per_m, columns)
    return rows


def _drive(plate: np.ndarray, corners: int, columns: int) -> np.ndarray:
    """(corners, 1 or columns, samples) from integrate_rk4's plate layout: (samples,) or (columns, samples)
    for a quarter car, (2, samples) or (2, columns, samples) for an axle."""
    plate = np.asarray(plate, dtype=float)
    if corners == 1:
        plate = plate[None]
    if plate.ndim == 2:
        plate = plate[:, None, :]
    if plate.ndim != 3 or plate.shape[0] != corners or plate.shape[1] not in (1, columns):
        raise ValueError(
            f"a plate drive of shape {np.shape(plate)} does not fit {corners} corner(s), {columns} column(s)"
        )
    return np.ascontiguousarray(plate)


def integrate_compiled(
    physics: QuarterCarPhysics | AxlePhysics,
    initial_state: np.ndarray,
    step_s: float,
    plate_m: np.ndarray,
    plate_rate_m_s: np.ndarray,
) -> np.ndarray:
    """integrate_rk4(physics.derivatives, initial_state, step_s, plate_m, plate_rate_m_s), compiled.

    initial_state: (variables,) for one model or (variables, columns) for a population; the plate as
    integrate_rk4 takes it, sampled at the step times. Returns the state at every step, shape
    (steps + 1, *initial_state.shape) (a transposed view: each column's samples are contiguous)."""
    initial = np.asarray(initial_state, dtype=float)
    single = initial.ndim == 1
    initial = initial[:, None] if single else initial
    if initial.ndim != 2 or initial.shape[0] != physics.state_size:
        raise ValueError(
            f"the initial state must be ({physics.state_size},) or ({physics.state_size}, columns)"
        )
    columns = initial.shape[1]
    axle = isinstance(physics, AxlePhysics)
    corners = [physics.left, physics.right] if axle else [physics.corner]
    dampers = [_damper_table(c.damper, columns) for c in corners]
    knots = np.array([d[0].size for d in dampers], dtype=np.int64)
    width = int(knots.max())
    grid = np.zeros((len(corners), width))
    force = np.zeros((len(corners), columns, width))
    slope = np.zeros((len(corners), columns, width - 1))
    for index, (knot_m_s, force_N, slope_Ns_per_m) in enumerate(dampers):
        grid[index, : knot_m_s.size] = knot_m_s
        force[index, :, : knot_m_s.size] = force_N
        slope[index, :, : knot_m_s.size - 1] = slope_Ns_per_m
    table = np.stack([_corner_rows(c, columns) for c in corners])
    body = np.zeros((BODY_ROWS, columns))
    body[SPRUNG_KG] = _per_column(physics.sprung_mass_kg, columns)
    body[UNSPRUNG_KG] = _per_column(physics.unsprung_mass_kg, columns)
    if axle:
        body[ROLL_INERTIA_KG_M2] = _per_column(physics.roll_inertia_kg_m2, columns)
        body[TRACK_M] = _per_column(physics.track_m, columns)
        body[ANTI_ROLL_BAR_N_PER_M] = _per_column(physics.anti_roll_bar_N_per_m, columns)
    tyre_codes = np.array([TYRE_CODES[TyreModel(c.tyre_model)] for c in corners], dtype=np.int64)
    plate = _drive(plate_m, len(corners), columns)
    rate = _drive(plate_rate_m_s, len(corners), columns)
    if rate.shape != plate.shape:
        raise ValueError("the plate position and rate must have the same shape")
    states = np.empty((columns, physics.state_size, plate.shape[2]))
    _integrate(
        axle,
        np.ascontiguousarray(initial.T),
        float(step_s),
        plate,
        rate,
        table,
        body,
        tyre_codes,
        grid,
        knots,
        force,
        slope,
        states,
    )
    trajectories = states.transpose(2, 1, 0)
    return trajectories[:, :, 0] if single else trajectories


def compile_ahead() -> None:
    """Compile (or load from the on-disk cache) the kernel on a tiny model, so a user's first identify
    does not pay the compile."""
    curve = PiecewiseLinearCurve(np.array([-1.0, 0.0, 1.0]), np.array([-1000.0, 0.0, 1000.0]))
    corner = CornerPhysics(damper=curve, spring_stiffness_N_per_m=20000.0, tyre_stiffness_N_per_m=200000.0)
    physics = QuarterCarPhysics(corner, 300.0, 40.0)
    integrate_compiled(physics, np.zeros(5), 0.001, np.zeros(3), np.zeros(3))
