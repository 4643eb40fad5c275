"""The equations of motion as residuals that are affine in the unknowns: the paper's f1, f2 (eqs 6-7) for
the quarter car and f1..f4 (eqs 11-14, with the anti-roll bar made physically consistent) for the axle.

With ϑ known, every residual at sample i is r_ei = A[e, i, :] @ θ + c[e, i], where θ is the vector of
unknowns. The mass constraint of eq (9) (M_s + M_u = M_1/4; axle: M_s + 2·M_u = M_1/2 with M_u^l = M_u^r) is
substituted, so θ = [M_s, (I,) C, C_a^1..C_a^N (, right curve's points), free stiffnesses (, a lab rig's
frame guides' frictions, estimator.frame_guides)]. A stiffness the vehicle file states goes into c (its
force is known); one that is free (not stated, or `identify --free`) is one more unknown whose column is
its force per unit stiffness, like a damper basis function: the spring K_s·ζ in the suspension, the tyre
K_t·δ in the wheel equation(s), the axle's bar K_e·(ζ_l − ζ_r). An axle has one K_s and one K_t for both
sides.

The tyre term C_d·g: the viscous force of the tyre is C_d (the unknown tyre damping) times a regressor g
made from the tyre deflection rate δ̇. Kelvin-Voigt: g = δ̇. Constant stiffness: no term. Maxwell (eq 3,
τ·ḟ_v + f_v = C_d·δ̇ with τ = C_d/K_d = Δt·ϑ/(1−ϑ)): g is δ̇ through the element discretised by the bilinear
transform, g_k = a·g_(k−1) + b·(δ̇_k + δ̇_(k−1)), a = (3ϑ−1)/(1+ϑ), b = (1−ϑ)/(1+ϑ) (= (2τ−Δt)/(2τ+Δt) and
Δt/(2τ+Δt)). Deviation from the paper's eq (4), f_v(t) = C_γ·δ̇(t) + ϑ·f_v(t−1), which is the backward-Euler
discretisation of the same element: its phase error grows with ω·Δt, and on simulated sweeps (tests) it
biases an identified τ by −10% at 1 ms and −20% at 2 ms, the tyre stiffness by +1-2% and the masses by up
to 1%; the bilinear transform leaves them unbiased at both rates. ϑ keeps the paper's meaning.
The roll equation is divided by b/2 so that every residual is a force in newtons (the paper's eq 17 sums
squares of a moment and forces; the scaling only weighs the roll equation like the others).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from estimator.damper import hat_basis, velocity_grid
from estimator.digital_filters import first_order_filter
from estimator.errors import InvalidValueError
from estimator.frame_guides import GUIDE_FRICTION_NAMES, guide_columns
from estimator.recording import AXLE_CHANNELS, QUARTER_CAR_CHANNELS, Recording
from estimator.signals import FilterChoice, Kinematics, choose_filters, derivative, kinematics, lowpass
from estimator.vehicle import TyreModel, VehicleConstant, VehicleParameters

EDGE_TRIM_S = 0.25
"""Samples this close to either end are left out of the objective (filter start-up transients)."""
STIFFNESS_NAMES = {
    VehicleConstant.SPRING: "spring_stiffness_N_per_m",
    VehicleConstant.TYRE: "tyre_stiffness_N_per_m",
    VehicleConstant.BAR: "anti_roll_bar_stiffness_N_per_m",
}
"""The unknown's name in θ of each stiffness that can be free (the vehicle file's key)."""
TYRE_DAMPING = "tyre_damping_Ns_per_m"
"""The unknown's name in θ of the tyre damping C_d (Kelvin-Voigt and Maxwell)."""


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
    tyre_theta: float | None = None
    """The ϑ (at the recording's sample time) the Maxwell tyre column was built with."""
    tyre_rates_m_s: list[np.ndarray] = field(default_factory=list, repr=False)
    """Tyre deflection rate δ̇ per corner, full length, after the equation low-pass: the tyre column is
    tyre_regressor of it at the selected samples (the regressor is a linear time-invariant filter, so
    filtering before it equals filtering after it except within the trimmed edges: 3e-9 of the column at
    ϑ = 0.97)."""
    tyre_equations: list[int] = field(default_factory=list)
    """The equation (row of matrix) that carries each corner's tyre column."""
    _flat: np.ndarray | None = field(default=None, repr=False)
    _flat_offset: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_params(self) -> int:
        return self.matrix.shape[2]

    def value(self, theta: np.ndarray, name: str) -> float | None:
        """The unknown called `name` in θ (None when the system has no such unknown)."""
        return float(theta[self.parameter_names.index(name)]) if name in self.parameter_names else None

    def with_tyre_theta(self, theta: float) -> LinearResiduals:
        """The same system with the Maxwell tyre column built for another ϑ (at the recording's sample
        time): only that column changes, so a search over ϑ does not rebuild the system."""
        if self.tyre_model is not TyreModel.MAXWELL:
            raise InvalidValueError("ϑ applies to the maxwell tyre model only")
        column = self.parameter_names.index(TYRE_DAMPING)
        matrix = self.matrix.copy()
        for rate, equation in zip(self.tyre_rates_m_s, self.tyre_equations, strict=True):
            matrix[equation, :, column] = maxwell_regressor(rate, theta)[self.sample_index]
        return replace(self, matrix=matrix, tyre_theta=theta, _flat=None, _flat_offset=None)

    def with_unknown_held(self, name: str, value: float) -> LinearResiduals:
        """The same system with the unknown `name` held at `value`: its column moved into the offset and
        dropped from θ (parameter_names without it)."""
        index = self.parameter_names.index(name)
        keep = [k for k in range(self.n_params) if k != index]
        return replace(
            self,
            matrix=self.matrix[:, :, keep],
            offset=self.offset + value * self.matrix[:, :, index],
            parameter_names=[self.parameter_names[k] for k in keep],
            _flat=None,
            _flat_offset=None,
        )

    def reparametrised(self, basis: np.ndarray, names: list[str]) -> LinearResiduals:
        """The same residuals in new unknowns z, θ = basis·z (basis of shape (len θ, len z)), named `names`:
        how linear equality constraints on θ are eliminated."""
        return replace(
            self,
            matrix=np.einsum("enp,pq->enq", self.matrix, basis),
            parameter_names=list(names),
            _flat=None,
            _flat_offset=None,
        )

    def subset(self, keep: np.ndarray) -> LinearResiduals:
        """The same system on some of its selected samples (keep: indices or a mask over sample_index)."""
        return replace(
            self,
            matrix=self.matrix[:, keep],
            offset=self.offset[:, keep],
            sample_index=self.sample_index[keep],
            velocity_m_s=[v[keep] for v in self.velocity_m_s],
            _flat=None,
            _flat_offset=None,
        )

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


