from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kadv.attack import (
    Agreement,
    AttackConfig,
    HalvingSettings,
    SearchContext,
    ViewRecord,
    agreement,
    attack,
    get_method,
    restarted_search,
)
from kadv.attack.records import Budget, InitViewResult
from kadv.models import count_passes
from kadv.report.outputs import trajectory_rows
from kadv.report.summary import read_partial, write_partial

H, W = 24, 32


def _record(delta1: float, passes: int = 1) -> ViewRecord:
    return ViewRecord(0, 0, [0.0] * 6, [0.0] * 3, [0.0, 1.5, 1.0], 1.0 - delta1, 0.0, 1.0 - delta1, delta1, 0.1,
                      "valid", passes=passes)  # fmt: skip


class _Scripted:
    """A search whose k-th run finds a view of the k-th scripted worst delta1, for 10 passes."""

    def __init__(self, worsts: list[float]) -> None:
        self.worsts, self.seeds = list(worsts), []

    def __call__(self, context, rng: np.random.Generator, bar) -> InitViewResult:
        self.seeds.append(rng.integers(2**31))
        worst = self.worsts[len(self.seeds) - 1]
        records = [_record(0.9), _record(worst, passes=10)]
        return InitViewResult(None, records, [records[1]], Budget(forward=10, seconds=1.0), records)


class _Context:
    def __init__(self) -> None:
        self.clock = type("Clock", (), {"progress": None})()


def _restarted(worsts: list[float], restarts: int, tolerance: float = 0.03) -> tuple[InitViewResult, _Scripted]:
    search = _Scripted(worsts)
    config = AttackConfig("random", budget_passes=10 * restarts, restarts=restarts, agreement_delta1=tolerance)
    return restarted_search(search, lambda share, first: _Context(), config, [0, 0], None), search


def test_the_restarts_stop_once_a_second_run_reaches_the_best_worst() -> None:
    result, search = _restarted([0.50, 0.20, 0.21, 0.0], restarts=4)
    assert len(search.seeds) == 3 and len(set(search.seeds)) == 3  # each run draws anew
    assert result.agreement == Agreement(2, 3, 4, [0.50, 0.20, 0.21], 0.03)
    assert result.agreement.stopped_early and not result.agreement.alone
    assert result.agreement.text() == "2/3 (stopped early, of 4)"
    assert result.budget.passes == 30 and [r.run for r in result.records] == [0, 0, 1, 1, 2, 2]
    # each run's passes and seconds count on from the runs before it
    assert [r.passes for r in result.records] == [1, 10, 11, 20, 21, 30]
    assert result.top[0].delta1 == 0.20 and result.path[-1] is result.top[0]


def test_a_worst_that_no_other_run_reaches_is_flagged_alone_after_every_run() -> None:
    result, search = _restarted([0.50, 0.20, 0.90, 0.60], restarts=4)
    assert len(search.seeds) == 4 and result.agreement.text() == "1/4 (alone)"
    assert result.agreement.alone and not result.agreement.stopped_early
    one, _ = _restarted([0.3], restarts=1)
    assert one.agreement.text() == "1/1 (alone)" and one.records == _restarted([0.3], 1)[0].records


def test_the_agreement_counts_the_runs_within_the_tolerance_of_the_lowest_worst() -> None:
    results = [InitViewResult(None, [_record(w)], [], Budget(), []) for w in (0.31, 0.30, 0.34, 0.33)]
    assert agreement(results, 4, 0.03).reached == 3  # 0.30, 0.31, 0.33; 0.34 is 0.04 away
    assert agreement(results, 4, 0.0).reached == 1
    unrankable = [
        InitViewResult(None, [dataclasses.replace(_record(0.1), verdict="inside an object")], [], Budget(), [])
    ]
    assert agreement(unrankable, 1, 0.03).worsts == [1.0]  # nothing rankable: no failure found


def test_one_run_is_the_method_alone_bit_for_bit(tiny_objective, differentiable, file_view) -> None:
    config = AttackConfig("halving", budget_passes=20)
    result = attack(tiny_objective, differentiable, [file_view], H, W, config, seed=3, progress=False)
    differentiable.reset()
    context = SearchContext(tiny_objective, differentiable, file_view, H, W, config)
    alone = get_method("halving").search(context, np.random.default_rng([3, 0]), _NoBar())
    assert [dataclasses.replace(r, seconds=0.0) for r in result.views[0].records] == [
        dataclasses.replace(r, seconds=0.0) for r in alone.records
    ]
    assert result.views[0].agreement.text() == "1/1 (alone)"


class _NoBar:
    def update(self, *args) -> None: ...
    def set_postfix(self, *args, **kwargs) -> None: ...
    def set_postfix_str(self, *args, **kwargs) -> None: ...


def test_restarts_share_the_budget_and_the_model_counts_it(tiny_objective, differentiable, file_view, tmp_path) -> None:
    config = AttackConfig("halving", budget_passes=30, restarts=3, agreement_delta1=1.0)  # any two runs agree
    with count_passes(tiny_objective.model) as count:
        result = attack(tiny_objective, differentiable, [file_view], H, W, config, seed=0, progress=False)
    view = result.views[0]
    assert view.agreement.runs == 2 and view.agreement.stopped_early  # the second run agreed: the third never ran
    assert count.passes == view.budget.passes == 20 and {r.run for r in view.records} == {0, 1}
    spent = [r.passes for r in view.records]
    assert spent == sorted(spent) and spent[-1] == 20
    for run in (0, 1):  # each run began at the init view
        assert next(r for r in view.records if r.run == run).params == [0.0] * 6
    # the partial result that a resumed run reads back keeps the runs apart, and the agreement
    back = read_partial(write_partial(tmp_path / "init0.json", view))
    assert back.agreement == view.agreement and [(r.run, r.step, r.restart) for r in back.top] == [
        (r.run, r.step, r.restart) for r in view.top
    ]
    assert {row["run"] for row in trajectory_rows(result)} == {0, 1}
    again = attack(tiny_objective, differentiable, [file_view], H, W, config, seed=0, progress=False)
    assert trajectory_rows(again) == trajectory_rows(result)  # the same seed, the same runs


@pytest.mark.parametrize(
    "overrides, message",
    [
        ({"restarts": 0}, r"^attack.restarts must be an integer >= 1, got 0$"),
        ({"agreement_delta1": 2.0}, r"^attack.agreement_delta1 must be in \[0, 1\], got 2.0$"),
        (
            {"restarts": 3, "budget_passes": 5},
            r"^attack.budget_passes must be at least 2 for attack.halving .*\(attack.budget_passes=5 split over "
            r"attack.restarts=3: 1 a run\)$",
        ),
    ],
)
def test_bad_restart_settings_are_refused_in_one_line(overrides, message) -> None:
    with pytest.raises(ValueError, match=message):
        AttackConfig("halving", HalvingSettings(), **overrides)
