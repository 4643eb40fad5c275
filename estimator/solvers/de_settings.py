"""Differential evolution's settings (DE/rand/1/bin as the paper uses it), declared once with their bounds
and help (estimator.declared): the solver (estimator.solvers.differential_evolution) runs them, and the
API's identification options and `shockbench identify`'s --generations and --seed derive theirs from them.
A module of its own, without numpy, so that the CLI's parser can read the declarations without loading
the solver."""

from __future__ import annotations

from dataclasses import dataclass

from estimator.declared import setting
from estimator.errors import InvalidValueError

MAX_GENERATIONS = 200_000
"""Most generations a user may ask for (a 3000-generation run takes about a minute)."""
MAX_SEED = 2**31 - 1


@dataclass(frozen=True)
class DESettings:
    """Every setting of the run; defaults are the paper's Table 1.

    mutation_probability (MP) is read as described in estimator.solvers.differential_evolution's
    docstring; relative_tolerance stops early when the population's objective spread falls below this
    fraction of its mean (0: never)."""

    mutation_factor: float = setting(1.0, "F, the paper's disturbance factor", gt=0, le=2)
    crossover_probability: float = setting(0.3, "CR (CP in Table 1)", ge=0, le=1)
    mutation_probability: float = setting(0.1, "MP, one gene redrawn in its bounds", ge=0, le=1)
    population_size: int = setting(70, "NP, individuals per generation", ge=4)
    generations: int = setting(3000, "DE generations", ge=1, le=MAX_GENERATIONS)
    seed: int | None = setting(0, "DE seed", ge=0, le=MAX_SEED)
    relative_tolerance: float = setting(0.0, "stop when the objective spread is below this of its mean", ge=0)

    def __post_init__(self) -> None:
        if self.population_size < 4:
            raise InvalidValueError("DE/rand/1 needs a population of at least 4")
        if not 0.0 <= self.crossover_probability <= 1.0 or not 0.0 <= self.mutation_probability <= 1.0:
            raise InvalidValueError("probabilities must lie in [0, 1]")
        if self.generations < 1:
            raise InvalidValueError("generations must be >= 1")
