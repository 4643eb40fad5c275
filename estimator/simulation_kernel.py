"""The output-error simulation compiled: the fixed-step Runge-Kutta of estimator.dynamics (quarter car or
axle, piecewise-linear dampers, Maxwell / Kelvin-Voigt / spring tyre with a parallel dashpot, Coulomb,
Stribeck and hysteretic friction, cubic spring, spring hinges, tyre lift-off) for a population of models,
one column each.

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

Which compiled code runs (the kernel's source is estimator/simulation_kernel_numba.py):
- the extension built ahead of time, `estimator/_simulation_kernel_aot_<digest>` (numba's pycc, built by
  service/kernel_build.py: `shockbench demo` or `python -m service.kernel_build`), when it exists for the
  present source (the digest is of the sources of KERNEL_MODULES: this file, the kernel's and that of
  estimator.digital_filters' compiled filters, which the extension also holds, and of the values of the
  constants they import, IMPORTED_CONSTANTS). Loading it takes
  milliseconds: it needs neither numba nor its cache. A process that only runs one identify would
  otherwise spend 1-3 s importing numba and loading the cached kernel (numba's typing registries), about
  100 times the simulation itself;
- otherwise numba's just-in-time compile, cached on disk (cache=True: the compile, 10-30 s, is paid once
  per machine and source version; later processes load it from the cache).
This module imports numba only in the second case.
"""

from __future__ import annotations

import importlib
import importlib.util
import zlib
from collections.abc import Callable
from functools import cache
from types import ModuleType

import numpy as np

from estimator.damper import CurveBatch, PiecewiseLinearCurve
from estimator.dynamics import HINGES, AxlePhysics, CornerPhysics, QuarterCarPhysics
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
STRIBECK_PEAK_N = 9
STRIBECK_VELOCITY_M_S = 10  # the kernel adds no Stribeck term where this or the peak is 0
HINGED = 11  # 1.0 where a hinge has a rate (the kernel skips the hinges where not), 0.0 where not
HINGE_KNOT_M = 12  # HINGES rows: the knots of CornerPhysics.hinge_table
HINGE_RATE_N_PER_M = HINGE_KNOT_M + HINGES  # HINGES rows: their rates
PRESLIDING_M = HINGE_RATE_N_PER_M + HINGES  # hysteretic friction's z: the sign is Dahl's h where > 0
GUIDE_BODY_FRICTION_N = PRESLIDING_M + 1  # the frame guides' friction on the body (a quarter-car rig)
GUIDE_WHEEL_FRICTION_N = PRESLIDING_M + 2  # ... and on the wheel
CORNER_ROWS = GUIDE_WHEEL_FRICTION_N + 1

# rows of the per-column body table, shape (BODY_ROWS, columns)
SPRUNG_KG = 0
UNSPRUNG_KG = 1  # per wheel
ROLL_INERTIA_KG_M2 = 2
TRACK_M = 3
ANTI_ROLL_BAR_N_PER_M = 4
BODY_ROWS = 5

# tyre models as the kernel knows them (one per corner)
TYRE_CODES = {TyreModel.MAXWELL: 0, TyreModel.KELVIN_VOIGT: 1, TyreModel.SPRING: 2}

STATE_SLOTS = 12
"""The kernel carries every model's state in 12 slots: the axle's 10 and its corners' Dahl states h_l, h_r
(hysteretic friction); a quarter car uses the first 5 and its h in the sixth. Slots beyond the physics'
state_size start at 0 and are not returned."""

KERNEL_MODULES = (
    "estimator.simulation_kernel",
    "estimator.simulation_kernel_numba",
    "estimator.filter_kernel_numba",
)
"""The modules the extension is built from (its digest covers their source)."""
IMPORTED_CONSTANTS = {
    "estimator.dynamics": ("HINGES",),
    "estimator.friction": ("COULOMB_SMOOTHING_M_S",),
    "estimator.digital_filters": ("FLUSH_BELOW_PEAK",),
}
"""The names the kernel modules import from other modules of ours, by module: the build freezes their
values into the extension, so the digest covers their values too (tests/estimator/test_kernel_digest.py
checks the table lists every such import)."""
EXTENSION_PREFIX = "_simulation_kernel_aot_"


