from __future__ import annotations

import math
import time

import pytest
import torch

from kadv.attack import AttackConfig, ViewRecord, attack, select_top_views, separated

H, W = 48, 64


def _run(objective, differentiable, views, size=(H, W), **overrides):
    config = AttackConfig(**{"steps": 10, "restarts": 2, **overrides})
    return attack(objective, differentiable, views, *size, config, seed=0, progress=False)


def test_ten_gradient_steps_raise_l_depth_on_every_restart(tiny_objective, differentiable, file_view) -> None:
    # L_depth is rough in the pose at a few thousand pixels (min-max normalisation, occlusions); at
    # 96 x 128 ten steps lift every restart
    result = _run(tiny_objective, differentiable, [file_view], size=(96, 128), restarts=3)
    view = result.views[0]
    for restart in range(3):
        path = [r for r in view.records if r.restart == restart]
        assert [r.step for r in path] == list(range(11))
        assert max(r.l_depth for r in path[1:]) > path[0].l_depth, restart
    assert view.budget.forward == 33 and view.budget.backward == 30 and view.budget.seconds > 0
    assert view.init_record.params == [0.0] * 6  # restart 0 starts at the init view itself
    best = max(range(3), key=lambda b: max(r.l_depth for r in view.records if r.restart == b and r.valid))
    assert view.best_restart == best
    assert view.top and all(r.valid and r.restart == best for r in view.top)
    assert [r.l_depth for r in view.top] == sorted((r.l_depth for r in view.top), reverse=True)
    for i, a in enumerate(view.top):
        for b in view.top[i + 1:]:
            assert separated(a, b, 0.05, 3.0)


def test_bounds_hold_on_every_visited_pose(tiny_objective, differentiable, file_view) -> None:
    result = _run(tiny_objective, differentiable, [file_view], lr_rotation=0.2, lr_translation=0.2,
                  max_angle_deg=5.0, max_distance=0.1, steps=4)
    for record in result.views[0].records:
        assert torch.tensor(record.params[:3], dtype=torch.float64).norm() <= math.radians(5.0) + 1e-9
        assert torch.tensor(record.params[3:], dtype=torch.float64).norm() <= 0.1 + 1e-9


def _record(l_depth: float, centre: list[float], verdict: str = "valid", theta=(0.0, 0.0, 0.0)) -> ViewRecord:
    return ViewRecord(step=0, restart=0, params=[0.0] * 6, theta=list(theta), centre=centre, l_depth=l_depth,
                      l_dist=0.0, objective=l_depth, delta1=1.0, abs_rel=0.0, verdict=verdict)


def test_top_views_skip_invalid_views_and_keep_their_separation() -> None:
    records = [
        _record(0.9, [0.0, 0.0, 0.0], verdict="inside an object"),
        _record(0.8, [0.0, 0.0, 0.0]),
        _record(0.7, [0.01, 0.0, 0.0]),                        # too near the 0.8 view
        _record(0.6, [0.01, 0.0, 0.0], theta=(0.0, 0.2, 0.0)),  # as near, but turned by 11.5 degrees
        _record(0.5, [1.0, 0.0, 0.0]),
    ]
    top = select_top_views(records, 5, min_distance=0.05, min_angle_deg=3.0)
    assert [r.l_depth for r in top] == [0.8, 0.6, 0.5]
    assert select_top_views(records, 2, 0.05, 3.0) == top[:2]


@pytest.mark.parametrize("method", ["random", "cma"])
def test_black_box_methods_stay_within_their_evaluation_budget(method, tiny_objective, differentiable, file_view) -> None:
    result = _run(tiny_objective, differentiable, [file_view], method=method, budget_evaluations=11, population=4)
    view = result.views[0]
    assert view.budget.forward == len(view.records) == 11
    assert view.budget.backward == 0
    assert view.init_record.params == [0.0] * 6 and view.best_restart is None
    assert all(r.valid for r in view.top)
    half = AttackConfig(steps=10, restarts=2).search_box()
    for record in view.records:  # samples stay in the box a gradient run may reach
        assert all(abs(p) <= h + 1e-9 for p, h in zip(record.params, half.tolist()))


@pytest.mark.parametrize("method", ["random", "cma"])
def test_black_box_methods_stay_within_their_time_budget(method, tiny_objective, differentiable, file_view) -> None:
    started = time.perf_counter()
    result = _run(tiny_objective, differentiable, [file_view], method=method, budget_evaluations=10_000,
                  budget_seconds=1.0, population=4)
    elapsed = time.perf_counter() - started
    view = result.views[0]
    assert view.budget.forward < 10_000
    # the clock is checked before each batch, so at most one batch runs past the budget
    per_batch = elapsed / max(1, len({r.step for r in view.records}))
    assert view.budget.seconds <= 1.0 + 2 * per_batch + 0.5


def test_same_seed_gives_bit_identical_records(tiny_objective, differentiable, file_view) -> None:
    first = _run(tiny_objective, differentiable, [file_view], steps=3)
    second = _run(tiny_objective, differentiable, [file_view], steps=3)
    assert first.views[0].records == second.views[0].records


@pytest.mark.parametrize("overrides, key", [
    ({"steps": -1}, "attack.steps"),
    ({"method": "adam"}, "attack.method"),
    ({"restarts": 0}, "attack.restarts"),
    ({"lr_rotation": 0.0}, "attack.lr_rotation"),
    ({"max_distance": -1.0}, "attack.max_distance"),
])
def test_bad_settings_name_their_key(overrides, key) -> None:
    with pytest.raises(ValueError, match=key):
        AttackConfig(**overrides)
