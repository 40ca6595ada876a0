"""Successive halving: many poses scored at a cheap fidelity, the best re-scored exactly, then
trust-region lanes from the best exact views, each step screened cheaply or taken along the gradient.

The cheap fidelity is the exact ray cast with fewer rays per pixel (one instead of the run's 2 x 2):
on the CPU it costs a third of an exact evaluation and ranks views as the exact render does
(Spearman 0.84-1.00 on the probes), where the reprojection of anchor layers costs as much as the
exact render and ranks them worse once the camera turns far (docs/attack.md measures both). Only
exact evaluations count against ``attack.budget_evaluations``; screened views are counted apart
(``budget.screened``) and paid for in seconds.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import qmc
from tqdm import tqdm

from kadv.attack.methods.hybrid import HybridSettings, check_trust_region, trust_region_refine
from kadv.attack.records import InitViewResult, ViewRecord, incumbent_path, select_top_views
from kadv.attack.registry import register_method
from kadv.attack.search import SearchContext

__all__ = ["HalvingSettings", "check_budget", "halving_search", "local_refine"]


@dataclass(frozen=True)
class HalvingSettings:
    """``attack.halving``.

    Attributes:
        screen_factor: views screened over the bounds per evaluation of the budget (under a seconds
            budget alone: per view of a screening batch).
        screen_supersample: rays per pixel side of the cheap fidelity; below the run's
            ``render.supersample``.
        batch: views per screening render.
        rescore_fraction: share of the evaluation budget that re-scores the best separated
            screened views (and the warm starts) exactly.
        refine: how the lanes step: ``gradient`` (along the normalised gradient through the
            differentiable renderer, :func:`~kadv.attack.methods.hybrid.trust_region_refine`) or
            ``local`` (``local_views`` poses drawn around the lane's incumbent within its trust
            region, screened, the best re-scored exactly).
        lanes: trust-region lanes, from the best separated exact views.
        local_views: poses screened per lane and step with ``refine=local``.
        step_fraction: a ``local`` lane's first trust region, as a share of the bounds (rotation
            angle, distance).
        grow, shrink: a step that raises the lane's objective multiplies its trust region (or its
            gradient step) by ``grow``; one that does not, by ``shrink``.
        stall_scale: a lane whose trust region shrank below this share of the first restarts from
            the next best separated exact view.
    """

    screen_factor: float = 2.0
    screen_supersample: int = 1
    batch: int = 32
    rescore_fraction: float = 0.25
    refine: str = "gradient"
    lanes: int = 2
    local_views: int = 8
    step_fraction: float = 0.1
    grow: float = 1.5
    shrink: float = 0.5
    stall_scale: float = 0.1

    def __post_init__(self) -> None:
        if self.refine not in ("gradient", "local"):
            raise ValueError(f"attack.halving.refine must be 'gradient' or 'local', got {self.refine!r}")
        check_trust_region(self, "attack.halving", ("step_fraction", "shrink", "stall_scale"))
        if not (math.isfinite(self.screen_factor) and self.screen_factor >= 0.0):
            raise ValueError(f"attack.halving.screen_factor must be >= 0, got {self.screen_factor}")

    def gradient_lanes(self) -> HybridSettings:
        """The gradient lanes' settings (their first step lengths are hybrid's)."""
        return HybridSettings(refine_views=self.lanes, grow=self.grow, shrink=self.shrink, stall_scale=self.stall_scale)


def _rescore_count(settings: HalvingSettings, evaluations: int | None) -> int:
    """Exact evaluations that re-score screened views: a share of the budget, at least one per lane."""
    if evaluations is None:
        return max(settings.lanes, settings.batch // 4)
    return max(settings.lanes, math.ceil(settings.rescore_fraction * evaluations))


def check_budget(settings: HalvingSettings, evaluations: int | None, supersample: int | None = None) -> None:
    """Refuse, naming the key, a budget without room for the init view, the re-scoring and one step
    of each lane, and a screening fidelity not cheaper than the run's ``supersample`` rays per
    pixel side."""
    if supersample is not None and settings.screen_supersample >= supersample:
        raise ValueError(
            f"attack.halving.screen_supersample must be below render.supersample ({supersample}) to be a cheap "
            f"fidelity, got {settings.screen_supersample}"
        )
    if evaluations is not None:
        rescore = _rescore_count(settings, evaluations)
        needed = 1 + rescore + settings.lanes
        if evaluations < needed:
            raise ValueError(
                f"attack.budget_evaluations must be at least {needed} for attack.halving (the init view, "
                f"{rescore} re-scored screened views and a step of each of "
                f"{settings.lanes} lanes), got {evaluations}"
            )


def local_refine(
    context: SearchContext,
    starts: list[ViewRecord],
    pool: list[ViewRecord],
    settings: HalvingSettings,
    rng: np.random.Generator,
    bar: tqdm,
    first_step: int,
) -> list[ViewRecord]:
    """Trust-region lanes without the gradient: each step screens ``local_views`` poses drawn
    around each lane's incumbent (a normal draw scaled by the trust region, a share of the bounds)
    and re-scores the best of each lane exactly; it becomes the incumbent if it raises the lane's
    objective (the region grows), else the region shrinks. A lane whose region shrank below
    ``stall_scale`` restarts from the next view of ``pool``. Its records, screened ones included."""
    clock = context.clock
    lanes = clock.allows(len(starts))
    if lanes == 0:
        return []
    pool = list(pool)
    half = context.config.search_box().numpy()
    current = np.array([r.params for r in starts[:lanes]])
    best = np.array([r.objective for r in starts[:lanes]])
    region = np.ones(lanes)
    records: list[ViewRecord] = []
    step = first_step
    while clock.allows(lanes) == lanes:
        draws = rng.normal(size=(lanes, settings.local_views, 6)) * (settings.step_fraction * region)[:, None, None]
        proposals = torch.from_numpy((current[:, None, :] + draws * half).reshape(-1, 6))
        screened = context.screen(step, proposals, settings.screen_supersample, settings.batch)
        records += screened
        if len(screened) < len(proposals):
            break
        picks = []
        for lane in range(lanes):
            rows = screened[lane * settings.local_views : (lane + 1) * settings.local_views]
            picks.append(max(rows, key=lambda r: r.objective if r.valid else -math.inf).params)
        exact = context.evaluate(step + 1, torch.tensor(picks, dtype=torch.float64), lanes=range(lanes))
        records += exact
        for lane, record in enumerate(exact):
            if record.rankable and record.objective > best[lane]:
                current[lane], best[lane] = record.params, record.objective
                region[lane] = min(region[lane] * settings.grow, 1.0 / settings.step_fraction)
            else:
                region[lane] *= settings.shrink
            if region[lane] < settings.stall_scale:
                region[lane] = 1.0
                if pool:
                    restart = pool.pop(0)
                    current[lane], best[lane] = restart.params, restart.objective
        bar.update(lanes)
        step += 2
    return records


@register_method("halving", HalvingSettings, check=check_budget)
def halving_search(context: SearchContext, rng: np.random.Generator, bar: tqdm) -> InitViewResult:
    """The init view and the warm starts exactly; scrambled Sobol points over the bounds' balls at
    the cheap fidelity; the best separated screened views re-scored exactly; then trust-region
    lanes from the best separated exact views for the rest of the budget.

    The path is the successive best rankable views (the incumbent never falls).
    """
    settings, clock, config = context.config.settings, context.clock, context.config
    records = context.evaluate(0, torch.zeros(1, 6, dtype=torch.float64))
    bar.update(1)
    warm = clock.allows(len(context.starts))
    if warm:
        records += context.evaluate(1, context.starts[:warm])
    rescore = _rescore_count(settings, clock.evaluations)
    screen_views = round(settings.screen_factor * (clock.evaluations or settings.batch))
    screened: list[ViewRecord] = []
    if screen_views:
        unit = qmc.Sobol(d=6, scramble=True, rng=rng).random_base2(math.ceil(math.log2(screen_views)))[:screen_views]
        screened = context.screen(2, config.sample_ball(unit), settings.screen_supersample, settings.batch, bar)
        records += screened
    best = select_top_views(
        [dataclasses.replace(r, screened=False) for r in screened],  # rank the screened views among themselves
        rescore,
        config.min_separation,
        config.min_separation_deg,
    )
    count = clock.allows(len(best))
    if count:
        records += context.evaluate(3, torch.tensor([r.params for r in best[:count]], dtype=torch.float64))
        bar.update(count)
    candidates = select_top_views(records, settings.lanes * 4, config.min_separation, config.min_separation_deg)
    starts, pool = candidates[: settings.lanes], candidates[settings.lanes :]
    if starts:
        if settings.refine == "gradient":
            records += trust_region_refine(context, starts, pool, settings.gradient_lanes(), bar, 4)
        else:
            records += local_refine(context, starts, pool, settings, rng, bar, 4)
    return context.result(records, incumbent_path(records))
