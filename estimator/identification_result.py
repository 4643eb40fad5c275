"""What an identification found (IdentificationResult): the identified model, the damper curve(s) with
their tanh fits, the objective and how close to the optimum, the output-error gap, the inspection figures,
the 95% intervals, and the stable JSON of `shockbench identify --json`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimator.damper import PiecewiseLinearCurve
from estimator.equations import STIFFNESS_NAMES, TYRE_DAMPING, LinearResiduals
from estimator.frame_guides import GUIDE_FRICTION_NAMES
from estimator.identify_options import Solver
from estimator.inspection import CornerInspection
from estimator.model_io import ModelWithEffects
from estimator.output_error import IdentifiedModel
from estimator.tanh_fit import TanhFit
from estimator.uncertainty import Intervals
from estimator.vehicle import VehicleConstant


@dataclass(frozen=True)
class CornerCurve:
    corner: str  # "single", "left" or "right"
    curve: PiecewiseLinearCurve
    tanh: TanhFit


@dataclass
class IdentificationResult:
    model: IdentifiedModel
    curves: list[CornerCurve]
    objective: float
    solver: Solver
    certified_gap: float
    """Relative optimality gap of the reported solution, certified by the exact solver's dual bound."""
    gap_m: float | None
    inspection: dict[str, CornerInspection]
    imbalance: dict[str, float] | None
    system: LinearResiduals
    de_generations: int | None = None
    refined_gap_m: float | None = None
    identified: frozenset[VehicleConstant] = frozenset()
    """The vehicle constants found from the recording (the rest are the vehicle file's)."""
    warnings: list[str] = field(default_factory=list)
    intervals: Intervals | None = None
    """95% confidence intervals of θ (estimator.uncertainty), None when not asked for."""

    @property
    def refined(self) -> bool:
        """The curve and the tyre damping were refined on the output error (refine_output_error)."""
        return self.refined_gap_m is not None

    def curve_band(self, index: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(low, high) force at the grid points of curve `index`, None without intervals, and None after the
        output-error refinement: the bands are the equation fit's, and the refinement moves the curve off
        that fit (its points may lie outside them), so they are no band of the curve reported."""
        if self.intervals is None or self.refined:
            return None
        where = self.system.curve_slices[index]
        return self.intervals.low[where], self.intervals.high[where]

    def intervals_json(self) -> dict[str, object]:
        """The `*_interval` keys of the JSON ([low, high] pairs), empty without intervals. The unsprung
        mass is M − M_s (axle: (M − M_s)/2), so its interval is the sprung one's mirrored."""
        if self.intervals is None:
            return {}
        sprung = self.intervals.interval("sprung_mass_kg")
        assert sprung is not None
        vehicle = self.model.vehicle
        unsprung = [vehicle.unsprung_mass_kg(sprung[1]), vehicle.unsprung_mass_kg(sprung[0])]
        out: dict[str, object] = {
            "masses_kg_interval": {"sprung": list(sprung), "unsprung": unsprung},
            "stiffness_N_per_m_interval": {
                key: list(interval)
                for key, name in STIFFNESS_JSON_KEYS.items()
                if (interval := self.intervals.interval(name)) is not None
            },
        }
        damping = None if self.refined else self.intervals.interval(TYRE_DAMPING)  # as curve_band's
        out["tyre_damping_Ns_per_m_interval"] = list(damping) if damping is not None else None
        inertia = self.intervals.interval("roll_inertia_kg_m2")
        if inertia is not None:
            out["roll_inertia_kg_m2_interval"] = list(inertia)
        guides = {name: list(i) for name in GUIDE_FRICTION_NAMES if (i := self.intervals.interval(name))}
        if guides:  # a lab rig's frame guides (the refinement leaves them as the equations found them)
            out["effects_interval"] = guides
        return out

    def to_json(self) -> dict[str, object]:
        """The stable JSON shape of `shockbench identify --json`."""
        m = self.model
        inspection: dict[str, object]
        if len(self.inspection) == 1:
            inspection = self.inspection["single"].as_dict()
        else:
            inspection = {side: ins.as_dict() for side, ins in self.inspection.items()}
            inspection["imbalance"] = self.imbalance
        curves: list[dict[str, object]] = []
        for index, c in enumerate(self.curves):
            entry: dict[str, object] = {
                "corner": c.corner,
                "velocity_m_s": c.curve.velocity_m_s.tolist(),
                "force_N": c.curve.force_N.tolist(),
            }
            band = self.curve_band(index)
            if band is not None:
                entry["force_N_low"], entry["force_N_high"] = band[0].tolist(), band[1].tolist()
            entry |= {"tanh": c.tanh.curve.as_dict(), "tanh_rms_N": c.tanh.rms_N, "outliers": c.tanh.outliers}
            curves.append(entry)
        out: dict[str, object] = {
            "curves": curves,
            "masses_kg": {"sprung": m.sprung_mass_kg, "unsprung": m.unsprung_mass_kg},
            "stiffness_N_per_m": self.stiffness_json(),
            "tyre_viscoelastic_coefficient": m.vehicle.tyre_viscoelastic_coefficient,
            "tyre_relaxation_time_s": m.vehicle.tyre_relaxation_time_s,
            "tyre_viscoelastic_identified": VehicleConstant.THETA in self.identified,
            "tyre_damping_Ns_per_m": m.tyre_damping_Ns_per_m,
            "tyre_model": m.tyre_model.value,
            **self.effects_json(),
            "objective": self.objective,
            "solver": self.solver.value,
            "certified_gap": self.certified_gap,
            "gap_m": self.gap_m if self.gap_m is None or np.isfinite(self.gap_m) else None,
            "gap_diverged": self.gap_m is not None and not np.isfinite(self.gap_m),
            "inspection": inspection,
            "filters": {
                "kinematics_cutoff_Hz": self.system.filters.kinematics_cutoff_Hz,
                "equation_cutoff_Hz": self.system.filters.equation_cutoff_Hz,
                "noise_floor_m": self.system.filters.noise_floor_m,
            },
        }
        if m.roll_inertia_kg_m2 is not None:
            out["roll_inertia_kg_m2"] = m.roll_inertia_kg_m2
        if m.vehicle.is_axle:
            out["track_m"] = m.vehicle.track_m  # what `validate` needs to rebuild the axle's roll
        if self.refined_gap_m is not None:
            out["refined_gap_m"] = self.refined_gap_m
        out |= self.intervals_json()
        out["warnings"] = list(self.warnings)
        return out

    def effects_json(self) -> dict[str, object]:
        """{"effects": {...}} for a model that has effects beyond identify's form (a lab rig's frame guides'
        frictions, estimator.frame_guides), in the model file's keys, so `validate` simulates them; {}
        otherwise (every vehicle on a plate)."""
        m = self.model
        return {"effects": m.effects.to_json()} if isinstance(m, ModelWithEffects) and m.effects.names else {}

    def stiffness_json(self) -> dict[str, object]:
        """{spring, tyre, (anti_roll_bar,) identified: [names]} in N/m; ϑ is reported beside it."""
        v = self.model.vehicle
        out: dict[str, object] = {"spring": v.spring_stiffness_N_per_m, "tyre": v.tyre_stiffness_N_per_m}
        if v.is_axle:
            out["anti_roll_bar"] = v.anti_roll_bar_stiffness_N_per_m
        found = self.identified & set(STIFFNESS_NAMES)
        out["identified"] = [c.value for c in VehicleConstant if c in found]
        return out


STIFFNESS_JSON_KEYS = {
    "spring": "spring_stiffness_N_per_m",
    "tyre": "tyre_stiffness_N_per_m",
    "anti_roll_bar": "anti_roll_bar_stiffness_N_per_m",
}
"""The stiffness_N_per_m(_interval) key of each stiffness unknown."""