def maxwell_regressor(rate_m_s: np.ndarray, theta: float) -> np.ndarray:
    """g with f_v = C_d·g for the Maxwell element at ϑ (at the rate's sample time), by the bilinear
    transform (module docstring). ϑ = 0 (τ = 0) is the element's limit, a dashpot: g = δ̇."""
    if theta == 0.0:
        return np.asarray(rate_m_s, dtype=float)
    gain = (1.0 - theta) / (1.0 + theta)
    return first_order_filter((gain, gain), -(3.0 * theta - 1.0) / (1.0 + theta), rate_m_s)


def tyre_regressor(rate_m_s: np.ndarray, tyre: TyreModel, theta: float | None) -> np.ndarray | None:
    """g such that the tyre's viscous force is C_d·g (None for constant stiffness); theta: ϑ at the rate's
    sample time (Maxwell only)."""
    if tyre is TyreModel.SPRING:
        return None
    if tyre is TyreModel.KELVIN_VOIGT:
        return rate_m_s
    if theta is None:
        raise InvalidValueError("the maxwell tyre needs ϑ")
    return maxwell_regressor(rate_m_s, theta)


def select_samples(n: int, sample_time_s: float, nsample: int | None) -> np.ndarray:
    """nsample indices spread evenly over the recording, edges trimmed; all samples when nsample is None."""
    trim = round(EDGE_TRIM_S / sample_time_s)
    usable = np.arange(trim, n - trim)
    if usable.size < 10:
        raise InvalidValueError("recording too short: less than 10 samples after trimming filter transients")
    if nsample is None or nsample >= usable.size:
        return usable
    return usable[np.linspace(0, usable.size - 1, nsample).round().astype(int)]


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
        return self.eq_full(x)[self.index]

    def eq_full(self, x: np.ndarray) -> np.ndarray:
        """Equation-filtered series, full length."""
        return lowpass(x, self.f.equation_cutoff_Hz, self.dt)

    def acceleration(self, name: str) -> np.ndarray:
        filtered = lowpass(self.rec.channels[name], self.f.equation_cutoff_Hz, self.dt)
        return derivative(derivative(filtered, self.dt), self.dt)[self.index]

    def damper_basis(self, velocity: np.ndarray, grid: np.ndarray) -> np.ndarray:
        basis = hat_basis(velocity, grid)
        return lowpass(basis, self.f.equation_cutoff_Hz, self.dt, axis=0)[self.index]

    def velocity(self, name: str) -> np.ndarray:
        return self.kin[name].velocity_m_s


