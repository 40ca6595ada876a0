"""Screen, then refine: a space-filling design over the bounds (optionally at a reduced size, its
best views re-scored at full size), then trust-region gradient steps from the best screened views
for the rest of the budget."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import qmc
from tqdm import tqdm

from kadv.attack.methods.lanes import LaneSettings, check_trust_region, trust_region_refine
from kadv.attack.records import InitViewResult, incumbent_path, select_top_views
from kadv.attack.registry import register_method
from kadv.attack.search import SearchContext

__all__ = ["HybridSettings", "hybrid_search"]

# Restart starts held per refined lane (each is re-scored at full size when screening ran smaller).
_POOL_PER_LANE = 3


@dataclass(frozen=True)
class HybridSettings:
    """``attack.hybrid``.

    Attributes:
        screen_fraction: share of the budget (model passes, or seconds) spent screening.
        screen_scale: screening renders and scores at this share of the run's height and width;
            below 1 its best separated views are re-scored at full size before refinement.
        population: screening views per evaluated batch (a power of two keeps Sobol points balanced).
        refine_views: trust-region lanes, batched, from the best separated valid screened views.
        lr_rotation, lr_translation, lr_fov_deg, grow, shrink, stall_scale: the lanes' steps
            (:class:`~kadv.attack.methods.lanes.LaneSettings`); a stalled lane restarts from the next
            best separated screened view.
    """

    screen_fraction: float = 0.5
    screen_scale: float = 0.5
    population: int = 8
    refine_views: int = 2
    lr_rotation: float = LaneSettings.lr_rotation
    lr_translation: float = LaneSettings.lr_translation
    lr_fov_deg: float = LaneSettings.lr_fov_deg
    grow: float = LaneSettings.grow
    shrink: float = LaneSettings.shrink
    stall_scale: float = LaneSettings.stall_scale

    def __post_init__(self) -> None:
        check_trust_region(self, "attack.hybrid", ("screen_scale", "shrink", "stall_scale"))

    def lanes(self) -> LaneSettings:
        """The refinement's lanes."""
        return LaneSettings(
            self.lr_rotation, self.lr_translation, self.lr_fov_deg, self.grow, self.shrink, self.stall_scale
        )


@register_method("hybrid", HybridSettings)
def hybrid_search(context: SearchContext, rng: np.random.Generator, bar: tqdm) -> InitViewResult:
    """Scrambled Sobol points spread over the bounds' balls, then trust-region ascent from the best.

    The path is the successive best rankable views (the incumbent never falls).
    """
    settings, clock, config = context.config.settings, context.clock, context.config
    screen_views = math.ceil(settings.screen_fraction * clock.passes) if clock.passes is not None else None
    screen_seconds = settings.screen_fraction * clock.seconds if clock.seconds is not None else None
    sobol = qmc.Sobol(d=context.space.dims, scramble=True, rng=rng)
    records = context.evaluate(0, context.space.zeros())
    step = 1
    while screen_views is None or clock.budget.passes < screen_views:
        if screen_seconds is not None and clock.elapsed() >= screen_seconds:
            break
        wanted = (
            settings.population
            if screen_views is None
            else min(settings.population, screen_views - clock.budget.passes)
        )
        count = clock.allows(wanted)
        if count == 0:
            break
        unit = sobol.random(settings.population)[:count]
        records += context.evaluate(step, context.space.sample(unit), scale=settings.screen_scale)
        step += 1
    candidates = select_top_views(
        [dataclasses.replace(r, scale=1.0) for r in records],  # rank the reduced-size views too
        settings.refine_views * (1 + _POOL_PER_LANE),
        config.min_separation,
        config.min_separation_deg,
    )
    if settings.screen_scale < 1.0 and candidates:
        # re-score at full size what screening ranked at a reduced one; the init view is already full size
        small = [r for r in candidates if r.step > 0]
        count = clock.allows(len(small))
        if count:
            params = torch.tensor([r.params for r in small[:count]], dtype=torch.float64)
            records += context.evaluate(step, params)
            step += 1
        candidates = select_top_views(
            [r for r in records if r.scale == 1.0], len(candidates), config.min_separation, config.min_separation_deg
        )
    starts, pool = candidates[: settings.refine_views], candidates[settings.refine_views :]
    if starts:
        records += trust_region_refine(context, starts, pool, settings.lanes(), bar, step)
    return context.result(records, incumbent_path(records))
