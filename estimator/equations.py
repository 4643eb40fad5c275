"""The equations of motion as residuals that are affine in the unknowns: the paper's f1, f2 (eqs 6-7) for
the quarter car and f1..f4 (eqs 11-14, with the anti-roll bar made physically consistent) for the axle.

With ϑ and the stiffnesses known, every residual at sample i is r_ei = A[e, i, :] @ θ + c[e, i], where θ is
the vector of unknowns. The mass constraint of eq (9) (M_s + M_u = M_1/4; axle: M_s + 2·M_u = M_1/2 with
M_u^l = M_u^r) is substituted, so θ = [M_s, (I,) C, C_a^1..C_a^N (, right curve's points)].

The tyre term C·g: with the Maxwell model of eq (4) the viscoelastic force is
f_v(t) = C_γ·δ̇(t) + ϑ·f_v(t−1), i.e. C_γ times g = δ̇ filtered by 1/(1 − ϑ·z⁻¹); the unknown is C_γ and
the tyre damping is C_d = C_γ·(1+γ) = C_γ/(1−ϑ). Kelvin-Voigt: g = δ̇, C = C_d. Constant stiffness: no term.

The roll equation is divided by b/2 so that every residual is a force in newtons (the paper's eq 17 sums
squares of a moment and forces; the scaling only weighs the roll equation like the others).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps

from estimator.damper import hat_basis
from estimator.recording import AXLE_CHANNELS, QUARTER_CAR_CHANNELS, Recording
from estimator.signals import FilterChoice, Kinematics, choose_filters, derivative, kinematics, lowpass
from estimator.vehicle import TyreModel, VehicleParameters

EDGE_TRIM_S = 0.25
"""Samples this close to either end are left out of the objective (filter start-up transients)."""
GRID_QUANTILE = 0.002
"""The damper velocity grid spans the measured suspension velocities from this quantile to 1 − it; the end
segments extend linearly beyond, so the few samples outside still count."""


@dataclass
class LinearResiduals:
    """r[e, i] = matrix[e, i, :] @ θ + offset[e, i] for equations e and selected samples i."""

    matrix: np.ndarray
    offset: np.ndarray
    parameter_names: list[str]
    grids_m_s: list[np.ndarray]
    """Damper velocity grid(s): one for the quarter car, (left, right) for the axle."""
    curve_slices: list[slice]
    """Where each damper's points sit in θ."""
    tyre_model: TyreModel
    filters: FilterChoice
    sample_index: np.ndarray
    """Indices of the recording's samples used in the objective."""
    velocity_m_s: list[np.ndarray]
    """Suspension velocity at the selected samples, per damper (what the curve is evaluated at)."""
    kinematics: dict[str, Kinematics] = field(default_factory=dict, repr=False)
    """Every channel low-passed at the kinematics cutoff (full length): what output error and the inspection
    figures reuse instead of filtering the recording again."""
    _flat: np.ndarray | None = field(default=None, repr=False)
    _flat_offset: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_params(self) -> int:
        return self.matrix.shape[2]

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Residuals for one θ (shape (p,)) -> (e, n), or a population (P, p) -> (P, e, n)."""
        return np.einsum("enp,...p->...en", self.matrix, theta) + self.offset

    def objective(self, theta: np.ndarray) -> np.ndarray:
        """The paper's GF = Σ_i sqrt(Σ_e r_ei²) for one θ (p,) or a population (P, p)."""
        e, n, p = self.matrix.shape
        if self._flat is None:
            self._flat = np.ascontiguousarray(self.matrix.reshape(e * n, p).T)
            self._flat_offset = self.offset.reshape(e * n)
        gf = population_sum_of_norms(np.atleast_2d(theta), self._flat, self._flat_offset, e)
        return gf if np.ndim(theta) == 2 else gf[0]


