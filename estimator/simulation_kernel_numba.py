"""The output-error simulation's kernel for numba: the fixed-step Runge-Kutta of estimator.dynamics (quarter
car or axle, piecewise-linear dampers, Maxwell / Kelvin-Voigt / spring tyre with a parallel dashpot,
Coulomb, Stribeck and hysteretic friction, cubic spring, spring hinges, tyre lift-off, a rig's frame
guides) for a population of models, one column each.

Callers use estimator.simulation_kernel (integrate_compiled), which lays the models out in the tables this
kernel reads and runs it either as built ahead of time into a Python extension (service/kernel_build.py,
numba's pycc, exporting `integrate` with INTEGRATE_SIGNATURE: no numba import, no cache load
at run time) or compiled just in time by numba (cache=True, in estimator/__pycache__ or numba's user
cache). Both compile this same source.
"""

from __future__ import annotations

import numba
import numpy as np

from estimator.dynamics import HINGES
from estimator.friction import COULOMB_SMOOTHING_M_S
from estimator.simulation_kernel import (
    ANTI_ROLL_BAR_N_PER_M,
    CORNER_ROWS,
    COULOMB_FRICTION_N,
    CUBIC_SPRING_N_PER_M3,
    GUIDE_BODY_FRICTION_N,
    GUIDE_WHEEL_FRICTION_N,
    HINGE_KNOT_M,
    HINGE_RATE_N_PER_M,
    HINGED,
    MAXWELL_TIME_CONSTANT_S,
    PRESLIDING_M,
    ROLL_INERTIA_KG_M2,
    SPRING_N_PER_M,
    SPRUNG_KG,
    STATE_SLOTS,
    STATIC_WHEEL_LOAD_N,
    STRIBECK_PEAK_N,
    STRIBECK_VELOCITY_M_S,
    TRACK_M,
    TYRE_DAMPING_NS_PER_M,
    TYRE_DASHPOT_NS_PER_M,
    TYRE_LIFTOFF,
    TYRE_N_PER_M,
    UNSPRUNG_KG,
)

_MAXWELL, _KELVIN_VOIGT = 0, 1  # estimator.simulation_kernel.TYRE_CODES

if HINGES != 4 or CORNER_ROWS != 23 or STATE_SLOTS != 12:  # spelled out one by one below
    raise ImportError(
        f"the kernel is written for 4 hinges, 23 corner rows, 12 state slots, not {HINGES}, {CORNER_ROWS},"
        f" {STATE_SLOTS}"
    )

# The per-step functions take and return tuples of floats and 1-D arrays only, and are inlined into the
# loop: passing numba arrays between functions costs reference counting at every call (25x slower here).
# They are compiled into integrate, whose cache holds them.
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


@_scalar
def _hinge_N(deflection_m: float, knot_m: float, rate_N_per_m: float) -> float:
    """One spring hinge: rate·(ζ − knot) beyond the knot on its side, 0 elsewhere (side·max(side·(ζ − knot),
    0) is ζ − knot exactly, or 0). Written without a branch on ζ: with one (or a branch per hinge on how
    many a column has) every simulation ran a quarter slower, with hinges or without (measured on
    benchmarks/bench_kernel.py's cases); so the kernel takes all HINGES where a column has one."""
    side = 1.0 if knot_m >= 0.0 else -1.0
    return rate_N_per_m * side * max(side * (deflection_m - knot_m), 0.0)


@_inline
def _hinges_N(deflection_m: float, corner) -> float:
    """CornerPhysics.spring_hinge_force_N of one column: its HINGES hinges (padded with rate 0) in order."""
    return (
        _hinge_N(deflection_m, corner[HINGE_KNOT_M], corner[HINGE_RATE_N_PER_M])
        + _hinge_N(deflection_m, corner[HINGE_KNOT_M + 1], corner[HINGE_RATE_N_PER_M + 1])
        + _hinge_N(deflection_m, corner[HINGE_KNOT_M + 2], corner[HINGE_RATE_N_PER_M + 2])
        + _hinge_N(deflection_m, corner[HINGE_KNOT_M + 3], corner[HINGE_RATE_N_PER_M + 3])
    )


@_inline
def _suspension_N(
    deflection_m: float, velocity_m_s: float, hysteresis: float, corner, grid, force, slope, knots: int
) -> float:
    """CornerPhysics.suspension_force_N for one column, its terms in the same order; `corner` is its row of
    the corner table, hysteresis its Dahl state h."""
    force_N = _damper_N(velocity_m_s, grid, force, slope, knots) + corner[SPRING_N_PER_M] * deflection_m
    friction = corner[COULOMB_FRICTION_N]
    peak, stribeck_m_s = corner[STRIBECK_PEAK_N], corner[STRIBECK_VELOCITY_M_S]
    stribeck = peak != 0.0 and stribeck_m_s != 0.0
    sign = np.tanh(velocity_m_s / COULOMB_SMOOTHING_M_S) if friction != 0.0 or stribeck else 0.0
    if corner[PRESLIDING_M] > 0.0:  # hysteretic: the friction's sign is Dahl's state
        sign = hysteresis
    if friction != 0.0:
        force_N = force_N + friction * sign
    cubic = corner[CUBIC_SPRING_N_PER_M3]
    if cubic != 0.0:
        force_N = force_N + cubic * deflection_m**3.0
    if corner[HINGED] != 0.0:  # no hinge with a rate: no hinge code per step
        force_N = force_N + _hinges_N(deflection_m, corner)
    if stribeck:
        ratio = velocity_m_s / stribeck_m_s
        force_N = force_N + peak * sign * np.exp(-(ratio * ratio))
    return force_N


