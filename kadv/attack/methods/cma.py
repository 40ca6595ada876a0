"""CMA-ES (the ``cma`` package, ask/tell) on the pose space scaled to its box [-1, 1]^dims."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from kadv.attack.loop import Proposer, fitness, register_proposer
from kadv.attack.records import ViewRecord

__all__ = ["CMAProposer", "CMASettings"]

# CMA-ES ranks candidates; an invalid view ranks below every valid one
_INVALID_FITNESS = 1e9


@dataclass(frozen=True)
class CMASettings:
    """``attack.cma``.

    Attributes:
        sigma: initial step size, as a fraction of the search box.
        population: candidates per generation (one evaluated batch).
        ipop: once the strategy stops (its step or its spread of values has collapsed), start it
            again from a uniform random mean with twice the population (IPOP-CMA-ES), for as
            long as the budget lasts; else it keeps sampling its collapsed distribution.
    """

    sigma: float = 0.3
    population: int = 8
    ipop: bool = False


@register_proposer("cma", CMASettings)
class CMAProposer(Proposer):
    """Minimises -objective; a generation cut short by the budget is not told (CMA-ES needs whole ones)."""

    def __init__(self, context, rng: np.random.Generator) -> None:
        super().__init__(context, rng)
        self.strategy = self._start(np.zeros(context.space.dims), self.settings.population)
        self.candidates: list[np.ndarray] = []

    def _start(self, mean: np.ndarray, population: int):
        import cma  # here, not at the top: only a CMA-ES search needs it

        options = {
            "seed": int(self.rng.integers(1, 2**31 - 1)),
            "popsize": population,
            "bounds": [-1.0, 1.0],
            "verbose": -9,
            "CMA_stds": None,
        }
        return cma.CMAEvolutionStrategy(mean, self.settings.sigma, options)

    def ask(self, count: int) -> torch.Tensor:
        if self.settings.ipop and self.strategy.stop():
            self.strategy = self._start(self.rng.uniform(-1.0, 1.0, self.context.space.dims), 2 * self.strategy.popsize)
        self.candidates = self.strategy.ask()
        return self.context.space.from_box(torch.from_numpy(np.asarray(self.candidates)))

    def tell(self, records: list[ViewRecord]) -> None:
        if len(records) == len(self.candidates):
            self.strategy.tell(self.candidates, [-v if np.isfinite(v) else _INVALID_FITNESS for v in fitness(records)])
