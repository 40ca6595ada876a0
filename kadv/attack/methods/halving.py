"""Successive halving: many poses scored at a cheap fidelity, the best re-scored exactly, then
trust-region lanes from the best exact views, each step drawn around the lane's incumbent or
taken along the gradient (at the screening's fidelity: the exact render validates what a lane takes).

Every image the model runs on is a model pass of ``attack.budget_passes``, screened or exact, and
so is every backward pass. The cheap fidelity (fewer rays per pixel) saves render time, not model
passes: it pays only where seconds are the budget and the render costs more than the model (a small
model on a CPU). ``screen_supersample: auto`` (the default) screens exactly under a pass budget and
chooses by the init view's measured render and model seconds under a seconds budget; the choice
has the lowest held-out regret in each regime (docs/attack.md#the-worst-case-as-a-measurement).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from kadv.attack.methods.lanes import LaneSettings, check_trust_region, trust_region_refine
from kadv.attack.records import InitViewResult, ViewRecord, incumbent_path, select_top_views
from kadv.attack.registry import register_method
from kadv.attack.search import SearchContext

__all__ = ["AUTO", "HalvingSettings", "check_budget", "halving_search", "local_refine", "screen_fidelity"]

AUTO = "auto"  # attack.halving.screen_supersample chosen per init view (screen_fidelity)


@dataclass(frozen=True)
class HalvingSettings:
    """``attack.halving``.

    Attributes:
        screen_fraction: share of the budget's passes that scores Sobol poses over the bounds
            (under a seconds budget alone: ``batch`` poses).
        screen_supersample: rays per pixel side of the cheap fidelity, below the run's
            ``render.supersample``; None: the screening scores exactly (and nothing is re-scored);
            ``auto``: :func:`screen_fidelity` chooses per init view.
        batch: views per screening render.
        rescore_fraction: share of the budget that re-scores the best separated screened views
            exactly (a cheap fidelity only).
        refine: how the lanes step: ``gradient`` (along the normalised gradient through the
            differentiable renderer, :func:`~kadv.attack.methods.lanes.trust_region_refine`; a
            forward and a backward pass per lane, at the screening's fidelity, a trial it would
            take re-scored exactly first when that is cheap) or ``local`` (``local_views`` poses
            drawn around the lane's incumbent within its trust region and screened, the best
            re-scored exactly).
        lanes: trust-region lanes, from the best separated exact views.
        local_views: poses screened per lane and step with ``refine=local``.
        step_fraction: a ``local`` lane's first trust region, as a share of the bounds (rotation
            angle, distance).
        grow, shrink: a step that raises the lane's objective multiplies its trust region (or its
            gradient step) by ``grow``; one that does not, by ``shrink``.
        stall_scale: a lane whose trust region shrank below this share of the first restarts from
            the next best separated exact view.
        halve_every: with ``refine=local``, every this many steps the lanes whose objective is in the
            lower half stop, and their passes go to the others, down to one lane (successive
            halving of the lanes); 0: every lane runs to the end.
    """

    screen_fraction: float = 0.5
    screen_supersample: int | str | None = AUTO
    batch: int = 32
    rescore_fraction: float = 0.25
    refine: str = "local"
    lanes: int = 2
    local_views: int = 8
    step_fraction: float = 0.1
    grow: float = 1.5
    shrink: float = 0.5
    stall_scale: float = 0.1
    halve_every: int = 0

    def __post_init__(self) -> None:
        if self.refine not in ("gradient", "local"):
            raise ValueError(f"attack.halving.refine must be 'gradient' or 'local', got {self.refine!r}")
        if self.halve_every and self.refine != "local":
            raise ValueError(f"attack.halving.halve_every applies to refine=local, got refine={self.refine!r}")
        check_trust_region(self, "attack.halving", ("screen_fraction", "step_fraction", "shrink", "stall_scale"))
        value = self.screen_supersample
        if value not in (None, AUTO) and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            raise ValueError(
                f"attack.halving.screen_supersample must be 'auto', an integer >= 1 or null, got {value!r}"
            )

    @property
    def cheap(self) -> bool:
        """Whether the screening scores at a cheap fidelity (its best are then re-scored exactly);
        ``auto`` counts as exact, what it is under a pass budget alone."""
        return isinstance(self.screen_supersample, int)

    def gradient_lanes(self) -> LaneSettings:
        """The gradient lanes' settings (their first step lengths are the lanes' defaults)."""
        return LaneSettings(grow=self.grow, shrink=self.shrink, stall_scale=self.stall_scale)


def _rescore_count(settings: HalvingSettings, passes: int | None) -> int:
    """Exact evaluations that re-score screened views: a share of the budget, at least one per
    lane (none when the screening is exact)."""
    if not settings.cheap:
        return 0
    if passes is None:
        return max(settings.lanes, settings.batch // 4)
    return max(settings.lanes, math.ceil(settings.rescore_fraction * passes))


def _lane_step(settings: HalvingSettings) -> int:
    """The passes of one lane's step: a forward and a backward pass along the gradient, the draws
    without it, and at a cheap fidelity the exact re-scoring of what the lane takes."""
    return (2 if settings.refine == "gradient" else settings.local_views) + settings.cheap


def check_budget(settings: HalvingSettings, passes: int | None, supersample: int | None = None) -> None:
    """Refuse, naming the key, a budget without room for the init view and the re-scoring, and a
    screening fidelity not cheaper than the run's ``supersample`` rays per pixel side. (A budget
    with no room left for the lanes ends after the re-scoring.)"""
    if (
        supersample is not None
        and isinstance(settings.screen_supersample, int)
        and settings.screen_supersample >= supersample
    ):
        raise ValueError(
            f"attack.halving.screen_supersample must be below render.supersample ({supersample}) to be a cheap "
            f"fidelity (null: screen exactly), got {settings.screen_supersample}"
        )
    if passes is not None:
        rescore = _rescore_count(settings, passes)
        needed = 1 + max(rescore, 1)
        if passes < needed:
            # "screened": at the cheap fidelity, as the budget counts them; an exact screening scores its views
            rest = f"{rescore} screened views re-scored" if rescore else "1 view of its screening"
            raise ValueError(
                f"attack.budget_passes must be at least {needed} for attack.halving (the init view and {rest}), "
                f"got {passes}"
            )


def screen_fidelity(
    settings: HalvingSettings, supersample: int, seconds: float | None, render_s: float, model_s: float
) -> int | None:
    """The screening's rays per pixel side (None: exact) for ``attack.halving.screen_supersample``.

    ``auto``: exact under a pass budget alone, where a cheap view costs a pass as an exact one does
    and its best must be scored again; under ``budget_seconds``, one ray per pixel when the run's
    exact render of a view (``render_s`` seconds, ``supersample`` rays per pixel side) takes longer
    than the model's pass on it (``model_s``), the render-bound case where cheap views buy more
    views a second; exact otherwise. Any other setting is kept.
    """
    if settings.screen_supersample != AUTO:
        return settings.screen_supersample
    return 1 if seconds is not None and supersample > 1 and render_s > model_s else None


def _move_lanes(
    picks: list[ViewRecord],
    current: np.ndarray,
    best: np.ndarray,
    region: np.ndarray,
    pool: list[ViewRecord],
    settings: HalvingSettings,
) -> None:
    """Each lane's step, in place: its pick becomes the incumbent and its region grows where it
    raises the lane's objective, else the region shrinks; a lane whose region shrank below
    ``stall_scale`` restarts from the next view of ``pool``."""
    for lane, record in enumerate(picks):
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


def local_refine(
    context: SearchContext,
    starts: list[ViewRecord],
    pool: list[ViewRecord],
    settings: HalvingSettings,
    rng: np.random.Generator,
    first_step: int,
) -> list[ViewRecord]:
    """Trust-region lanes without the gradient: each step scores ``local_views`` poses drawn
    around each lane's incumbent (a normal draw scaled by the trust region, a share of the bounds)
    at the screening's fidelity, and re-scores the best of each lane exactly when that is cheap;
    the lane's best becomes the incumbent if it raises the lane's objective (the region grows),
    else the region shrinks. A lane whose region shrank below ``stall_scale`` restarts from the
    next view of ``pool``. Every ``halve_every`` steps (when set) the lanes in the lower half by
    objective stop. Its records, screened ones included."""
    clock = context.clock
    if clock.remaining() < 1 + settings.cheap:
        return []
    lanes = max(1, clock.allows(len(starts), _lane_step(settings)))
    pool = list(pool)
    half = context.space.box()[1].numpy()
    dims = context.space.dims
    current = np.array([r.params for r in starts[:lanes]])
    best = np.array([r.objective for r in starts[:lanes]])
    region = np.ones(lanes)
    records: list[ViewRecord] = []
    step = first_step
    while True:
        # every lane while whole steps fit; then the first lanes; then the first lane's last, fewer draws
        views, active = settings.local_views, clock.allows(lanes, _lane_step(settings))
        if active == 0:
            views, active = min(settings.local_views, clock.remaining() - settings.cheap), 1
            if views < 1 or clock.allows(1) == 0:
                break
        draws = rng.normal(size=(active, views, dims)) * (settings.step_fraction * region[:active])[:, None, None]
        proposals = torch.from_numpy((current[:active, None, :] + draws * half).reshape(-1, dims))
        screened = context.screen(step, proposals, settings.screen_supersample, settings.batch)
        records += screened
        if len(screened) < len(proposals):
            break
        picks = []
        for lane in range(active):
            rows = screened[lane * views : (lane + 1) * views]
            picks.append(max(rows, key=lambda r: r.objective if r.valid else -math.inf))
        if settings.cheap:
            params = torch.tensor([r.params for r in picks], dtype=torch.float64)
            picks = context.evaluate(step + 1, params, lanes=range(active))
            records += picks
        _move_lanes(picks, current, best, region, pool, settings)
        step += 2
        if settings.halve_every and ((step - first_step) // 2) % settings.halve_every == 0 and lanes > 1:
            kept = np.argsort(-best, kind="stable")[: lanes // 2]
            current, best, region, lanes = current[kept], best[kept], region[kept], len(kept)
    return records


@register_method("halving", HalvingSettings, check=check_budget)
def halving_search(context: SearchContext, rng: np.random.Generator, bar: tqdm) -> InitViewResult:
    """The init view and the warm starts exactly; scrambled Sobol points over the bounds' balls at
    the screening's fidelity; the best separated screened views re-scored exactly (when it is
    cheap); then trust-region lanes from the best separated exact views for the rest of the budget.

    The path is the successive best rankable views (the incumbent never falls).
    """
    clock, config = context.clock, context.config
    records = context.evaluate(0, context.space.zeros(), timed=True)
    run_supersample = context.differentiable.config.supersample
    fidelity = screen_fidelity(config.settings, run_supersample, clock.seconds, clock.render_s, clock.model_s)
    settings = dataclasses.replace(config.settings, screen_supersample=fidelity)
    warm = clock.allows(len(context.starts))
    if warm:
        records += context.evaluate(1, context.starts[:warm])
    rescore = _rescore_count(settings, clock.passes)
    screen_views = round(settings.screen_fraction * clock.passes) if clock.passes is not None else settings.batch
    screened: list[ViewRecord] = []
    if screen_views:
        poses = context.space.sobol(screen_views, rng)
        screened = context.screen(2, poses, settings.screen_supersample, settings.batch, bar)
        records += screened
    if rescore:
        best = select_top_views(
            [dataclasses.replace(r, screened=False) for r in screened],  # rank the screened views among themselves
            rescore,
            config.min_separation,
            config.min_separation_deg,
        )
        count = clock.allows(len(best))
        if count:
            records += context.evaluate(3, torch.tensor([r.params for r in best[:count]], dtype=torch.float64))
    candidates = select_top_views(records, settings.lanes * 4, config.min_separation, config.min_separation_deg)
    starts, pool = candidates[: settings.lanes], candidates[settings.lanes :]
    if starts:
        if settings.refine == "gradient":
            gradient = settings.gradient_lanes()
            records += trust_region_refine(context, starts, pool, gradient, bar, 4, settings.screen_supersample)
        else:
            records += local_refine(context, starts, pool, settings, rng, 4)
    return context.result(records, incumbent_path(records))