def population_sum_of_norms(
    population: np.ndarray, flat: np.ndarray, flat_offset: np.ndarray, equations: int
) -> np.ndarray:
    """Σ_i sqrt(Σ_e r_ei²) for every row of `population` (P, p), where the residuals are
    population @ flat + flat_offset laid out equation-major, shape (P, e·n): one matrix product for the whole
    population, then squares and roots in place. Runs in the arrays' precision; sums in float64."""
    r = population @ flat
    r += flat_offset
    np.square(r, out=r)
    norms = r.reshape(r.shape[0], equations, -1).sum(axis=1)
    np.sqrt(norms, out=norms)
    return norms.sum(axis=1, dtype=np.float64)


def tyre_regressor(rate_m_s: np.ndarray, tyre: TyreModel, theta: float) -> np.ndarray | None:
    """g such that the tyre's viscous force is C·g (None for constant stiffness)."""
    if tyre is TyreModel.SPRING:
        return None
    if tyre is TyreModel.KELVIN_VOIGT:
        return rate_m_s
    return sps.lfilter([1.0], [1.0, -theta], rate_m_s)


def tyre_damping_from_coefficient(coefficient: float, tyre: TyreModel, theta: float) -> float:
    """C_d from the identified C (C_γ for Maxwell: C_d = C_γ/(1−ϑ))."""
    return coefficient / (1.0 - theta) if tyre is TyreModel.MAXWELL else coefficient


def select_samples(n: int, sample_time_s: float, nsample: int | None) -> np.ndarray:
    """nsample indices spread evenly over the recording, edges trimmed; all samples when nsample is None."""
    trim = round(EDGE_TRIM_S / sample_time_s)
    usable = np.arange(trim, n - trim)
    if usable.size < 10:
        raise ValueError("recording too short: less than 10 samples after trimming filter transients")
    if nsample is None or nsample >= usable.size:
        return usable
    return usable[np.linspace(0, usable.size - 1, nsample).round().astype(int)]


def velocity_grid(velocity_m_s: np.ndarray, points: int) -> np.ndarray:
    lo, hi = np.quantile(velocity_m_s, [GRID_QUANTILE, 1.0 - GRID_QUANTILE])
    if not hi > lo:
        raise ValueError("the suspension barely moved: no velocity range to identify a damper curve on")
    return np.linspace(lo, hi, points)


class _Columns:
    """Builds equation-filtered columns of the recording."""

    def __init__(self, recording: Recording, filters: FilterChoice, index: np.ndarray) -> None:
        self.rec = recording
        self.f = filters
        self.dt = recording.sample_time_s
        self.index = index
        self.kin = {
            name: kinematics(x, filters.kinematics_cutoff_Hz, self.dt)
            for name, x in recording.channels.items()
        }

    def eq(self, x: np.ndarray) -> np.ndarray:
        """Equation-filtered column at the selected samples."""
        return lowpass(x, self.f.equation_cutoff_Hz, self.dt)[self.index]

    def acceleration(self, name: str) -> np.ndarray:
        filtered = lowpass(self.rec.channels[name], self.f.equation_cutoff_Hz, self.dt)
        return derivative(derivative(filtered, self.dt), self.dt)[self.index]

    def damper_basis(self, velocity: np.ndarray, grid: np.ndarray) -> np.ndarray:
        basis = hat_basis(velocity, grid)
        return lowpass(basis, self.f.equation_cutoff_Hz, self.dt, axis=0)[self.index]

    def velocity(self, name: str) -> np.ndarray:
        return self.kin[name].velocity_m_s