def free_stiffnesses(
    vehicle: VehicleParameters, free: frozenset[VehicleConstant] = frozenset()
) -> frozenset[VehicleConstant]:
    """The stiffnesses that are unknowns of the system: those the vehicle does not state, and those asked
    for (`free`); the anti-roll bar only on an axle."""
    wanted = (vehicle.unknown | free) & set(STIFFNESS_NAMES)
    if VehicleConstant.BAR in wanted and not vehicle.is_axle:
        raise InvalidValueError("the anti-roll bar applies to an axle only")
    return frozenset(wanted)


def _stiffness_terms(
    vehicle: VehicleParameters,
    free: frozenset[VehicleConstant],
    unit_forces: dict[VehicleConstant, np.ndarray],
) -> tuple[list[np.ndarray], list[str], np.ndarray]:
    """Free stiffnesses become columns (their (equations, samples) force per N/m), stated ones add their
    force to the offset. Returns the columns, their names and the offset to add."""
    stated = {
        VehicleConstant.SPRING: vehicle.spring_stiffness_N_per_m,
        VehicleConstant.TYRE: vehicle.tyre_stiffness_N_per_m,
        VehicleConstant.BAR: vehicle.anti_roll_bar_stiffness_N_per_m,
    }
    columns, names = [], []
    offset = np.zeros_like(next(iter(unit_forces.values())))
    for constant, unit in unit_forces.items():
        if constant in free:
            columns.append(unit[:, :, None])
            names.append(STIFFNESS_NAMES[constant])
        elif stated[constant]:
            offset = offset + float(stated[constant]) * unit
    return columns, names, offset


def _tyre_theta(vehicle: VehicleParameters, tyre: TyreModel, sample_time_s: float) -> float | None:
    """ϑ at the recording's sample time for the Maxwell tyre (None for the other tyre models)."""
    if tyre is not TyreModel.MAXWELL:
        return None
    if vehicle.tyre_viscoelastic_coefficient is None:
        raise InvalidValueError("the maxwell tyre needs ϑ: state it, or identify it (estimator.identify)")
    return vehicle.viscoelastic_coefficient_at(sample_time_s)


def build_quarter_car(
    recording: Recording,
    vehicle: VehicleParameters,
    tyre: TyreModel,
    points: int = 20,
    nsample: int | None = 5000,
    filters: FilterChoice | None = None,
    grids: list[np.ndarray] | None = None,
    free: frozenset[VehicleConstant] = frozenset(),
    guides: bool = True,
) -> LinearResiduals:
    """f1 = M_s·ẍ_s + F_d(v) + K_s·ζ ; f2 = (M − M_s)·ẍ_t − F_d(v) − K_s·ζ + C·g + K_t·δ (paper eqs 6-7).

    grids: the damper velocity grid to use instead of one spanning the measured velocities (so that systems
    built from corrected versions of one recording share their unknowns). free: stiffnesses to identify
    although the vehicle states them (see free_stiffnesses). A rig whose vehicle states frame guides has
    their friction, each mass's against the frame, as two more unknowns (estimator.frame_guides), unless
    `guides` is False (the model doctor starts without them and tests them)."""
    recording.require(QUARTER_CAR_CHANNELS)
    free = free_stiffnesses(vehicle, free)
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
    theta = _tyre_theta(vehicle, tyre, recording.sample_time_s)
    rate = cols.eq_full(cols.velocity("x_t") - cols.velocity("x_r"))
    g = tyre_regressor(rate, tyre, theta)
    n = index.size
    zeros = np.zeros((n, 1))
    tyre_col = [g[index][:, None]] if g is not None else []
    tyre_zero = [zeros] if g is not None else []
    stiffness_cols, stiffness_names, known_force = _stiffness_terms(
        vehicle,
        free,
        {
            VehicleConstant.SPRING: np.stack([zeta, -zeta]),
            VehicleConstant.TYRE: np.stack([np.zeros(n), tyre_defl]),
        },
    )
    f1 = np.hstack([a_s[:, None], *tyre_zero, phi])
    f2 = np.hstack([-a_t[:, None], *tyre_col, -phi])
    guided = guides and vehicle.frame_guides
    guide_cols = guide_columns(cols.velocity("x_s"), cols.velocity("x_t"), cols.eq) if guided else ()
    names = [
        "sprung_mass_kg",
        *([TYRE_DAMPING] if g is not None else []),
        *[f"C_a{j + 1}" for j in range(points)],
        *stiffness_names,
        *(GUIDE_FRICTION_NAMES if guided else ()),
    ]
    start = 1 + len(tyre_col)
    guide_unknowns = [column[:, :, None] for column in guide_cols]
    matrix = np.concatenate([np.stack([f1, f2]), *stiffness_cols, *guide_unknowns], axis=2)
    return LinearResiduals(
        matrix=matrix,
        offset=np.stack([np.zeros(n), vehicle.mass_kg * a_t]) + known_force,
        parameter_names=names,
        grids_m_s=[grid],
        curve_slices=[slice(start, start + points)],
        tyre_model=tyre,
        filters=filters,
        sample_index=index,
        velocity_m_s=[v[index]],
        kinematics=cols.kin,
        tyre_theta=theta,
        tyre_rates_m_s=[rate] if g is not None else [],
        tyre_equations=[1] if g is not None else [],
    )


