"""Trust-region lanes: batched gradient ascent from a search's best views, each lane's step grown
where the objective rises and undone and shrunk where it does not (``hybrid``'s refinement, and
``halving``'s with ``refine=gradient``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from tqdm import tqdm

from kadv.attack.records import ViewRecord
from kadv.attack.search import SearchContext
from kadv.attack.space import FOV

__all__ = ["LaneSettings", "check_trust_region", "trust_region_refine"]


@dataclass(frozen=True)
class LaneSettings:
    """The lanes' steps (checked, and named in errors, by the method whose settings they come from).

    Attributes:
        lr_rotation, lr_translation, lr_fov_deg: a lane's first step lengths (radians, metres,
            degrees) along the normalised gradient of the rotation vector, of the centre offset
            and of the field of view (when ``envelope.fov_deg`` frees it).
        grow, shrink: a step that raises the objective multiplies the lane's step length by
            ``grow``; one that does not is undone and multiplies it by ``shrink``.
        stall_scale: a lane whose step length has shrunk below this share of the first restarts
            from the next view of its pool (or, when none is left, with its first step length
            where it is).
    """

    lr_rotation: float = 0.02
    lr_translation: float = 0.03
    lr_fov_deg: float = 1.0
    grow: float = 1.5
    shrink: float = 0.5
    stall_scale: float = 0.1


def check_trust_region(settings, node: str, shares: tuple[str, ...]) -> None:
    """Refuse, naming ``<node>.<field>``, a trust region's ``grow`` below 1, a ``shrink`` outside
    (0, 1), or another of the ``shares`` outside (0, 1]."""
    for name in shares:
        value = getattr(settings, name)
        if not (math.isfinite(value) and 0.0 < value <= 1.0) or (name == "shrink" and value == 1.0):
            interval = "(0, 1)" if name == "shrink" else "(0, 1]"
            raise ValueError(f"{node}.{name} must be in {interval}, got {value}")
    if not (math.isfinite(settings.grow) and settings.grow >= 1.0):
        raise ValueError(f"{node}.grow must be >= 1, got {settings.grow}")


def _steps(gradient: torch.Tensor, radius: torch.Tensor, settings: LaneSettings) -> torch.Tensor:
    """Moves (L, dims): each lane's gradient, normalised per block (rotation, translation, field
    of view), times its step lengths."""
    step = torch.zeros_like(gradient)
    blocks = [(slice(0, 3), settings.lr_rotation), (slice(3, 6), settings.lr_translation)]
    if gradient.shape[1] > FOV:
        blocks.append((slice(FOV, FOV + 1), settings.lr_fov_deg))
    for block, length in blocks:
        part = gradient[:, block]
        step[:, block] = length * radius[:, None] * part / part.norm(dim=1, keepdim=True).clamp_min(1e-30)
    return step


def trust_region_refine(
    context: SearchContext,
    starts: list[ViewRecord],
    pool: list[ViewRecord],
    settings: LaneSettings,
    bar: tqdm,
    first_step: int,
    supersample: int | None = None,
) -> list[ViewRecord]:
    """Batched trust-region gradient ascent from ``starts`` within the context's budget; its records.

    Each lane keeps an incumbent (a rankable view and the objective's gradient there). A step goes
    along the normalised gradient from the incumbent, pulled within the pose bounds and through the
    step guard; it becomes the incumbent only if it is rankable and raises the objective (then the
    step grows), otherwise it is undone (and the step shrinks). A lane whose step has shrunk below
    ``stall_scale`` restarts from the next view of ``pool``. So no lane's incumbent ever falls.
    Lane ids (records' ``restart``) are new for each restart.

    ``supersample``: the lanes render and take their gradients at this cheap fidelity (rays per
    pixel side; None: the run's, exactly). A trial that raises its lane's objective at that fidelity
    is then rendered and scored exactly, and becomes the incumbent only if its exact objective beats
    the incumbent's: the exact render validates each accepted step, and every incumbent is an exact
    view. The cheap trials are screened records (never chosen or followed). Trials whose values
    came from the warp (``render.differentiable.values=warp``, between refreshes) are cheap too.

    A step costs a forward pass per lane and, when any lane's trial may be accepted, a backward
    pass through the whole batch (the model's backward runs over every image of it), and at a
    cheap fidelity a forward pass per trial validated; it starts only while the budget holds them all.
    """
    clock = context.clock
    # at a cheap fidelity, or with values from the warp, an accepted trial is validated exactly
    cheap = supersample is not None or context.differentiable.config.values == "warp"
    cost = 3 if cheap else 2
    lanes = clock.allows(len(starts), cost=cost)
    if lanes == 0:
        return []
    differentiable = context.differentiable_at(supersample)
    pool = list(pool)
    ids = list(range(lanes))
    next_id = lanes
    current = torch.tensor([r.params for r in starts[:lanes]], dtype=torch.float64)  # incumbents
    level = torch.full((lanes,), -math.inf, dtype=torch.float64)  # their objective at the lanes' fidelity
    exact = torch.tensor([r.objective for r in starts[:lanes]], dtype=torch.float64)  # and exactly (a cheap lane)
    gradient = torch.zeros(lanes, context.space.dims, dtype=torch.float64)
    radius = torch.ones(lanes, dtype=torch.float64)
    fresh = torch.ones(lanes, dtype=torch.bool)  # the trial is the incumbent itself: evaluate for its gradient
    records: list[ViewRecord] = []
    step = first_step
    while clock.allows(lanes, cost=cost) == lanes:
        with clock.charge(lanes) as charge:  # its backward passes and fidelity are known once it has run
            proposal = context.project(current + torch.where(fresh[:, None], 0.0, _steps(gradient, radius, settings)))
            reached, fraction = context.guard(current[:, 3:6], proposal[:, 3:6])
            # the lanes' bookkeeping stays on the host, where its decisions are made; the trial goes to the device
            trial = torch.cat(
                [proposal[:, :3].to(context.device), reached, proposal[:, FOV:].to(context.device)], dim=1
            )
            out, terms = context.differentiable_terms(differentiable, trial.requires_grad_(True))
            screened = charge.screened = supersample is not None or out.warped
            rows = context.records(
                step,
                trial,
                out.world_T_cam,
                terms,
                fraction,
                (out.coverage, out.rgb_error, out.depth_error),
                out.refreshed,
                lanes=list(ids),
                render=out.exact,
                screened=screened,
            )
            records += rows
            value = terms.objective.detach().cpu()
            valid = torch.tensor([r.valid for r in rows])  # rankable at the lanes' fidelity (full size)
            risen = ~fresh & valid & (value > level)
            backward = charge.backward = lanes if bool((fresh | risen).any()) else 0
            if backward:
                (terms.objective * (fresh | risen).to(terms.objective.device)).sum().backward()
        if screened and bool(risen.any()):
            chosen = torch.nonzero(risen).flatten().tolist()
            scored = context.score(step, trial.detach()[chosen], fraction[chosen], lanes=[ids[i] for i in chosen])
            records += scored
            for lane, row in zip(chosen, scored):
                if row.rankable and row.objective > exact[lane]:
                    exact[lane] = row.objective
                else:
                    risen[lane] = False  # the exact render does not confirm the step
        accepted = fresh | risen
        if backward:
            gradient[accepted] = trial.grad.cpu()[accepted]
            current[accepted] = trial.detach().cpu()[accepted]
            level[accepted] = torch.where(valid, value, torch.full_like(value, -math.inf))[accepted]
        radius = torch.where(risen, radius * settings.grow, radius)
        radius = torch.where(accepted, radius, radius * settings.shrink)
        fresh = torch.zeros_like(fresh)
        for lane in torch.nonzero(radius < settings.stall_scale).flatten().tolist():
            radius[lane] = 1.0
            if pool:
                restart = pool.pop(0)
                current[lane], exact[lane] = torch.tensor(restart.params, dtype=torch.float64), restart.objective
                level[lane], fresh[lane] = -math.inf, True
                ids[lane], next_id = next_id, next_id + 1
        bar.set_postfix(loss=f"{max((r.loss for r in records if r.rankable), default=math.nan):.4f}", refresh=False)
        step += 1
    return records