def build_quarter_car(
    recording: Recording,
    vehicle: VehicleParameters,
    tyre: TyreModel,
    points: int = 20,
    nsample: int | None = 5000,
    filters: FilterChoice | None = None,
    grids: list[np.ndarray] | None = None,
) -> LinearResiduals:
    """f1 = M_s·ẍ_s + F_d(v) + K·ζ ; f2 = (M − M_s)·ẍ_t − F_d(v) − K·ζ + C·g + K_t·δ (paper eqs 6-7).

    grids: the damper velocity grid to use instead of one spanning the measured velocities (so that systems
    built from corrected versions of one recording share their unknowns)."""
    recording.require(QUARTER_CAR_CHANNELS)
    filters = filters or choose_filters(recording.channels, recording.sample_time_s)
    index = select_samples(recording.time_s.size, recording.sample_time_s, nsample)
    cols = _Columns(recording, filters, index)
    ch = recording.channels
    v = cols.velocity("x_s") - cols.velocity("x_t")
    grid = grids[0] if grids is not None else velocity_grid(v[index], points)
    points = grid.size
    phi = cols.damper_basis(v, grid)
    a_s, a_t = cols.acceleration("x_s"), cols.acceleration("x_t")
    zeta = cols.eq(ch["x_s"] - ch["x_t"])
    tyre_defl = cols.eq(ch["x_t"] - ch["x_r"])
    g = tyre_regressor(
        cols.velocity("x_t") - cols.velocity("x_r"), tyre, vehicle.tyre_viscoelastic_coefficient
    )
    n = index.size
    zeros = np.zeros((n, 1))
    tyre_col = [cols.eq(g)[:, None]] if g is not None else []
    tyre_zero = [zeros] if g is not None else []
    k, kt, m = vehicle.spring_stiffness_N_per_m, vehicle.tyre_stiffness_N_per_m, vehicle.mass_kg
    f1 = np.hstack([a_s[:, None], *tyre_zero, phi])
    f2 = np.hstack([-a_t[:, None], *tyre_col, -phi])
    names = [
        "sprung_mass_kg",
        *(["tyre_coefficient"] if g is not None else []),
        *[f"C_a{j + 1}" for j in range(points)],
    ]
    start = 1 + len(tyre_col)
    return LinearResiduals(
        matrix=np.stack([f1, f2]),
        offset=np.stack([k * zeta, m * a_t - k * zeta + kt * tyre_defl]),
        parameter_names=names,
        grids_m_s=[grid],
        curve_slices=[slice(start, start + points)],
        tyre_model=tyre,
        filters=filters,
        sample_index=index,
        velocity_m_s=[v[index]],
        kinematics=cols.kin,
    )


