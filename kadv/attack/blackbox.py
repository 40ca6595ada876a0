"""Black-box baselines at the gradient attack's budget: uniform random search and CMA-ES.

Both sample poses in the box a gradient run may reach (:meth:`AttackConfig.search_box`), move
there from the init view through the same step guard, follow the same validity rules, evaluate
each batch in one pass of exact renders, and count their evaluations and seconds.
"""
from __future__ import annotations

import math
import time

import cma
import numpy as np
import torch
from tqdm import tqdm

from kadv.attack.records import Budget, InitViewResult, ViewRecord, select_top_views
from kadv.attack.search import AttackConfig, SearchContext

__all__ = ["cma_search", "random_search"]

# CMA-ES ranks candidates; an invalid view ranks below every valid one
_INVALID_FITNESS = 1e9


def _evaluate(context: SearchContext, step: int, params: torch.Tensor, budget: Budget) -> list[ViewRecord]:
    """Guard the move from the init view to each pose (B, 6), render exactly, and record."""
    reached, fraction = context.guard(torch.zeros_like(params[:, 3:]), params[:, 3:])
    params = torch.cat([params[:, :3], reached], dim=1)
    pose, terms, render = context.evaluate_exact(params)
    budget.forward += len(params)
    return context.records(step, params, pose, terms, fraction, render=render)


def _left(config: AttackConfig, budget: Budget, started: float) -> int:
    """Evaluations still allowed by the count and time budgets."""
    if config.budget_seconds is not None and time.perf_counter() - started >= config.budget_seconds:
        return 0
    return config.evaluations - budget.forward


def _result(context: SearchContext, config: AttackConfig, records: list[ViewRecord], budget: Budget) -> InitViewResult:
    top = select_top_views(records, config.top_n, config.min_separation, config.min_separation_deg)
    return InitViewResult(context.init, records, None, top, budget)


def random_search(context: SearchContext, config: AttackConfig, rng: np.random.Generator,
                  bar: tqdm) -> InitViewResult:
    """Uniform samples in the search box, ``config.population`` per batch; the first batch's first
    view is the init view itself."""
    started, budget, records = time.perf_counter(), Budget(), []
    half = config.search_box()
    step = 0
    while (left := _left(config, budget, started)) > 0:
        count = min(config.population, left)
        params = config.project(torch.from_numpy(rng.uniform(-1.0, 1.0, size=(count, 6))) * half)
        if step == 0:
            params[0] = 0.0
        records += _evaluate(context, step, params, budget)
        bar.set_postfix(L_depth=f"{max(r.l_depth for r in records):.4f}", refresh=False)
        bar.update(1)
        step += 1
    return _result(context, config, records, budget)


def cma_search(context: SearchContext, config: AttackConfig, rng: np.random.Generator,
               bar: tqdm) -> InitViewResult:
    """CMA-ES (the ``cma`` package, ask/tell) on the pose parameters scaled to the unit search box.

    Step 0 evaluates the init view alone; each later step is one population, evaluated as one
    batch. Fitness is -objective for valid views; invalid ones rank last.
    """
    started, budget = time.perf_counter(), Budget()
    half = config.search_box()
    records = _evaluate(context, 0, torch.zeros(1, 6, dtype=torch.float64), budget)
    bar.update(1)
    options = {"seed": int(rng.integers(1, 2**31 - 1)), "popsize": config.population, "bounds": [-1.0, 1.0],
               "verbose": -9, "CMA_stds": None}
    strategy = cma.CMAEvolutionStrategy(np.zeros(6), config.cma_sigma, options)
    step = 1
    while (left := _left(config, budget, started)) > 0:
        candidates = strategy.ask()
        count = min(len(candidates), left)
        params = config.project(torch.from_numpy(np.asarray(candidates[:count])) * half)
        rows = _evaluate(context, step, params, budget)
        records += rows
        bar.set_postfix(L_depth=f"{max(r.l_depth for r in records):.4f}", refresh=False)
        bar.update(1)
        step += 1
        if count < len(candidates):
            break  # the budget ends inside a population, which CMA-ES cannot be told about
        strategy.tell(candidates, [-r.objective if r.valid and math.isfinite(r.objective) else _INVALID_FITNESS
                                   for r in rows])
    return _result(context, config, records, budget)