def source_digest() -> str:
    """The kernel's version: a digest of the source of this module (the table layout) and of the kernels'
    (KERNEL_MODULES), as the import system reads them (the kernel modules are not imported: that would
    import numba), and of the values of the constants they import (IMPORTED_CONSTANTS). CRC-32 is enough
    to tell versions apart (this is a cache key, not a seal) and zlib is built in, where hashlib's OpenSSL
    would cost every process about 2.5 ms of its start."""
    digest = 0
    for name in KERNEL_MODULES:
        spec = importlib.util.find_spec(name)
        source = spec.loader.get_source(name) if spec is not None and spec.loader is not None else None
        if source is None:
            raise ImportError(f"no source for {name}")
        digest = zlib.crc32(source.encode(), digest)
    for module, names in IMPORTED_CONSTANTS.items():
        values = importlib.import_module(module).__dict__
        digest = zlib.crc32(repr([(name, values[name]) for name in names]).encode(), digest)
    return f"{digest:08x}"


def extension_name() -> str:
    """The module name of the ahead-of-time extension built from the present source."""
    return EXTENSION_PREFIX + source_digest()


def built_extension() -> str | None:
    """The name of the extension built ahead of time for the present source, None when there is none
    (found, not loaded: no numba import either way). For a service's readiness details: without one,
    every process loads numba (1-3 s) and the first on a machine compiles (10-30 s)."""
    name = extension_name()
    return name if importlib.util.find_spec(f"estimator.{name}") is not None else None


@cache
def _extension() -> ModuleType | None:
    """The extension built ahead of time for the present source, or None where there is none (not built
    for this source, or for this Python / numpy)."""
    try:
        return importlib.import_module(f"estimator.{extension_name()}")
    except ImportError:
        return None


@cache
def _kernel() -> tuple[str, Callable[..., None]]:
    """("extension" or "numba", the kernel's integrate function): the extension built ahead of time when
    it exists for the present source, else numba's just-in-time compile (loaded from its on-disk cache)."""
    extension = _extension()
    if extension is not None:
        return "extension", extension.integrate
    from estimator.simulation_kernel_numba import integrate

    return "numba", integrate


def forget_loaded_kernel() -> None:
    """Look for the kernel again at its next use (after an extension was built or removed)."""
    _extension.cache_clear()
    _kernel.cache_clear()


def compiled_filters() -> ModuleType | None:
    """The extension whose `recursion` and `zero_phase` run estimator.digital_filters' recursive filters
    (source: estimator/filter_kernel_numba.py), or None without an extension for the present source.
    digital_filters then uses LAPACK instead: it does not import numba, whose import and cache load cost a
    fresh process more than its filtering."""
    return _extension()


def kernel_in_use() -> str:
    """What integrate_compiled runs: "extension" (built ahead of time) or "numba" (just in time)."""
    return _kernel()[0]


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
    rows[STRIBECK_PEAK_N] = _per_column(corner.stribeck_peak_N, columns)
    rows[STRIBECK_VELOCITY_M_S] = _per_column(corner.stribeck_velocity_m_s, columns)
    rows[PRESLIDING_M] = _per_column(corner.presliding_m, columns)
    rows[GUIDE_BODY_FRICTION_N] = _per_column(corner.guide_body_friction_N, columns)
    rows[GUIDE_WHEEL_FRICTION_N] = _per_column(corner.guide_wheel_friction_N, columns)
    for first, values in zip((HINGE_KNOT_M, HINGE_RATE_N_PER_M), corner.hinge_table(), strict=True):
        rows[first : first + HINGES] = values if values.ndim == 2 else values[:, None]
    rows[HINGED] = np.any(rows[HINGE_RATE_N_PER_M : HINGE_RATE_N_PER_M + HINGES] != 0.0, axis=0)
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
    _kernel()[1](
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


def warm() -> None:
    """Load the kernel and run it on a tiny model (numba: compiles it or loads it from the on-disk cache), so
    that a long-lived process (the service's worker) pays that once, at start, not in its first job."""
    curve = PiecewiseLinearCurve(np.array([-1.0, 0.0, 1.0]), np.array([-1000.0, 0.0, 1000.0]))
    corner = CornerPhysics(damper=curve, spring_stiffness_N_per_m=20000.0, tyre_stiffness_N_per_m=200000.0)
    physics = QuarterCarPhysics(corner, 300.0, 40.0)
    integrate_compiled(physics, np.zeros(physics.state_size), 0.001, np.zeros(3), np.zeros(3))
