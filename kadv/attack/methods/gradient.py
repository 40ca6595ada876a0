"""The study's attack: Adam on (omega, delta) (and the field of view, when it is searched) through
the differentiable renderer, guarded steps."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from kadv.attack.capture import StepGraph
from kadv.attack.records import InitViewResult, ViewRecord
from kadv.attack.registry import register_method
from kadv.attack.search import Measures, SearchContext
from kadv.attack.space import FOV

__all__ = ["GradientSettings", "gradient_ascent", "gradient_search", "restart_jitter"]


@dataclass(frozen=True)
class GradientSettings:
    """``attack.gradient``. Angles in degrees, distances in metres.

    Attributes:
        steps: Adam steps per restart (each restart evaluates steps + 1 views, a forward and a
            backward pass at each step and a forward pass at the last view: 2 x steps + 1 passes).
        restarts: runs per init view, batched; restart 0 starts at the init view, the others from
            seeded pose jitter.
        lr_rotation: Adam learning rate of the rotation vector (radians).
        lr_translation: Adam learning rate of the centre offset (metres).
        lr_fov_deg: Adam learning rate of the field of view (degrees), when ``envelope.fov_deg``
            frees it.
        jitter_deg, jitter_distance: largest rotation and centre offset of a restart's start.
    """

    steps: int = 40
    restarts: int = 3
    lr_rotation: float = 0.02
    lr_translation: float = 0.03
    lr_fov_deg: float = 1.0
    jitter_deg: float = 3.0
    jitter_distance: float = 0.05


def restart_jitter(rng: np.random.Generator, restarts: int, settings: GradientSettings) -> torch.Tensor:
    """Start poses (restarts, 6): zero for restart 0, uniform in the jitter balls for the others."""
    directions = rng.normal(size=(restarts, 2, 3))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    scale = np.array([math.radians(settings.jitter_deg), settings.jitter_distance])[None, :, None]
    radii = rng.uniform(size=(restarts, 2, 1)) ** (1.0 / 3.0) * scale
    params = torch.from_numpy((directions * radii).reshape(restarts, 6))
    params[0] = 0.0
    return params


def gradient_ascent(
    context: SearchContext,
    start: torch.Tensor,
    steps: int,
    settings: GradientSettings,
    bar: tqdm,
    first_step: int = 0,
) -> list[Measures]:
    """Batched Adam runs from ``start`` (R, dims) within the context's budget, at the settings'
    learning rates; the measures of each step.

    Each update is pulled back within the pose bounds, then passes the step guard (a move that
    would cross or approach a surface is shortened; the fraction taken is recorded). Views whose
    values came from the warp (``render.differentiable.values=warp``, between refreshes) are
    screened records; the views the runs end on are rendered exactly. A step runs
    only while the budget allows its forward and backward passes for all R views; where it allows
    only the forward passes, the views are evaluated and the run ends. Restart r is lane r, step s
    is ``first_step + s``.
    The poses stay on the context's device and nothing is read back to the host until the run
    ends: :meth:`Measures.records` then makes the records.
    """
    clock = context.clock
    batch = clock.allows(len(start))
    if batch == 0:
        return []
    start = context.project(start[:batch].to(context.device, torch.float64, non_blocking=True))
    reached, fraction = context.guard(torch.zeros_like(start[:, 3:6]), start[:, 3:6])
    omega = start[:, :3].clone().requires_grad_(True)
    delta = reached.clone().requires_grad_(True)
    fov = start[:, FOV:].clone().requires_grad_(True)  # (R, 0) when the field of view is fixed
    render = context.differentiable.config
    # a step that keeps its anchor decides on the host when to refresh it, and a searched field of
    # view checks its intrinsics on the host: a graph would replay one choice
    fixed = render.refresh == "always" and not context.space.fov_searched
    capture = StepGraph.available(context.device, render.cuda_graphs and fixed)
    # a captured step keeps Adam's step count on the device
    groups = [{"params": [omega], "lr": settings.lr_rotation}, {"params": [delta], "lr": settings.lr_translation}]
    if context.space.fov_searched:
        groups.append({"params": [fov], "lr": settings.lr_fov_deg})
    optimiser = torch.optim.Adam(groups, maximize=True, capturable=capture)
    step = 0

    def evaluate() -> tuple[Measures, torch.Tensor]:
        params = torch.cat([omega, delta, fov], dim=1)
        out, terms = context.differentiable_terms(context.differentiable, params)
        stats = (out.coverage, out.rgb_error, out.depth_error)
        measured = context.measure(first_step + step, params, out.world_T_cam, terms, fraction, stats, out.refreshed,
                                   render=out.exact, screened=out.warped)  # fmt: skip
        return measured, terms.objective

    def ascend() -> Measures:
        """One Adam step from the current poses (it updates omega, delta, fov and fraction in
        place) and the measures of the views it started from."""
        measured, objective = evaluate()
        optimiser.zero_grad()
        objective.sum().backward()
        previous = delta.detach().clone()
        optimiser.step()
        with torch.no_grad():
            bounded = context.project(torch.cat([omega, delta, fov], dim=1))
            reached, moved = context.guard(previous, bounded[:, 3:6])
            omega.copy_(bounded[:, :3])
            delta.copy_(reached)
            fov.copy_(bounded[:, FOV:])
            fraction.copy_(moved)
        return measured

    graph = StepGraph(ascend, context.device, capture)
    measures: list[Measures] = []
    for step in range(steps + 1):
        if step > 0 and clock.allows(batch) < batch:
            break
        if step == steps or clock.allows(batch, cost=2) < batch:  # no room for the backward pass
            context.differentiable.validate_next()  # the views a run ends on are scored exactly
            with clock.charge(batch):
                measures.append(evaluate()[0])
            break
        with clock.charge(batch, backward=batch):
            measured = graph()
            if graph.captured:  # a replay returns what the capture measured, but for the host's numbers
                passes = clock.budget.passes + batch
                replaced = {"step": first_step + step, "seconds": clock.elapsed(), "passes": passes}
                measured = dataclasses.replace(measured, **replaced)
        measures.append(measured)
    return measures


def best_lane(records: list[ViewRecord]) -> list[ViewRecord]:
    """The records of the lane (restart) whose rankable views reach the largest loss."""
    lanes = sorted({r.restart for r in records})
    best = max(lanes, key=lambda b: max((r.loss for r in records if r.restart == b and r.rankable), default=-math.inf))
    return [r for r in records if r.restart == best]


@register_method("gradient", GradientSettings, passes=lambda s: s.restarts * (2 * s.steps + 1))
def gradient_search(
    context: SearchContext, rng: np.random.Generator, bar: tqdm, start: torch.Tensor | None = None
) -> InitViewResult:
    """Maximise the objective from one init view with batched Adam runs.

    Args:
        context: the search context; its settings are :class:`GradientSettings`.
        rng: seeds the restarts' jitter.
        bar: progress, in evaluated views.
        start: start points (R, dims) of the pose space instead of jitter around the init view;
            the init view itself is restart 0 (prepended unless a row is zero, which then comes first).

    Every visited view is recorded with its validity verdict; invalid views are never chosen. The
    path is the best restart's.
    """
    settings, space = context.config.settings, context.space
    if start is None:
        jitter = restart_jitter(rng, settings.restarts, settings)  # each restart at the init view's field of view
        start = torch.cat([jitter, space.zeros(settings.restarts)[:, FOV:]], dim=1)
    else:
        zero = (start == 0).all(dim=1)
        start = torch.cat([space.zeros(), start[~zero].double()])
    measures = gradient_ascent(context, start, settings.steps, settings, bar)
    records = [record for step in measures for record in step.records()]
    if records:
        bar.set_postfix(loss=f"{max(r.loss for r in records):.4f}", refresh=False)
    return context.result(records, best_lane(records))
