"""What an identification is asked for (IdentifyOptions): the tyre model, the damper curve's points and
their limits, the solver (exact or differential evolution) and where DE searches, the output error, the
constants to identify although the vehicle file states them, and the confidence intervals."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import ClassVar

from estimator.errors import InvalidValueError
from estimator.solvers.differential_evolution import DESettings
from estimator.tanh_fit import MIN_POINTS as MIN_TANH_POINTS
from estimator.vehicle import TyreModel, VehicleConstant


class Solver(StrEnum):
    EXACT = "exact"
    DE = "de"


class Coordinates(StrEnum):
    """Where DE searches. DECORRELATED: θ = centre + W·z with W = L⁻ᵀ, L the Cholesky factor of AᵀA (the
    equations' own normal matrix, not their solution), so the unknowns the data ties together (sprung mass
    and every curve point) become independent and the paper's low crossover rate works. RAW: the
    paper's unknowns as they are (with F = 1, CR = 0.3 DE then stalls far from the optimum; see
    BENCHMARKS.md)."""

    DECORRELATED = "decorrelated"
    RAW = "raw"


@dataclass(frozen=True)
class IdentifyOptions:
    MIN_POINTS: ClassVar[int] = MIN_TANH_POINTS
    """The fewest damper curve points accepted: the tanh fit of the curve needs as many."""
    MAX_POINTS: ClassVar[int] = 60
    """The most damper curve points accepted: more resolve nothing the 1 kHz recording carries, and the
    convex solve grows with them. The CLI, the job options and the diagnosis take their limits from here."""

    tyre: TyreModel = TyreModel.MAXWELL
    points: int | None = None
    """Damper curve points; default 20 for a quarter car, 10 per side for an axle."""
    solver: Solver = Solver.EXACT
    nsample: int | None = 5000
    de: DESettings = field(default_factory=DESettings)
    de_coordinates: Coordinates = Coordinates.DECORRELATED
    output_error: bool = True
    refine_output_error: bool = False
    free: frozenset[VehicleConstant] = frozenset()
    """Constants to identify although the vehicle file states them (those it does not state always are)."""
    intervals: bool = True
    """95% confidence intervals (estimator.uncertainty): one more convex solve on a refined grid."""

    def __post_init__(self) -> None:
        check_curve_points(self.points)


def check_curve_points(points: int | None, field: str = "points") -> None:
    """InvalidValueError (naming `field`) unless `points` is None or within IdentifyOptions' limits."""
    low, high = IdentifyOptions.MIN_POINTS, IdentifyOptions.MAX_POINTS
    if points is not None and not low <= points <= high:
        raise InvalidValueError(
            f"{field} must lie between {low} (the tanh fit needs as many) and {high}, got {points}",
            field=field,
        )