def build_axle(
    recording: Recording,
    vehicle: VehicleParameters,
    tyre: TyreModel,
    points: int = 10,
    nsample: int | None = 5000,
    filters: FilterChoice | None = None,
    grids: list[np.ndarray] | None = None,
    free: frozenset[VehicleConstant] = frozenset(),
) -> LinearResiduals:
    """Wheel equations f1 (left), f2 (right), heave f3, roll f4/(b/2); θ = [M_s, I, C, left pts, right pts,
    free stiffnesses]. grids and free: as for build_quarter_car.

    Q_side = F_d(v_side) + K_s·ζ_side ± K_e·(ζ_l − ζ_r) (+ left, − right) is the suspension force;
    f_wheel = M_u·ẍ_t − Q + C·g + K_t·δ, M_u = (M − M_s)/2; f3 = M_s·ẍ_G + Q_l + Q_r;
    f4 = I·θ̈·(2/b) + Q_l − Q_r with x_G = (x_s_l + x_s_r)/2 and θ = (x_s_l − x_s_r)/b.
    """
    recording.require(AXLE_CHANNELS)
    free = free_stiffnesses(vehicle, free)
    filters = filters or choose_filters(recording.channels, recording.sample_time_s)
    index = select_samples(recording.time_s.size, recording.sample_time_s, nsample)
    cols = _Columns(recording, filters, index)
    ch = recording.channels
    n = index.size
    b = float(vehicle.track_m or 0.0)
    zeta = {s: cols.eq(ch[f"x_s_{s}"] - ch[f"x_t_{s}"]) for s in "lr"}
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
    theta = _tyre_theta(vehicle, tyre, recording.sample_time_s)
    rates = {s: cols.eq_full(cols.velocity(f"x_t_{s}") - cols.velocity(f"x_r_{s}")) for s in "lr"}
    g = {s: tyre_regressor(rates[s], tyre, theta) for s in "lr"}
    has_tyre = g["l"] is not None
    zero = np.zeros((n, 1))
    zero_pts = np.zeros((n, points))

    def row(ms: np.ndarray, inertia: np.ndarray, tyre_col: np.ndarray, left: np.ndarray, right: np.ndarray):
        parts = [ms[:, None], inertia[:, None], *([tyre_col] if has_tyre else []), left, right]
        return np.hstack(parts)

    tyre_cols = {s: g[s][index][:, None] if has_tyre else zero for s in "lr"}
    z = np.zeros(n)
    f1 = row(-0.5 * a_t["l"], z, tyre_cols["l"], -phis["l"], zero_pts)
    f2 = row(-0.5 * a_t["r"], z, tyre_cols["r"], zero_pts, -phis["r"])
    f3 = row(a_heave, z, zero, phis["l"], phis["r"])
    f4 = row(z, roll_acc * 2.0 / b, zero, phis["l"], -phis["r"])
    defl = {s: cols.eq(ch[f"x_t_{s}"] - ch[f"x_r_{s}"]) for s in "lr"}
    roll_deflection = zeta["l"] - zeta["r"]
    stiffness_cols, stiffness_names, known_force = _stiffness_terms(
        vehicle,
        free,
        {
            VehicleConstant.SPRING: np.stack(
                [-zeta["l"], -zeta["r"], zeta["l"] + zeta["r"], zeta["l"] - zeta["r"]]
            ),
            VehicleConstant.TYRE: np.stack([defl["l"], defl["r"], z, z]),
            VehicleConstant.BAR: np.stack([-roll_deflection, roll_deflection, z, 2.0 * roll_deflection]),
        },
    )
    base = np.stack([0.5 * vehicle.mass_kg * a_t["l"], 0.5 * vehicle.mass_kg * a_t["r"], z, z])
    names = [
        "sprung_mass_kg",
        "roll_inertia_kg_m2",
        *([TYRE_DAMPING] if has_tyre else []),
        *[f"C_a{j + 1}_left" for j in range(points)],
        *[f"C_a{j + 1}_right" for j in range(points)],
        *stiffness_names,
    ]
    start = 3 if has_tyre else 2
    matrix = np.stack([f1, f2, f3, f4])
    if stiffness_cols:
        matrix = np.concatenate([matrix, *stiffness_cols], axis=2)
    return LinearResiduals(
        matrix=matrix,
        offset=base + known_force,
        parameter_names=names,
        grids_m_s=used_grids,
        curve_slices=[slice(start, start + points), slice(start + points, start + 2 * points)],
        tyre_model=tyre,
        filters=filters,
        sample_index=index,
        velocity_m_s=vel,
        kinematics=cols.kin,
        tyre_theta=theta,
        tyre_rates_m_s=[rates["l"], rates["r"]] if has_tyre else [],
        tyre_equations=[0, 1] if has_tyre else [],
    )


