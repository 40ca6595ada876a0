"""Random search: poses drawn uniformly over the bounds' two balls, a batch at a time."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from kadv.attack.loop import Proposer, register_proposer

__all__ = ["RandomProposer", "RandomSettings"]


@dataclass(frozen=True)
class RandomSettings:
    """``attack.random``.

    Attributes:
        population: views per evaluated batch.
    """

    population: int = 8


@register_proposer("random", RandomSettings)
class RandomProposer(Proposer):
    def ask(self, count: int) -> torch.Tensor:
        return self.config.sample_ball(self.rng.uniform(size=(min(self.settings.population, count), 6)))
