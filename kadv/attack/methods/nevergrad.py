"""Any optimizer of the ``nevergrad`` package (NGOpt by default), through its ask/tell interface."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from kadv.attack.loop import Proposer, fitness, register_proposer
from kadv.attack.records import ViewRecord

__all__ = ["NevergradProposer", "NevergradSettings"]

# nevergrad minimises; an invalid view gets a loss worse than any valid one
_INVALID_LOSS = 1e9


@dataclass(frozen=True)
class NevergradSettings:
    """``attack.nevergrad``.

    Attributes:
        optimizer: a name in ``nevergrad.optimizers.registry`` (NGOpt picks one by budget and dimension).
        population: candidates asked for per evaluated batch (nevergrad's ``num_workers``).
    """

    optimizer: str = "NGOpt"
    population: int = 8

    def __post_init__(self) -> None:
        import nevergrad as ng  # here, not at the top: it takes most of a second to import

        if self.optimizer not in ng.optimizers.registry:
            some = ", ".join(
                n for n in ("NGOpt", "TwoPointsDE", "PSO", "OnePlusOne", "DE", "CMA") if n in ng.optimizers.registry
            )
            raise ValueError(
                f"attack.nevergrad.optimizer={self.optimizer!r} is not a nevergrad optimizer; "
                f"valid names include {some} (nevergrad.optimizers.registry lists all)"
            )


def _metamodel_type_errors_as_failures() -> None:
    """nevergrad 1.0.12's meta-model turns the model's prediction, shaped (1,), into a float, which
    numpy 2.4 refuses with a TypeError (nevergrad issue 1612): NGOpt then crashes once a long enough
    search picks a meta-model optimizer. Report that TypeError as the ``MetaModelFailure`` the
    optimizers already recover from (they go on without the meta-model's proposal)."""
    from nevergrad.optimization import metamodel, optimizerlib

    learn = optimizerlib.learn_on_k_best
    if getattr(learn, "kadv_guarded", False):
        return

    def guarded(*args, **kwargs):
        try:
            return learn(*args, **kwargs)
        except TypeError as error:
            raise metamodel.MetaModelFailure(f"nevergrad's meta-model under this numpy: {error}") from error

    guarded.kadv_guarded = True
    optimizerlib.learn_on_k_best = guarded  # the optimizers call it through optimizerlib's name


@register_proposer("nevergrad", NevergradSettings)
class NevergradProposer(Proposer):
    """Minimises -objective over the pose space's box [-1, 1]^dims, seeded from the search's generator."""

    def __init__(self, context, rng: np.random.Generator) -> None:
        import nevergrad as ng

        _metamodel_type_errors_as_failures()
        super().__init__(context, rng)
        parametrization = ng.p.Array(shape=(context.space.dims,), lower=-1.0, upper=1.0)
        parametrization.random_state = np.random.RandomState(int(rng.integers(1, 2**31 - 1)))
        # the pass budget when there is one; else a count that a seconds budget rarely exceeds
        budget = context.clock.remaining() if context.clock.passes is not None else 1000
        self.optimizer = ng.optimizers.registry[self.settings.optimizer](
            parametrization=parametrization, budget=max(budget, 1), num_workers=self.settings.population
        )
        self.candidates: list = []

    def ask(self, count: int) -> torch.Tensor:
        self.candidates = [self.optimizer.ask() for _ in range(min(self.settings.population, count))]
        unit = np.stack([c.value for c in self.candidates])
        return self.context.space.from_box(torch.from_numpy(unit))

    def tell(self, records: list[ViewRecord]) -> None:
        for candidate, value in zip(self.candidates, fitness(records)):
            self.optimizer.tell(candidate, -value if np.isfinite(value) else _INVALID_LOSS)
