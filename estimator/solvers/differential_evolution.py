"""Differential evolution as the paper uses it: DE/rand/1/bin with F = 1, CR = 0.3, NP = 70, 3000
generations, evaluated for the whole population at once (one array expression per generation, no Python
loop over individuals).

The paper also lists a "mutation probability 0.1" besides F and CR. DE has no separate mutation step, so we
read it as the GA-style mutation of the authors' earlier evolutionary work: after crossover, each trial
vector is, with probability `mutation_probability`, given one gene (chosen at random) drawn uniformly within
that gene's bounds. It keeps diversity; greedy selection throws away the trials it spoils. Set it to 0 for
plain DE.

Other choices, as scipy.optimize.differential_evolution makes them: trial genes that leave the bounds are
re-drawn uniformly inside them; selection keeps the trial when it is at least as good; the whole
generation's trials are made from the previous generation (scipy's "deferred" updating).

The settings (DESettings, re-exported here) are declared in estimator.solvers.de_settings, without numpy.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from estimator.solvers.de_settings import DESettings

__all__ = ["DEProgress", "DEResult", "DESettings", "DifferentialEvolution", "sorted_columns"]


@dataclass(frozen=True)
class DEProgress:
    """Sent to the callback after every generation."""

    generation: int
    generations: int
    best_objective: float
    evaluations: int


@dataclass
class DEResult:
    theta: np.ndarray
    objective: float
    generations: int
    evaluations: int
    cancelled: bool
    history: list[float] = field(default_factory=list)
    """Best objective after each generation."""


DEFAULT_SETTINGS = DESettings()
"""The paper's Table 1."""

PopulationObjective = Callable[[np.ndarray], np.ndarray]
"""Maps a population (P, p) to objective values (P,)."""


class DifferentialEvolution:
    """A seeded, cancellable DE/rand/1/bin run over box bounds.

    objective: evaluates a whole population at once. bounds: shape (p, 2), low and high per gene.
    callback(progress) is called after every generation; returning True stops the run (like scipy's).
    cancel: an Event that, once set, stops the run after the current generation.
    """

    def __init__(
        self,
        objective: PopulationObjective,
        bounds: np.ndarray,
        settings: DESettings = DEFAULT_SETTINGS,
        callback: Callable[[DEProgress], bool | None] | None = None,
        cancel: threading.Event | None = None,
        initial: np.ndarray | None = None,
    ) -> None:
        self.objective = objective
        self.bounds = np.asarray(bounds, dtype=float)
        if (
            self.bounds.ndim != 2
            or self.bounds.shape[1] != 2
            or np.any(self.bounds[:, 1] <= self.bounds[:, 0])
        ):
            raise ValueError("bounds must have shape (p, 2) with low < high")
        self.settings = settings
        self.callback = callback
        self.cancel = cancel or threading.Event()
        self.rng = np.random.default_rng(settings.seed)
        self.initial = initial

    def _uniform(self, shape: tuple[int, ...]) -> np.ndarray:
        low, high = self.bounds[:, 0], self.bounds[:, 1]
        return low + self.rng.random(shape) * (high - low)

    def _parents(self, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Three distinct indices per target, all different from the target itself."""
        idx = np.empty((size, 3), dtype=int)
        for col in range(3):
            idx[:, col] = self.rng.integers(0, size - 1 - col, size)
        # map draws onto the indices not yet used (target and earlier picks), keeping them distinct
        targets = np.arange(size)
        used = [targets]
        for col in range(3):
            draw = idx[:, col]
            for taken in sorted_columns(used):
                draw = draw + (draw >= taken)
            idx[:, col] = draw
            used.append(draw)
        return idx[:, 0], idx[:, 1], idx[:, 2]

    def solve(self) -> DEResult:
        s = self.settings
        size, dims = s.population_size, self.bounds.shape[0]
        population = self._uniform((size, dims))
        if self.initial is not None:
            population[0] = np.clip(self.initial, self.bounds[:, 0], self.bounds[:, 1])
        scores = np.asarray(self.objective(population), dtype=float)
        evaluations = size
        history: list[float] = []
        cancelled = False
        generation = 0
        low, high = self.bounds[:, 0], self.bounds[:, 1]
        for generation in range(1, s.generations + 1):
            r1, r2, r3 = self._parents(size)
            mutant = population[r1] + s.mutation_factor * (population[r2] - population[r3])
            cross = self.rng.random((size, dims)) < s.crossover_probability
            cross[np.arange(size), self.rng.integers(0, dims, size)] = True
            trial = np.where(cross, mutant, population)
            if s.mutation_probability > 0:
                mutated = np.nonzero(self.rng.random(size) < s.mutation_probability)[0]
                genes = self.rng.integers(0, dims, mutated.size)
                trial[mutated, genes] = low[genes] + self.rng.random(mutated.size) * (
                    high[genes] - low[genes]
                )
            outside = (trial < low) | (trial > high)
            if outside.any():
                trial = np.where(outside, self._uniform((size, dims)), trial)
            trial_scores = np.asarray(self.objective(trial), dtype=float)
            evaluations += size
            better = trial_scores <= scores
            population[better] = trial[better]
            scores[better] = trial_scores[better]
            best = float(scores.min())
            history.append(best)
            stop = False
            if self.callback is not None:
                stop = bool(self.callback(DEProgress(generation, s.generations, best, evaluations)))
            if self.cancel.is_set():
                cancelled = True
                break
            if stop:
                break
            if s.relative_tolerance > 0 and np.std(scores) <= s.relative_tolerance * abs(np.mean(scores)):
                break
        best_index = int(np.argmin(scores))
        return DEResult(
            population[best_index].copy(),
            float(scores[best_index]),
            generation,
            evaluations,
            cancelled,
            history,
        )


def sorted_columns(columns: list[np.ndarray]) -> list[np.ndarray]:
    """Per row, the already-taken indices in increasing order (so that shifting a draw past each taken
    index in turn yields a uniformly chosen index among the free ones)."""
    stacked = np.sort(np.stack(columns, axis=1), axis=1)
    return [stacked[:, k] for k in range(stacked.shape[1])]
