"""``attack``: run one search method from every init view, resumably."""

from __future__ import annotations

from collections.abc import Callable

import torch
from tqdm import tqdm

from kadv.attack.init_views import InitView, fit_into_envelope
from kadv.attack.objective import Objective
from kadv.attack.records import AttackResult, InitViewResult
from kadv.attack.registry import check_searchable, get_method
from kadv.attack.restarts import restarted_search
from kadv.attack.search import AttackConfig, SearchContext
from kadv.render import DifferentiableRenderer

__all__ = ["attack"]


def attack(
    objective: Objective,
    differentiable: DifferentiableRenderer,
    init_views: list[InitView],
    height: int,
    width: int,
    config: AttackConfig,
    seed: int,
    completed: dict[int, InitViewResult] | None = None,
    on_result: Callable[[int, InitViewResult], None] | None = None,
    progress: bool = True,
    starts: dict[int, torch.Tensor] | None = None,
) -> AttackResult:
    """Search for adversarial views from every init view with ``config.method``.

    Each init view's search is seeded by (seed, its index) alone, so a run resumed after an
    interruption (``completed`` holds the init views already done) gives the same results.

    Args:
        objective: what to maximise; its penalty settings also rule the step guard and view validity.
        differentiable: the differentiable renderer (gradient steps use it; views evaluated
            without a gradient use its exact renderer and supersampling).
        init_views: starting views; one outside ``config.envelope`` is moved into it, or refused
            (:class:`InitViewError`) when it cannot be.
        height, width: the image size.
        config: search settings.
        seed: the run's seed.
        completed: results already computed, by init-view index; they are not recomputed.
        on_result: called with (index, result) as each init view finishes (to save it).
        progress: show a tqdm bar (in model passes; no total under a seconds budget alone).
        starts: warm starts by init-view index, pose parameters (N, 6) relative to that init view
            (:class:`~kadv.attack.search.SearchContext`'s ``starts``).
    """
    init_views = _checked(objective, differentiable, init_views, config)
    completed, result = dict(completed or {}), AttackResult(config.method)
    per_view = config.passes
    total = len(init_views) * per_view if per_view else None
    options = {"desc": f"{config.method} attack", "disable": not progress, "unit": "pass", "dynamic_ncols": True}
    with tqdm(total=total, **options) as bar:
        for index, init in enumerate(init_views):
            if index in completed:
                bar.update(per_view or 0)
                result.views.append(completed[index])
                continue
            bar.set_description(f"{config.method} attack, init view {index + 1}/{len(init_views)}")
            bar.set_postfix_str("", refresh=False)  # the previous init view's best is not this one's
            warm = (starts or {}).get(index)
            view_result = _search_from(
                objective, differentiable, init, (height, width), config, [seed, index], warm, bar
            )
            result.views.append(view_result)
            if on_result is not None:
                on_result(index, view_result)
            if per_view:  # a search that ended early leaves the bar where the budget would have
                bar.n = (index + 1) * per_view
                bar.refresh()
    return result


def _checked(
    objective: Objective, differentiable: DifferentiableRenderer, init_views: list[InitView], config: AttackConfig
) -> list[InitView]:
    """The init views moved into ``config.envelope``, once the method has accepted its settings and
    the model; all of them before any search, so that a view that cannot be moved in is refused
    before work is spent."""
    config.check_run(get_method(config.method).check, differentiable.config.supersample)
    check_searchable(config.method, objective.model)
    fit = lambda init: fit_into_envelope(differentiable.renderer, init, config.envelope, objective.penalty.margin)
    return [fit(init) for init in init_views]


def _search_from(
    objective: Objective,
    differentiable: DifferentiableRenderer,
    init: InitView,
    size: tuple[int, int],
    config: AttackConfig,
    seed: list[int],
    warm: torch.Tensor | None,
    bar: tqdm,
) -> InitViewResult:
    """One init view's search under ``config`` (its restarts, each seeded from ``seed``), each run
    from an anchor of its own, the first warm-started from ``warm``."""

    def make_context(share: AttackConfig, first: bool) -> SearchContext:
        differentiable.reset()  # each run from its own anchor: runs are independent
        return SearchContext(objective, differentiable, init, *size, share, warm if first else None)

    return restarted_search(get_method(config.method).search, make_context, config, seed, bar)