def default_points(vehicle: VehicleParameters) -> int:
    """Damper curve points per side when none are asked for: 20 for a quarter car, 10 per side for an axle."""
    return 10 if vehicle.is_axle else 20


def damper_grids(
    recording: Recording,
    vehicle: VehicleParameters,
    points: int | None = None,
    nsample: int | None = 5000,
    filters: FilterChoice | None = None,
) -> tuple[FilterChoice, list[np.ndarray]]:
    """The filters and damper velocity grids `build` chooses from the recording (default points as build's),
    without building the system (for callers that only need them, e.g. each bootstrap draw of the doctor)."""
    filters = filters or choose_filters(recording.channels, recording.sample_time_s)
    index = select_samples(recording.time_s.size, recording.sample_time_s, nsample)
    sides = [f"_{s}" for s in "lr"] if vehicle.is_axle else [""]
    recording.require(AXLE_CHANNELS if vehicle.is_axle else QUARTER_CAR_CHANNELS)
    grids, cutoff_Hz, dt = [], filters.kinematics_cutoff_Hz, recording.sample_time_s
    for side in sides:
        body, wheel = (kinematics(recording.channels[f"{n}{side}"], cutoff_Hz, dt) for n in ("x_s", "x_t"))
        velocity = body.velocity_m_s - wheel.velocity_m_s
        grids.append(velocity_grid(velocity[index], points or default_points(vehicle)))
    return filters, grids


def build(
    recording: Recording,
    vehicle: VehicleParameters,
    tyre: TyreModel,
    points: int | None = None,
    nsample: int | None = 5000,
    filters: FilterChoice | None = None,
    grids: list[np.ndarray] | None = None,
    free: frozenset[VehicleConstant] = frozenset(),
    guides: bool = True,
) -> LinearResiduals:
    """The residual system for the vehicle's model (default points: default_points).
    filters and grids, when given, are used instead of being chosen from the recording; the stiffnesses the
    vehicle does not state, and those in `free`, are unknowns (free_stiffnesses); a rig's frame guides too,
    unless `guides` is False (build_quarter_car)."""
    points = points or default_points(vehicle)
    if vehicle.is_axle:
        return build_axle(recording, vehicle, tyre, points, nsample, filters, grids, free)
    return build_quarter_car(recording, vehicle, tyre, points, nsample, filters, grids, free, guides)
