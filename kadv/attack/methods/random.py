"""Random search: points drawn uniformly over the pose space (the bounds' two balls), a batch at a time."""

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
        space = self.context.space
        return space.sample(self.rng.uniform(size=(min(self.settings.population, count), space.dims)))
