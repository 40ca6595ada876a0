"""The gradient attack: Adam on (omega, delta) through the differentiable renderer, guarded steps."""
from __future__ import annotations

import math

import numpy as np
import torch
from tqdm import tqdm

from kadv.attack.records import Budget, InitViewResult, select_top_views
from kadv.attack.search import AttackConfig, SearchContext

__all__ = ["gradient_search", "restart_jitter"]


def restart_jitter(rng: np.random.Generator, restarts: int, config: AttackConfig) -> torch.Tensor:
    """Start parameters (restarts, 6): zero for restart 0, uniform in the jitter balls for the others."""
    directions = rng.normal(size=(restarts, 2, 3))
    directions /= np.linalg.norm(directions, axis=2, keepdims=True)
    scale = np.array([math.radians(config.jitter_deg), config.jitter_distance])[None, :, None]
    radii = rng.uniform(size=(restarts, 2, 1)) ** (1.0 / 3.0) * scale
    params = torch.from_numpy((directions * radii).reshape(restarts, 6))
    params[0] = 0.0
    return params


def gradient_search(context: SearchContext, config: AttackConfig, rng: np.random.Generator,
                    bar: tqdm) -> InitViewResult:
    """Maximise the objective from one init view with ``config.restarts`` batched Adam runs.

    Each update is pulled back within the pose bounds, then passes the step guard (a move that
    would cross or approach a surface is shortened; the fraction taken is recorded). Every
    visited view is recorded with its validity verdict; invalid views are never chosen.
    """
    batch = config.restarts
    start = config.project(restart_jitter(rng, batch, config))
    reached, fraction = context.guard(torch.zeros(batch, 3, dtype=torch.float64), start[:, 3:])
    omega = start[:, :3].clone().requires_grad_(True)
    delta = reached.clone().requires_grad_(True)
    optimiser = torch.optim.Adam([{"params": [omega], "lr": config.lr_rotation},
                                  {"params": [delta], "lr": config.lr_translation}], maximize=True)
    base = context.base(batch)
    records, budget = [], Budget()
    for step in range(config.steps + 1):
        params = torch.cat([omega, delta], dim=1)
        out = context.differentiable(params, base, context.K, context.height, context.width)
        terms = context.objective(out.rgb, out.depth, out.mask, out.world_T_cam)
        budget.forward += batch
        records += context.records(step, params, out.world_T_cam, terms, fraction,
                                   (out.coverage, out.rgb_error, out.depth_error), out.refreshed, render=out.exact)
        bar.set_postfix(L_depth=f"{float(terms.l_depth.detach().max()):.4f}", refresh=False)
        bar.update(1)
        if step == config.steps:
            break
        optimiser.zero_grad()
        terms.objective.sum().backward()
        budget.backward += batch
        previous = delta.detach().clone()
        optimiser.step()
        with torch.no_grad():
            bounded = config.project(torch.cat([omega, delta], dim=1))
            reached, fraction = context.guard(previous, bounded[:, 3:])
            omega.copy_(bounded[:, :3])
            delta.copy_(reached)
    best = max(range(batch), key=lambda b: max((r.l_depth for r in records if r.restart == b and r.valid),
                                               default=-math.inf))
    top = select_top_views([r for r in records if r.restart == best], config.top_n, config.min_separation,
                           config.min_separation_deg)
    return InitViewResult(context.init, records, best, top, budget)
