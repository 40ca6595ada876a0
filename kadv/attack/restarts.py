"""Independent restarts of one init view's search, and how many of them reached the worst view.

A worst case found once may be luck: a deep basin that one draw falls into and the next misses.
So the search runs again from the same init view with other draws, under the same budget rules
(``attack.restarts``, each a share of the budget), and says how many of its runs reached the worst
it reports: its *agreement* (several MCMC chains checked against each other; AutoAttack's
restarts). Once two runs agree the search stops early and says so; while they disagree, the
budget buys new runs.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from tqdm import tqdm

from kadv.attack.records import Budget, InitViewResult, agreement, select_top_views
from kadv.attack.search import AttackConfig, SearchContext

__all__ = ["restarted_search"]


def restarted_search(
    search: Callable[[SearchContext, np.random.Generator, tqdm], InitViewResult],
    make_context: Callable[[AttackConfig, bool], SearchContext],
    config: AttackConfig,
    seeds: list[int],
    bar: tqdm,
) -> InitViewResult:
    """Run ``search`` ``config.restarts`` times at most, each under its share of the budget.

    Run 0 is the search as it runs alone (seeded by ``seeds``, with the context's warm starts);
    run k draws from ``seeds + [k]`` without warm starts, so that it checks run 0 independently.
    After each run from the second on, the runs' :func:`agreement` is measured, and the search
    stops once two runs agree. ``make_context(config, warm)`` gives a run's context.

    Returns the merged result: every run's records (``run`` set, their passes and seconds counted
    from the first run's start), the top views among them all, the path of the run that holds the
    best view, the budget spent, and the agreement.
    """
    share = config.restart_config()
    results: list[InitViewResult] = []
    spent = Budget()
    for run in range(config.restarts):
        context = make_context(share, run == 0)
        context.clock.progress = bar
        rng = np.random.default_rng(seeds if run == 0 else [*seeds, run])
        result = search(context, rng, bar)
        results.append(_counted_from(result, run, spent))
        spent = spent + result.budget
        if run >= 1 and not agreement(results, config.restarts, config.agreement_delta1).alone:
            break
    records = [record for result in results for record in result.records]
    top = select_top_views(records, config.top_n, config.min_separation, config.min_separation_deg)
    holder = next((result for result in results if top and any(r is top[0] for r in result.records)), results[0])
    return InitViewResult(
        results[0].init, records, top, spent, holder.path, agreement(results, config.restarts, config.agreement_delta1)
    )


def _counted_from(result: InitViewResult, run: int, spent: Budget) -> InitViewResult:
    """A run's result with its records marked ``run`` and its passes and seconds counted on from
    what the runs before it ``spent``."""
    if run == 0:
        return result
    moved = {
        id(r): dataclasses.replace(r, run=run, passes=r.passes + spent.passes, seconds=r.seconds + spent.seconds)
        for r in result.records
    }
    again = lambda records: [moved[id(r)] for r in records]
    return dataclasses.replace(result, records=again(result.records), top=again(result.top), path=again(result.path))
