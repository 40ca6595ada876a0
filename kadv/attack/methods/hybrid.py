"""Screen, then refine: a space-filling design over the bounds, then batched gradient ascent from
the best screened views for the rest of the budget."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import qmc
from tqdm import tqdm

from kadv.attack.methods.gradient import best_lane, gradient_ascent
from kadv.attack.records import InitViewResult, incumbent_path, select_top_views
from kadv.attack.registry import register_method
from kadv.attack.search import SearchContext

__all__ = ["HybridSettings", "hybrid_search"]


@dataclass(frozen=True)
class HybridSettings:
    """``attack.hybrid``.

    Attributes:
        screen_fraction: share of the budget (evaluations, or seconds) spent screening.
        population: screening views per evaluated batch (a power of two keeps Sobol points balanced).
        refine_views: gradient runs, batched, from the best separated valid screened views.
        lr_rotation, lr_translation: their Adam learning rates (radians, metres).
    """

    screen_fraction: float = 0.5
    population: int = 8
    refine_views: int = 2
    lr_rotation: float = 0.02
    lr_translation: float = 0.03


@register_method("hybrid", HybridSettings)
def hybrid_search(context: SearchContext, rng: np.random.Generator, bar: tqdm) -> InitViewResult:
    """Scrambled Sobol points spread over the bounds' balls, then gradient ascent from the best.

    The path is the screening's successive best views, then the best refined run.
    """
    settings, clock, config = context.config.settings, context.clock, context.config
    screen_views = math.ceil(settings.screen_fraction * clock.evaluations) if clock.evaluations is not None else None
    screen_seconds = settings.screen_fraction * clock.seconds if clock.seconds is not None else None
    sobol = qmc.Sobol(d=6, scramble=True, rng=rng)
    records = context.evaluate(0, torch.zeros(1, 6, dtype=torch.float64))
    bar.update(1)
    step = 1
    while screen_views is None or clock.budget.forward < screen_views:
        if screen_seconds is not None and clock.elapsed() >= screen_seconds:
            break
        wanted = (
            settings.population
            if screen_views is None
            else min(settings.population, screen_views - clock.budget.forward)
        )
        count = clock.allows(wanted)
        if count == 0:
            break
        records += context.evaluate(step, config.sample_ball(sobol.random(settings.population)[:count]))
        bar.update(count)
        step += 1
    screened = list(records)
    starts = select_top_views(screened, settings.refine_views, config.min_separation, config.min_separation_deg)
    if starts:
        start = torch.tensor([r.params for r in starts], dtype=torch.float64)
        records += gradient_ascent(
            context, start, 2**31, settings.lr_rotation, settings.lr_translation, bar, first_step=step
        )
    refined = records[len(screened) :]
    return context.result(records, incumbent_path(screened) + (best_lane(refined) if refined else []))