@_scalar
def _hysteresis_rate(velocity_m_s: float, hysteresis: float, corner) -> float:
    """estimator.dynamics.hysteresis_rate for one column: Dahl's ḣ, 0 without hysteresis."""
    presliding_m = corner[PRESLIDING_M]
    if presliding_m > 0.0:
        return (velocity_m_s - abs(velocity_m_s) * hysteresis) / presliding_m
    return 0.0


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
    """QuarterCarPhysics.derivatives for one column (state in the first 5 of the slots, h in the sixth)."""
    x_s, v_s, x_t, v_t, f_v, h = state[0], state[1], state[2], state[3], state[4], state[5]
    q = _suspension_N(x_s - x_t, v_s - v_t, h, corner, grid, force, slope, knots)
    tyre = _tyre_N(x_t - plate_m, v_t - plate_rate_m_s, f_v, corner, code)
    on_body, on_wheel = q, q + tyre
    guide_body, guide_wheel = corner[GUIDE_BODY_FRICTION_N], corner[GUIDE_WHEEL_FRICTION_N]
    if guide_body != 0.0 or guide_wheel != 0.0:  # the frame guides' friction, each mass against the frame
        on_body = on_body + guide_body * np.tanh(v_s / COULOMB_SMOOTHING_M_S)
        on_wheel = on_wheel - guide_wheel * np.tanh(v_t / COULOMB_SMOOTHING_M_S)
    return (
        v_s,
        -on_body / body[SPRUNG_KG],
        v_t,
        on_wheel / body[UNSPRUNG_KG],
        _maxwell_rate(v_t - plate_rate_m_s, f_v, corner, code, tyre),
        _hysteresis_rate(v_s - v_t, h, corner),
        0.0,
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
    h_l, h_r = state[10], state[11]
    q_l = _suspension_N(zeta_l, vel_l, h_l, left, grid_l, force_l, slope_l, knots_l) + bar
    q_r = _suspension_N(zeta_r, vel_r, h_r, right, grid_r, force_r, slope_r, knots_r) - bar
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
        _hysteresis_rate(vel_l, h_l, left),
        _hysteresis_rate(vel_r, h_r, right),
    )


@_inline
def _rates(axle: bool, state, plate_m, plate_rate_m_s, body, left, right, code_l, code_r, damper_l, damper_r):
    """The derivatives of the 12 state slots; plate_m, plate_rate_m_s: (left, right) (a quarter car: left)."""
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
        state[9] + scale * rates[9], state[10] + scale * rates[10], state[11] + scale * rates[11],
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
        k1[10] + 2.0 * k2[10] + 2.0 * k3[10] + k4[10], k1[11] + 2.0 * k2[11] + 2.0 * k3[11] + k4[11],
    )  # fmt: skip
    return _combine(state, sixth_h, total)


@_inline
def _row(table, corner: int, column: int):
    """One corner's parameters of one column, as a tuple indexed by the row constants."""
    return (
        table[corner, 0, column], table[corner, 1, column], table[corner, 2, column],
        table[corner, 3, column], table[corner, 4, column], table[corner, 5, column],
        table[corner, 6, column], table[corner, 7, column], table[corner, 8, column],
        table[corner, 9, column], table[corner, 10, column], table[corner, 11, column],
        table[corner, 12, column], table[corner, 13, column], table[corner, 14, column],
        table[corner, 15, column], table[corner, 16, column], table[corner, 17, column],
        table[corner, 18, column], table[corner, 19, column], table[corner, 20, column],
        table[corner, 21, column], table[corner, 22, column],
    )  # fmt: skip


@_inline
def _store(target, state) -> None:
    target[0], target[1], target[2], target[3], target[4] = state[0], state[1], state[2], state[3], state[4]
    target[5], target[6], target[7], target[8], target[9] = state[5], state[6], state[7], state[8], state[9]
    target[10], target[11] = state[10], state[11]


@numba.njit(cache=True, error_model="numpy")
def integrate(
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
            start[0], start[1], start[2], start[3], start[4], start[5],
            start[6], start[7], start[8], start[9], start[10], start[11],
        )  # fmt: skip
        for i in range(variables):
            states[column, i, 0] = start[i]
        current = np.empty(STATE_SLOTS)
        zero = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
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


INTEGRATE_SIGNATURE = (
    "void(boolean, f8[:, :], f8, f8[:, :, :], f8[:, :, :], f8[:, :, :], f8[:, :], i8[:], f8[:, :], i8[:],"
    " f8[:, :, :], f8[:, :, :], f8[:, :, :])"
)
"""integrate's argument types, as the extension exports it (any memory layout)."""

_integrate = integrate  # the name the kernel tests import