def build_axle(
    recording: Recording,
    vehicle: VehicleParameters,
    tyre: TyreModel,
    points: int = 10,
    nsample: int | None = 5000,
    filters: FilterChoice | None = None,
    grids: list[np.ndarray] | None = None,
) -> LinearResiduals:
    """Wheel equations f1 (left), f2 (right), heave f3, roll f4/(b/2); θ = [M_s, I, C, left pts, right pts].
    grids: (left, right) damper velocity grids to use, as for build_quarter_car.

    Q_side = F_d(v_side) + K·ζ_side ± K_e·(ζ_l − ζ_r) (+ left, − right) is the suspension force;
    f_wheel = M_u·ẍ_t − Q + C·g + K_t·δ, M_u = (M − M_s)/2; f3 = M_s·ẍ_G + Q_l + Q_r;
    f4 = I·θ̈·(2/b) + Q_l − Q_r with x_G = (x_s_l + x_s_r)/2 and θ = (x_s_l − x_s_r)/b.
    """
    recording.require(AXLE_CHANNELS)
    filters = filters or choose_filters(recording.channels, recording.sample_time_s)
    index = select_samples(recording.time_s.size, recording.sample_time_s, nsample)
    cols = _Columns(recording, filters, index)
    ch = recording.channels
    n = index.size
    k, kt, m = vehicle.spring_stiffness_N_per_m, vehicle.tyre_stiffness_N_per_m, vehicle.mass_kg
    ke, b = vehicle.anti_roll_bar_stiffness_N_per_m, float(vehicle.track_m or 0.0)
    zeta = {s: cols.eq(ch[f"x_s_{s}"] - ch[f"x_t_{s}"]) for s in "lr"}
    bar = ke * (zeta["l"] - zeta["r"])
    # per side: the part of Q that is known (spring + bar), and the damper basis
    q_known = {"l": k * zeta["l"] + bar, "r": k * zeta["r"] - bar}
    vel, used_grids, phis = [], [], {}
    for number, s in enumerate("lr"):
        v = cols.velocity(f"x_s_{s}") - cols.velocity(f"x_t_{s}")
        grid = grids[number] if grids is not None else velocity_grid(v[index], points)
        phis[s] = cols.damper_basis(v, grid)
        used_grids.append(grid)
        vel.append(v[index])
    points = used_grids[0].size
    if used_grids[1].size != points:
        raise ValueError("the left and right damper grids must have the same number of points")
    a_t = {s: cols.acceleration(f"x_t_{s}") for s in "lr"}
    a_s = {s: cols.acceleration(f"x_s_{s}") for s in "lr"}
    a_heave = 0.5 * (a_s["l"] + a_s["r"])
    roll_acc = (a_s["l"] - a_s["r"]) / b
    g = {
        s: tyre_regressor(
            cols.velocity(f"x_t_{s}") - cols.velocity(f"x_r_{s}"), tyre, vehicle.tyre_viscoelastic_coefficient
        )
        for s in "lr"
    }
    has_tyre = g["l"] is not None
    zero = np.zeros((n, 1))
    zero_pts = np.zeros((n, points))

    def row(ms: np.ndarray, inertia: np.ndarray, tyre_col: np.ndarray, left: np.ndarray, right: np.ndarray):
        parts = [ms[:, None], inertia[:, None], *([tyre_col] if has_tyre else []), left, right]
        return np.hstack(parts)

    tyre_cols = {s: cols.eq(g[s])[:, None] if has_tyre else zero for s in "lr"}
    z = np.zeros(n)
    f1 = row(-0.5 * a_t["l"], z, tyre_cols["l"], -phis["l"], zero_pts)
    f2 = row(-0.5 * a_t["r"], z, tyre_cols["r"], zero_pts, -phis["r"])
    f3 = row(a_heave, z, zero, phis["l"], phis["r"])
    f4 = row(z, roll_acc * 2.0 / b, zero, phis["l"], -phis["r"])
    defl = {s: cols.eq(ch[f"x_t_{s}"] - ch[f"x_r_{s}"]) for s in "lr"}
    offset = np.stack(
        [
            0.5 * m * a_t["l"] - q_known["l"] + kt * defl["l"],
            0.5 * m * a_t["r"] - q_known["r"] + kt * defl["r"],
            q_known["l"] + q_known["r"],
            q_known["l"] - q_known["r"],
        ]
    )
    names = [
        "sprung_mass_kg",
        "roll_inertia_kg_m2",
        *(["tyre_coefficient"] if has_tyre else []),
        *[f"C_a{j + 1}_left" for j in range(points)],
        *[f"C_a{j + 1}_right" for j in range(points)],
    ]
    start = 3 if has_tyre else 2
    return LinearResiduals(
        matrix=np.stack([f1, f2, f3, f4]),
        offset=offset,
        parameter_names=names,
        grids_m_s=used_grids,
        curve_slices=[slice(start, start + points), slice(start + points, start + 2 * points)],
        tyre_model=tyre,
        filters=filters,
        sample_index=index,
        velocity_m_s=vel,
        kinematics=cols.kin,
    )


def build(
    recording: Recording,
    vehicle: VehicleParameters,
    tyre: TyreModel,
    points: int | None = None,
    nsample: int | None = 5000,
    filters: FilterChoice | None = None,
    grids: list[np.ndarray] | None = None,
) -> LinearResiduals:
    """The residual system for the vehicle's model (default points: 20 for a quarter car, 10 for an axle).
    filters and grids, when given, are used instead of being chosen from the recording."""
    if vehicle.is_axle:
        return build_axle(recording, vehicle, tyre, points or 10, nsample, filters, grids)
    return build_quarter_car(recording, vehicle, tyre, points or 20, nsample, filters, grids)
