"""Black-box search as ask/tell proposers, driven by one loop that owns the budget.

The loop evaluates the init view at step 0, then asks the proposer for a batch of pose
parameters, moves there through the step guard, renders, evaluates and records each view
(with its validity verdict), and tells the proposer the records, until the evaluation or
seconds budget ends. Proposers only propose.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
import torch
from tqdm import tqdm

from kadv.attack.records import InitViewResult, ViewRecord, incumbent_path
from kadv.attack.registry import NoSettings, register_method
from kadv.attack.search import SearchContext

__all__ = ["Proposer", "fitness", "proposer_search", "register_proposer"]


def fitness(records: list[ViewRecord]) -> np.ndarray:
    """Each view's objective, -inf for an invalid view or a non-finite value (to maximise)."""
    return np.array([r.objective if r.valid and math.isfinite(r.objective) else -math.inf for r in records])


class Proposer:
    """Proposes points of the pose space (:class:`~kadv.attack.space.PoseSpace`); the loop evaluates them.

    Args:
        context: the search context (``context.config`` holds the bounds, ``.settings`` the
            method's own settings).
        rng: the search's seeded generator; draw every random number from it.
    """

    def __init__(self, context: SearchContext, rng: np.random.Generator) -> None:
        self.context, self.config, self.settings, self.rng = context, context.config, context.config.settings, rng

    def ask(self, count: int) -> torch.Tensor:
        """At most ``count`` points (N, dims) float64 of the pose space to evaluate next (N = 0 ends the search)."""
        raise NotImplementedError

    def tell(self, records: list[ViewRecord]) -> None:
        """The records of the poses last asked for (possibly fewer, when the budget cut the batch)."""


def proposer_search(
    proposer_class: type[Proposer], context: SearchContext, rng: np.random.Generator, bar: tqdm
) -> InitViewResult:
    """Run a proposer from one init view within the context's budget."""
    proposer = proposer_class(context, rng)
    records = context.evaluate(0, context.space.zeros())
    step = 1
    while (left := context.clock.allows(context.clock.remaining())) > 0:
        params = proposer.ask(left)
        count = context.clock.allows(len(params))
        if count == 0:
            break
        rows = context.evaluate(step, params[:count])
        records += rows
        proposer.tell(rows)
        bar.set_postfix(loss=f"{max(r.loss for r in records if r.rankable or r is records[0]):.4f}", refresh=False)
        step += 1
    return context.result(records, incumbent_path(records))


def register_proposer(
    name: str, settings: type = NoSettings, check: Callable[..., None] | None = None
) -> Callable[[type], type]:
    """Class decorator: register an ask/tell :class:`Proposer` as method ``name``, driven by
    :func:`proposer_search` (``check``: as :func:`~kadv.attack.registry.register_method`'s)."""

    def decorate(proposer: type) -> type:
        register_method(name, settings, check=check, gradient=False)(functools.partial(proposer_search, proposer))
        return proposer

    return decorate
