from __future__ import annotations

import ast
import collections
import dataclasses
import math
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from tqdm import tqdm

from kadv import DifferentiableRenderer, ExactRenderer
from kadv.attack import (
    METHODS,
    AttackConfig,
    GradientSettings,
    HalvingSettings,
    HybridSettings,
    NevergradSettings,
    Objective,
    PenaltyConfig,
    Proposer,
    SearchContext,
    TurboSettings,
    ViewRecord,
    attack,
    driver,
    get_method,
    gradient_search,
    register_proposer,
    select_top_views,
    separated,
)
from kadv.attack.init_views import InitViewError, fit_into_envelope
from kadv.attack.methods.halving import screen_fidelity
from kadv.attack.search import Clock
from kadv.geometry import intrinsics_from_fov, look_at, perturb_world_T_cam, scaled_size
from kadv.models import count_passes
from kadv.penalties import ENVELOPES, Envelope
from kadv.render import DiffRenderConfig
from kadv.report.outputs import _write_csv, read_trajectory, trajectory_rows
from kadv.testing import DEFAULT_RADII

H, W = 48, 64
BUILT_IN = ("gradient", "random", "cma", "nevergrad", "hybrid", "halving", "turbo")


def _run(objective, differentiable, views, size=(H, W), method="gradient", settings=None, **overrides):
    config = AttackConfig(method, settings, **overrides)
    return attack(objective, differentiable, views, *size, config, seed=0, progress=False)


def test_the_registry_holds_the_built_in_methods_and_refuses_unknown_ones() -> None:
    assert all(get_method(m).name == m for m in BUILT_IN) and set(BUILT_IN) <= set(METHODS)
    with pytest.raises(ValueError, match=r"attack.method must be one of .*gradient.*got 'adam'"):
        AttackConfig("adam")


def test_ten_gradient_steps_raise_l_depth_from_most_restarts(tiny_objective, differentiable, file_view) -> None:
    # L_depth is rough in the pose at a few thousand pixels (min-max normalisation, occlusions): a
    # restart can start on a local peak where every step, even a quarter of the default rate, loses
    # (restart 2 here, 0.181 -> 0.156 at the first step); the others climb
    result = _run(
        tiny_objective,
        differentiable,
        [file_view],
        size=(96, 128),
        settings=GradientSettings(steps=10, restarts=3),
        budget_passes=None,
    )
    view = result.views[0]
    rose = []
    for restart in range(3):
        path = [r for r in view.records if r.restart == restart]
        assert [r.step for r in path] == list(range(11))
        rose.append(max(r.l_depth for r in path[1:]) > path[0].l_depth)
    assert sum(rose) >= 2, rose
    assert max(r.l_depth for r in view.records if r.valid) > view.init_record.l_depth
    assert view.budget.forward == 33 and view.budget.backward == 30 and view.budget.seconds > 0
    assert view.init_record.params == [0.0] * 6  # restart 0 starts at the init view itself
    best = max(range(3), key=lambda b: max(r.l_depth for r in view.records if r.restart == b and r.valid))
    assert view.path == [r for r in view.records if r.restart == best]  # the path is the best restart
    assert [r.l_depth for r in view.top] == sorted((r.l_depth for r in view.top), reverse=True)
    for i, a in enumerate(view.top):
        for b in view.top[i + 1 :]:
            assert separated(a, b, 0.05, 3.0)


def test_the_gradient_method_starts_from_given_poses(tiny_objective, differentiable, file_view) -> None:
    start = torch.tensor([[0.0, 0.1, 0.0, 0.05, 0.0, 0.0], [0.0, -0.1, 0.0, 0.0, 0.0, 0.05]], dtype=torch.float64)
    config = AttackConfig("gradient", GradientSettings(steps=2), budget_passes=None)
    context = SearchContext(tiny_objective, differentiable, file_view, H, W, config)
    from tqdm import tqdm

    with tqdm(disable=True) as bar:
        result = gradient_search(context, np.random.default_rng(0), bar, start=start)
    first = [r for r in result.records if r.step == 0]
    assert [r.params for r in first] == [[0.0] * 6, *start.tolist()]  # the init view is prepended as restart 0
    assert result.budget.forward == 3 * 3 and {r.restart for r in result.records} == {0, 1, 2}


def test_bounds_hold_on_every_visited_pose(tiny_objective, differentiable, file_view) -> None:
    for method, settings in (
        ("gradient", GradientSettings(steps=4, lr_rotation=0.2, lr_translation=0.2)),
        ("random", None),
    ):
        result = _run(
            tiny_objective,
            differentiable,
            [file_view],
            method=method,
            settings=settings,
            max_angle_deg=5.0,
            max_distance=0.1,
            budget_passes=12,
        )
        for record in result.views[0].records:
            assert torch.tensor(record.params[:3], dtype=torch.float64).norm() <= math.radians(5.0) + 1e-9
            assert torch.tensor(record.params[3:], dtype=torch.float64).norm() <= 0.1 + 1e-9


def _record(l_depth: float, centre: list[float], verdict: str = "valid", theta=(0.0, 0.0, 0.0)) -> ViewRecord:
    return ViewRecord(
        step=0,
        restart=0,
        params=[0.0] * 6,
        theta=list(theta),
        centre=centre,
        l_depth=l_depth,
        l_dist=0.0,
        objective=l_depth,
        delta1=1.0,
        abs_rel=0.0,
        verdict=verdict,
    )


def _scored(params: torch.Tensor, objectives: list[float]) -> list[ViewRecord]:
    """Valid records of the poses ``params`` (N, 6) at the given objectives, as a proposer is told them."""
    return [
        dataclasses.replace(_record(0.0, [0.0] * 3), params=p.tolist(), objective=o) for p, o in zip(params, objectives)
    ]


def test_top_views_skip_invalid_and_uninformative_views_and_keep_their_separation() -> None:
    records = [
        _record(0.9, [0.0, 0.0, 0.0], verdict="inside an object"),
        _record(0.85, [2.0, 0.0, 0.0], verdict="uninformative"),
        _record(0.8, [0.0, 0.0, 0.0]),
        _record(0.7, [0.01, 0.0, 0.0]),  # too near the 0.8 view
        _record(0.6, [0.01, 0.0, 0.0], theta=(0.0, 0.2, 0.0)),  # as near, but turned by 11.5 degrees
        _record(0.5, [1.0, 0.0, 0.0]),
    ]
    top = select_top_views(records, 5, min_distance=0.05, min_angle_deg=3.0)
    assert [r.l_depth for r in top] == [0.8, 0.6, 0.5]
    assert select_top_views(records, 2, 0.05, 3.0) == top[:2]


@pytest.mark.parametrize("method", sorted(METHODS))
@pytest.mark.parametrize("budget", [11, 30])
def test_every_method_runs_the_model_no_more_than_its_budget_of_passes(
    method, budget, tiny_objective, differentiable, file_view
) -> None:
    # the model itself counts every image it runs on and every backward pass through it
    with count_passes(tiny_objective.model) as count:
        result = _run(tiny_objective, differentiable, [file_view], method=method, budget_passes=budget)
    view = result.views[0]
    assert count.forward == view.budget.forward == len(view.records)  # screened views are passes too
    assert count.backward == view.budget.backward and count.passes == view.budget.passes <= budget
    assert view.budget.screened == sum(r.screened for r in view.records)
    # what is left is less than a step: the gradient's 3 restarts' forward and backward passes at most
    assert view.budget.passes > budget - 6
    spent = [r.passes for r in view.records]  # each view's count of passes once it was scored
    assert spent == sorted(spent) and spent[-1] <= budget
    assert view.init_record.params == [0.0] * 6 and view.path[0].step == 0 and view.path[-1] in view.records
    assert all(r.valid for r in view.top)
    half = AttackConfig().space(70.0).box()[1]
    for record in view.records:  # every pose stays in the bounds' box
        assert all(abs(p) <= h + 1e-9 for p, h in zip(record.params, half.tolist()))


@pytest.mark.parametrize("method", sorted(METHODS))
def test_48_more_budgeted_passes_buy_at_most_48_more_model_passes_at_every_profile_radius(
    method, tiny_objective, differentiable, file_view
) -> None:
    for angle, distance in DEFAULT_RADII:
        passes = []
        for budget in (48, 96):
            with count_passes(tiny_objective.model) as count:  # a backward pass through an image counts one
                result = _run(
                    tiny_objective,
                    differentiable,
                    [file_view],
                    (24, 32),
                    method,
                    budget_passes=budget,
                    max_angle_deg=angle,
                    max_distance=distance,
                )
            assert count.passes == result.views[0].budget.passes <= budget, (angle, budget)
            passes.append(count.passes)
        assert passes[1] - passes[0] <= 48, (angle, passes)


def test_the_clock_predicts_a_batch_by_its_passes(monkeypatch) -> None:
    now = [100.0]
    monkeypatch.setattr(time, "perf_counter", lambda: now[0])
    clock = Clock(None, 10.0)
    now[0] += 1.0
    with clock.charge(32, screened=True):  # six seconds gone, of which a screening of 32 passes took five
        now[0] += 5.0
    assert (clock.budget.passes, clock.budget.screened, clock.elapsed()) == (32, 32, 6.0)
    # four seconds left at 5/32 s a pass: a two-lane step (forward and backward) fits, 32 more do not
    assert clock.allows(2, cost=2) == 2
    assert clock.allows(32) == math.floor(4.0 / (5.0 / 32)) < 32
    with clock.charge(2) as charge:  # a block that learns its backward passes as it runs
        charge.backward = 2
        now[0] += 0.5
    assert (clock.budget.forward, clock.budget.backward, clock.budget.passes) == (34, 2, 36)
    now[0] += 4.0  # the budget is spent
    assert clock.allows(1) == 0
    assert Clock(8, None).allows(5, cost=2) == 4 and Clock(8, None).allows(100) == 8


@pytest.mark.parametrize("method", BUILT_IN)
def test_every_method_stays_within_its_time_budget(method, tiny_objective, differentiable, file_view) -> None:
    started = time.perf_counter()
    settings = GradientSettings(steps=10_000) if method == "gradient" else None
    result = _run(
        tiny_objective,
        differentiable,
        [file_view],
        method=method,
        settings=settings,
        budget_passes=None,
        budget_seconds=1.5,
    )
    elapsed = time.perf_counter() - started
    view = result.views[0]
    batches = len({r.step for r in view.records})
    assert view.budget.forward == len(view.records)
    # a second batch is drawn unless the first took over half the budget (a loaded machine)
    assert batches >= 2 or view.budget.seconds > 1.5 / 2
    # a batch starts only while the previous batch's duration still fits in the budget
    assert view.budget.seconds <= 1.5 + 2 * elapsed / batches


@pytest.mark.parametrize(
    "method, settings",
    [
        ("hybrid", None),
        ("halving", None),
        ("halving", HalvingSettings(refine="local", local_views=4)),
        ("nevergrad", NevergradSettings("TwoPointsDE")),
        ("nevergrad", None),
        ("turbo", TurboSettings(init_views=8)),
    ],
)
def test_same_seed_gives_identical_trajectories(method, settings, tiny_objective, differentiable, file_view) -> None:
    runs = [
        _run(tiny_objective, differentiable, [file_view], method=method, settings=settings, budget_passes=20)
        for _ in range(2)
    ]
    assert trajectory_rows(runs[0]) == trajectory_rows(runs[1])
    # the whole budget, less what is left when a lane's step (at most 4 draws and a re-scoring) no longer fits
    assert 20 - 4 <= runs[0].views[0].budget.passes <= 20


def test_same_seed_gives_bit_identical_gradient_records(tiny_objective, differentiable, file_view) -> None:
    first, second = (
        _run(tiny_objective, differentiable, [file_view], settings=GradientSettings(steps=3)) for _ in range(2)
    )
    assert trajectory_rows(first) == trajectory_rows(second)


def test_the_warp_backend_gives_one_trajectory_per_seed_and_the_open3d_one(tiny_objective, file_view) -> None:
    warp = ExactRenderer(tiny_objective.renderer.scene, backend="warp")
    objective = Objective(tiny_objective.model, tiny_objective.loss, warp, PenaltyConfig())
    runs = [
        _run(
            objective,
            DifferentiableRenderer(warp, DiffRenderConfig()),
            [file_view],
            method="hybrid",
            budget_passes=20,
        )
        for _ in range(2)
    ]
    assert trajectory_rows(runs[0]) == trajectory_rows(runs[1])
    # the same search on Open3D's casts scores the views both evaluate alike (to the few pixels at
    # ties, edges and coplanar faces, that the two casters break differently); the refined lanes
    # then drift apart, as any two float orders of one search do
    reference = _run(
        tiny_objective,
        DifferentiableRenderer(tiny_objective.renderer, DiffRenderConfig()),
        [file_view],
        method="hybrid",
        budget_passes=20,
    )
    shared = [
        (ours, theirs)
        for ours, theirs in zip(runs[0].views[0].records, reference.views[0].records)
        if ours.params == theirs.params
    ]
    full_size = [(ours.l_depth, theirs.l_depth) for ours, theirs in shared if ours.scale == 1.0]
    assert len(full_size) >= 8
    np.testing.assert_allclose(*zip(*full_size), atol=2e-3)
    # a view screened at half size is 24 x 32: the two edge pixels its casts break differently are
    # 0.3% of it, which moves a model's L_depth more than that tolerance, so its renders are compared
    screened = [ours for ours, _ in shared if ours.scale != 1.0]
    assert screened
    for view in screened:
        size = scaled_size(H, W, view.scale)
        pose = view.world_T_cam(file_view.world_T_cam)[None]
        K = intrinsics_from_fov(file_view.fov_x_deg, *size)
        ours, theirs = (caster.render(pose, K, *size, supersample=2) for caster in (warp, tiny_objective.renderer))
        assert torch.equal(ours.mask, theirs.mask) and (ours.depth - theirs.depth).abs().max() < 1e-4
        assert ((ours.rgb - theirs.rgb).abs() > 1e-3).any(1).float().mean() < 0.01


def test_a_method_added_through_the_documented_route_runs(tiny_objective, differentiable, file_view) -> None:
    # the README's route: a Proposer subclass registered under a name, then attack.method=<name>
    @register_proposer("still_test")
    class Still(Proposer):
        def ask(self, count: int) -> torch.Tensor:
            return torch.zeros(min(count, 4), 6, dtype=torch.float64)

    result = _run(tiny_objective, differentiable, [file_view], method="still_test", budget_passes=9)
    assert len(result.views[0].records) == 9 and all(r.params == [0.0] * 6 for r in result.views[0].records)
    METHODS.pop("still_test")


@pytest.mark.parametrize(
    "overrides, key",
    [
        ({"settings": GradientSettings(steps=-1)}, "attack.gradient.steps"),
        ({"settings": GradientSettings(restarts=0)}, "attack.gradient.restarts"),
        ({"settings": GradientSettings(lr_rotation=0.0)}, "attack.gradient.lr_rotation"),
        ({"max_distance": -1.0}, "attack.max_distance"),
        ({"budget_passes": 0}, "attack.budget_passes"),
        ({"budget_passes": True}, "attack.budget_passes"),
        # the old name, whose count left screened views and backward passes out, names the new one
        ({"budget_evaluations": 48}, r"attack.budget_evaluations was renamed attack.budget_passes"),
    ],
)
def test_bad_settings_name_their_key(overrides, key) -> None:
    with pytest.raises(ValueError, match=key):
        AttackConfig("gradient", **overrides)


def test_bad_method_settings_name_their_key() -> None:
    with pytest.raises(ValueError, match=r"attack.nevergrad.optimizer.*NGOpt"):
        NevergradSettings("NoSuchOptimizer")
    with pytest.raises(ValueError, match=r"attack.method=random needs attack.budget_passes or attack.budget_seconds"):
        AttackConfig("random", budget_passes=None)


def _shown(monkeypatch) -> list[tuple[str, str]]:
    """What the attack's progress bars will show, recorded as (kind, text) pairs."""
    shown: list[tuple[str, str]] = []

    class Bar(tqdm):
        def set_description(self, desc=None, refresh=True):
            shown.append(("description", desc))
            super().set_description(desc, refresh)

        def set_postfix_str(self, s="", refresh=True):
            shown.append(("postfix", s))
            super().set_postfix_str(s, refresh)

        def set_postfix(self, ordered_dict=None, refresh=True, **kwargs):
            shown.append(("postfix", ",".join(f"{k}={v}" for k, v in kwargs.items())))
            super().set_postfix(ordered_dict, refresh, **kwargs)

    monkeypatch.setattr(driver, "tqdm", Bar)
    return shown


def test_the_progress_bar_forgets_the_previous_init_views_best(tiny_objective, differentiable, file_view, monkeypatch):
    shown = _shown(monkeypatch)
    _run(tiny_objective, differentiable, [file_view, file_view], method="random", budget_passes=6)
    second = shown.index(("description", "random attack, init view 2/2"))
    before = [value for kind, value in shown[:second] if kind == "postfix"]
    assert before and before[-1].startswith("loss=")  # init view 1 showed its best
    assert shown[second + 1] == ("postfix", "")  # and init view 2 starts without it


@pytest.mark.parametrize(("fidelity", "word"), [("auto", "scored"), (1, "screened")])
def test_the_progress_bar_calls_screened_only_the_cheap_views(
    tiny_objective, differentiable, file_view, monkeypatch, fidelity, word
) -> None:
    """The screening's count says "screened" as the budget's count does: at the cheap fidelity only
    (``auto`` under a pass budget scores exactly)."""
    shown = _shown(monkeypatch)
    settings = HalvingSettings(screen_supersample=fidelity, batch=4)
    result = _run(tiny_objective, differentiable, [file_view], method="halving", settings=settings, budget_passes=12)
    counts = [value for kind, value in shown if kind == "postfix" and value.split(" ")[0] in ("scored", "screened")]
    assert counts and all(value.startswith(f"{word} ") for value in counts)
    assert (result.views[0].budget.screened > 0) == (word == "screened")


def test_the_search_modules_import_each_other_in_one_direction() -> None:
    layers = ["registry", "search", "loop", "methods", "driver"]
    folder = Path(driver.__file__).parent
    for index, name in enumerate(layers[:3]):
        tree = ast.parse((folder / f"{name}.py").read_text())  # function-level imports included
        imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        imported |= {alias.name for n in ast.walk(tree) if isinstance(n, ast.Import) for alias in n.names}
        later = {f"kadv.attack.{layer}" for layer in layers[index + 1 :]}
        assert not {m for m in imported if any(m == x or m.startswith(f"{x}.") for x in later)}, name


def _lanes(records: list[ViewRecord]) -> dict[int, list[ViewRecord]]:
    lanes: dict[int, list[ViewRecord]] = {}
    for record in records:
        lanes.setdefault(record.restart, []).append(record)
    return lanes


def test_trust_region_steps_from_the_incumbent_undo_failures_and_restart_stalled_lanes(
    tiny_objective, differentiable, file_view
) -> None:
    """Replays each refined lane: every step leaves the lane's incumbent (never the view of a step
    that failed) with the step length the grow/shrink rule gives, so no incumbent falls; a lane
    whose step shrinks below stall_scale restarts from a screened view."""
    settings = HybridSettings(screen_fraction=0.4, screen_scale=1.0, population=8, refine_views=2, stall_scale=0.3)
    result = _run(tiny_objective, differentiable, [file_view], method="hybrid", settings=settings, budget_passes=40)
    view = result.views[0]
    screened = [r for r in view.records if r.step <= 2]
    refined = [r for r in view.records if r.step > 2]
    lanes = _lanes(refined)
    assert len(lanes) > 2  # some lane stalled and restarted under a new id
    screened_params = [r.params for r in screened]
    for lane in lanes.values():
        assert lane[0].params in screened_params  # a lane starts at a screened view, evaluated for its gradient
        incumbent, radius = lane[0], 1.0
        for record in lane[1:]:
            step = np.subtract(record.params[:3], incumbent.params[:3])
            assert float(np.linalg.norm(step)) == pytest.approx(settings.lr_rotation * radius, rel=1e-9)
            if record.rankable and record.objective > incumbent.objective:
                incumbent, radius = record, radius * settings.grow
            else:
                radius *= settings.shrink
            if radius < settings.stall_scale:  # the lane restarts elsewhere, or afresh here once none is left
                radius = 1.0
    path = [r.loss for r in view.path]
    assert path == sorted(path) and view.path[-1].loss == max(r.loss for r in view.records if r.rankable)


def test_cheap_gradient_lanes_take_a_step_only_once_the_exact_render_confirms_it(
    tiny_objective, differentiable, file_view
) -> None:
    """Replays each gradient lane of a search screening at one ray per pixel: the lanes step and
    take their gradients at that fidelity; exactly the trials that raise the lane's objective there
    are scored again exactly (a model pass each, counted), and a trial becomes the incumbent, its
    step growing, only if its exact objective beats the incumbent's."""
    settings = HalvingSettings(
        screen_fraction=0.25, screen_supersample=1, rescore_fraction=0.1, refine="gradient", lanes=2, stall_scale=0.3
    )
    with count_passes(tiny_objective.model) as count:
        result = _run(tiny_objective, differentiable, [file_view], (H, W), "halving", settings, budget_passes=60)
    view = result.views[0]
    assert count.forward == view.budget.forward == len(view.records) and count.passes == view.budget.passes <= 60
    refined = [r for r in view.records if r.step >= 4]
    trials, checks = [r for r in refined if r.screened], [r for r in refined if not r.screened]
    assert trials and checks  # some trials rose at the cheap fidelity and were checked
    # the trials went through the differentiable render (its warp's agreement), the checks did not
    assert all(not math.isnan(r.coverage) for r in trials) and all(math.isnan(r.coverage) for r in checks)
    exact_before = {tuple(r.params): r for r in view.records if r.step < 4 and r.rankable}
    lanes, validated, taken = settings.gradient_lanes(), 0, 0
    for lane in _lanes(refined).values():
        steps = [r for r in lane if r.screened]
        checked = {r.step: r for r in lane if not r.screened}
        incumbent, radius = steps[0], 1.0  # a lane starts at an exact view, rendered cheaply for its gradient
        level = incumbent.objective if incumbent.valid else -math.inf
        best = exact_before[tuple(incumbent.params)].objective
        for trial in steps[1:]:
            moved = float(np.linalg.norm(np.subtract(trial.params[:3], incumbent.params[:3])))
            assert moved == pytest.approx(lanes.lr_rotation * radius, rel=1e-9)
            rose = trial.valid and trial.objective > level
            assert (trial.step in checked) == rose  # checked exactly when, and only when, it rose cheaply
            if rose:
                validated += 1
                assert checked[trial.step].params == trial.params
            check = checked.get(trial.step)
            if rose and check.rankable and check.objective > best:
                incumbent, level, best, radius = trial, trial.objective, check.objective, radius * lanes.grow
                taken += 1
            else:
                radius *= lanes.shrink
            if radius < lanes.stall_scale:
                radius = 1.0
    assert validated == len(checks) and taken >= 1
    assert all(not r.screened for r in view.top + view.path)  # only exact views are chosen or followed
    K = intrinsics_from_fov(file_view.fov_x_deg, H, W)
    for record, supersample in ((trials[-1], 1), (checks[-1], differentiable.config.supersample)):
        pose = record.world_T_cam(file_view.world_T_cam)[None]  # the trial at one ray per pixel, the check exactly
        out = tiny_objective.renderer.render(pose, K, H, W, supersample=supersample)
        terms = tiny_objective(out.rgb, out.depth, out.mask, pose, K)
        assert float(terms.delta1[0]) == pytest.approx(record.delta1, abs=1e-6)


def test_gradient_steps_through_the_warp_are_screened_and_the_run_ends_on_an_exact_view(
    tiny_objective, file_view
) -> None:
    """render.differentiable.values=warp: the steps between refreshes are scored on the warp's
    values (screened, never chosen); the refreshes' views and the view each run ends on are scored
    on the exact render, within the same budget as through the exact render."""
    config = DiffRenderConfig(values="warp", refresh="every_k", every_k=3, layers=2)
    differentiable = DifferentiableRenderer(tiny_objective.renderer, config)
    settings = GradientSettings(steps=7, restarts=2)
    with count_passes(tiny_objective.model) as count:
        result = _run(tiny_objective, differentiable, [file_view], (H, W), "gradient", settings)
    view = result.views[0]
    assert count.passes == view.budget.passes == settings.restarts * (2 * settings.steps + 1)
    for lane in _lanes(view.records).values():
        steps = sorted(lane, key=lambda r: r.step)
        # refreshes at steps 0, 3 and 6; the last (7) validated exactly
        assert [r.step for r in steps if not r.screened] == [0, 3, 6, 7]
        assert all(r.screened == (not r.refreshed) for r in steps[:-1]) and not steps[-1].refreshed
    assert view.top and all(not r.screened for r in view.top)  # the path is the best run's every step
    K = intrinsics_from_fov(file_view.fov_x_deg, H, W)
    last = max(view.records, key=lambda r: (r.restart == 0, r.step))
    pose = last.world_T_cam(file_view.world_T_cam)[None]
    out = tiny_objective.renderer.render(pose, K, H, W, supersample=config.supersample)
    terms = tiny_objective(out.rgb, out.depth, out.mask, pose, K)
    assert float(terms.delta1[0]) == pytest.approx(last.delta1, abs=1e-6)


def test_screening_at_a_reduced_size_re_scores_its_best_views_at_full_size(
    tiny_objective, differentiable, file_view
) -> None:
    settings = HybridSettings(screen_fraction=0.5, screen_scale=0.5, population=8, refine_views=2)
    # half of 34 views screens: the init view at full size, then two batches of 8 at half size
    result = _run(tiny_objective, differentiable, [file_view], method="hybrid", settings=settings, budget_passes=34)
    view = result.views[0]
    small = [r for r in view.records if r.scale == 0.5]
    assert len(small) == 16 and view.init_record.scale == 1.0
    rescored = [r for r in view.records if r.scale == 1.0 and r.step == 3]
    # the re-scored views are the best separated screened ones, evaluated again at full size
    best = select_top_views([dataclasses.replace(r, scale=1.0) for r in small], len(rescored), 0.05, 3.0)
    assert [r.params for r in rescored] == [r.params for r in best] and len(rescored) == 8
    assert all(r.scale == 1.0 for r in view.top + view.path)  # only full-size views are chosen or followed
    assert any(a.l_depth != b.l_depth for a, b in zip(rescored, best))  # the sizes score differently


def test_trajectory_csv_reads_back_the_records_it_was_written_from(
    tiny_objective, differentiable, file_view, tmp_path
) -> None:
    result = _run(tiny_objective, differentiable, [file_view], method="hybrid", budget_passes=20)
    path = _write_csv(tmp_path / "trajectory.csv", trajectory_rows(result))
    written = [dataclasses.replace(r, seconds=math.nan) for r in result.views[0].records]
    assert repr(read_trajectory(path)) == repr({0: written})  # repr: NaN fields compare too


@pytest.mark.parametrize("method", BUILT_IN)
def test_every_method_keeps_its_chosen_views_inside_the_envelope(method, tiny_objective, differentiable, file_view):
    robot = ENVELOPES["robot"]  # roll 2 degrees, pitch 15 degrees, height 0.3 to 1.5 m
    result = _run(tiny_objective, differentiable, [file_view], (24, 32), method, budget_passes=12, envelope=robot)
    view = result.views[0]
    for record in view.records:
        inside = abs(record.roll_deg) <= 2 + 1e-5 and abs(record.pitch_deg) <= 15 + 1e-5
        assert inside or record.verdict in ("outside the envelope", "outside the scene", "inside an object")
    centres = torch.tensor([r.centre for r in view.records if r.valid], dtype=torch.float64)
    heights = robot.figures(tiny_objective.renderer, look_at(centres, centres + torch.tensor([1.0, 0.0, 0.0]))).height
    assert ((heights >= 0.3 - 1e-5) & (heights <= 1.5 + 1e-5)).all()  # nothing but the floor below, in the box room
    assert view.top and all(r.valid for r in view.top)


@pytest.mark.parametrize("method", BUILT_IN)
def test_every_method_moves_the_field_of_view_within_its_range_when_the_envelope_frees_it(
    method, tiny_objective, differentiable, file_view
) -> None:
    free_fov = Envelope("custom", fov_deg=(40.0, 100.0))
    result = _run(tiny_objective, differentiable, [file_view], (24, 32), method, budget_passes=24, envelope=free_fov)
    records = result.views[0].records
    assert records[0].params == [0.0] * 7 and records[0].fov_x_deg == file_view.fov_x_deg  # the init view's own
    assert all(len(r.params) == 7 and r.fov_x_deg == pytest.approx(file_view.fov_x_deg + r.params[6]) for r in records)
    assert all(40.0 - 1e-9 <= r.fov_x_deg <= 100.0 + 1e-9 for r in records)
    assert len({round(r.fov_x_deg, 6) for r in records}) > 2  # it moved
    # a fixed field of view stays the init view's, in six coordinates
    fixed = _run(tiny_objective, differentiable, [file_view], (24, 32), method, budget_passes=12).views[0].records
    assert all(len(r.params) == 6 and r.fov_x_deg == file_view.fov_x_deg for r in fixed)


def test_a_recorded_view_is_rendered_at_its_own_field_of_view(tiny_objective, differentiable, file_view) -> None:
    free_fov = Envelope("custom", fov_deg=(40.0, 100.0))
    result = _run(tiny_objective, differentiable, [file_view], (24, 32), "random", budget_passes=9, envelope=free_fov)
    record = max(result.views[0].records, key=lambda r: abs(r.params[6]))
    pose = record.world_T_cam(file_view.world_T_cam)[None]
    for fov, same in ((record.fov_x_deg, True), (file_view.fov_x_deg, False)):
        out = tiny_objective.renderer.render(pose, intrinsics_from_fov(fov, 24, 32), 24, 32, supersample=2)
        delta1 = float(tiny_objective(out.rgb, out.depth, out.mask, pose).delta1)
        assert (delta1 == pytest.approx(record.delta1, abs=1e-6)) == same


def test_an_init_view_outside_the_envelope_is_moved_into_it_or_refused(tiny_objective, file_view) -> None:
    renderer, margin = tiny_objective.renderer, PenaltyConfig().margin
    tilted = perturb_world_T_cam(
        file_view.world_T_cam[None], torch.tensor([[-0.9, 0.0, 0.3]]).double(), torch.zeros(1, 3)
    )
    init = dataclasses.replace(file_view, world_T_cam=tilted[0])
    moved = fit_into_envelope(renderer, init, ENVELOPES["upright"], margin)
    assert ENVELOPES["upright"].figures(renderer, moved.world_T_cam[None]).reasons() == [None]
    assert "moved into the envelope upright" in moved.note
    assert fit_into_envelope(renderer, moved, ENVELOPES["upright"], margin) is moved  # inside: left alone
    stilts = Envelope("stilts", height=(5.0, 6.0))  # above the box room's 3 m ceiling
    with pytest.raises(InitViewError, match=r"init view file0 lies outside the envelope stilts \(height 5 to 6 m\): "):
        fit_into_envelope(renderer, file_view, stilts, margin)


def test_halving_screens_at_one_ray_per_pixel_and_re_scores_its_best_views_exactly(
    tiny_objective, differentiable, file_view
) -> None:
    settings = HalvingSettings(screen_fraction=0.5, screen_supersample=1, rescore_fraction=0.25, lanes=2)
    result = _run(tiny_objective, differentiable, [file_view], (H, W), "halving", settings, budget_passes=20)
    view = result.views[0]
    screened = [r for r in view.records if r.screened and r.step == 2]
    # half the budget's passes screened over the bounds, each a pass like an exact view's; the lanes' draws too
    assert len(screened) == 10 and view.budget.screened == sum(r.screened for r in view.records)
    assert view.budget.passes == 20  # the last lane step draws fewer views to spend the budget whole
    assert not any(r.rankable for r in screened) and view.init_record.rankable
    rescored = [r for r in view.records if r.step == 3]
    best = select_top_views([dataclasses.replace(r, screened=False) for r in screened], 5, 0.05, 3.0)
    assert [r.params for r in rescored] == [r.params for r in best]  # the best separated screened views
    assert all(not r.screened for r in rescored)
    assert any(a.loss != b.loss for a, b in zip(rescored, best))  # one ray per pixel scores differently
    assert all(not r.screened for r in view.top + view.path)  # only exact views are chosen or followed
    # a screened view is one exact ray per pixel: its delta1 is what that render gives
    record = screened[0]
    pose = record.world_T_cam(file_view.world_T_cam)[None]
    K = intrinsics_from_fov(file_view.fov_x_deg, H, W)
    out = tiny_objective.renderer.render(pose, K, H, W, supersample=1)
    terms = tiny_objective(out.rgb, out.depth, out.mask, pose, K)
    assert float(terms.delta1[0]) == pytest.approx(record.delta1, abs=1e-9)


def test_auto_screening_is_exact_under_passes_and_cheap_under_seconds_where_the_render_outweighs_the_model() -> None:
    auto = HalvingSettings()
    assert auto.screen_supersample == "auto"
    assert screen_fidelity(auto, 2, None, render_s=1.0, model_s=0.01) is None  # passes: a cheap view costs one too
    assert screen_fidelity(auto, 2, 60.0, render_s=0.3, model_s=0.02) == 1  # render-bound: cheap views a second
    assert screen_fidelity(auto, 2, 60.0, render_s=0.3, model_s=2.3) is None  # network-bound: exact
    assert screen_fidelity(auto, 1, 60.0, render_s=0.3, model_s=0.02) is None  # nothing cheaper than the run's
    for fixed in (1, None):  # a fidelity set is kept
        assert screen_fidelity(HalvingSettings(screen_supersample=fixed), 2, None, 1.0, 0.01) == fixed


def test_the_default_search_scores_every_view_exactly_under_a_pass_budget(
    tiny_objective, differentiable, file_view
) -> None:
    view = _run(tiny_objective, differentiable, [file_view], (H, W), "halving", budget_passes=20).views[0]
    assert view.budget.passes == 20 and view.budget.screened == 0
    assert all(not r.screened for r in view.records) and not any(r.step == 3 for r in view.records)  # no re-score
    screening = [r for r in view.records if r.step == 2]
    assert len(screening) == 10 and all(r.rankable or not r.valid for r in screening)


@pytest.mark.parametrize("slow, screened", [("model", False), ("render", True)])
def test_the_default_search_under_a_seconds_budget_screens_cheaply_only_when_the_render_outweighs_the_model(
    slow, screened, tiny_objective, differentiable, file_view, monkeypatch
) -> None:
    # a part made 50 ms a view slower decides, whatever this machine's speeds of the other
    renderer = tiny_objective.renderer
    part, name = (tiny_objective.model, "forward") if slow == "model" else (renderer, "render")
    original = getattr(part, name)

    def slowed(*args, **kwargs):
        out = original(*args, **kwargs)
        views = out.shape[0] if isinstance(out, torch.Tensor) else out.rgb.shape[0]
        time.sleep(0.05 * views)
        return out

    monkeypatch.setattr(part, name, slowed)
    view = _run(
        tiny_objective, differentiable, [file_view], (H, W), "halving", budget_passes=None, budget_seconds=4.0
    ).views[0]
    assert (view.budget.screened > 0) is screened
    assert any(r.step == 3 for r in view.records) is screened  # the cheap screen's best re-scored exactly


def test_halving_starts_from_warm_starts_and_its_local_lanes_step_within_their_trust_regions(
    tiny_objective, differentiable, file_view
) -> None:
    starts = torch.tensor([[0.1, -0.05, 0.0, 0.1, 0.0, 0.05], [-0.2, 0.1, 0.0, 0.0, 0.0, -0.1]], dtype=torch.float64)
    settings = HalvingSettings(
        screen_supersample=1, refine="local", local_views=4, lanes=2, step_fraction=0.1, rescore_fraction=0.1
    )
    config = AttackConfig("halving", settings, budget_passes=40)
    result = attack(tiny_objective, differentiable, [file_view], H, W, config, 0, progress=False, starts={0: starts})
    view = result.views[0]
    first = [r for r in view.records if r.step == 1]
    np.testing.assert_allclose([r.params for r in first], starts.numpy())  # the warm starts, evaluated exactly
    assert all(not r.screened for r in first)
    half = config.space(file_view.fov_x_deg).box()[1].numpy()
    proposals = [r for r in view.records if r.step >= 4 and r.screened]
    exact = [r for r in view.records if r.step >= 4 and not r.screened]
    # four draws per lane and step, the last step fewer, each lane's best re-scored exactly
    assert proposals and exact and 4 * (len(exact) - 1) < len(proposals) <= 4 * len(exact)
    # every lane's step draws around its incumbent: no draw is further than 6 sigma of the widest region
    widest = settings.step_fraction / settings.stall_scale * settings.grow
    assert all(np.max(np.abs(np.asarray(r.params)) / half) < 1.0 + 6 * widest for r in proposals)


def test_halved_local_lanes_stop_the_lower_half_every_so_many_steps(tiny_objective, differentiable, file_view) -> None:
    settings = HalvingSettings(screen_supersample=None, local_views=3, lanes=4, halve_every=2)
    config = AttackConfig("halving", settings, budget_passes=100)
    view = attack(tiny_objective, differentiable, [file_view], H, W, config, 0, progress=False).views[0]
    assert view.budget.passes == 100
    drawn = collections.Counter(r.step for r in view.records if r.step >= 4)
    # the init view and 50 screened; four lanes of three draws for two steps, two for two more, then
    # one lane to the end, its last step one draw
    assert [drawn[step] for step in sorted(drawn)] == [12, 12, 6, 6, 3, 3, 3, 3, 1]


@pytest.mark.parametrize(
    "settings, budget, message",
    [
        (HalvingSettings(), 1, r"attack.budget_passes must be at least 2 for attack.halving"),
        (HalvingSettings(screen_supersample=1), 2, r"attack.budget_passes must be at least 3 for attack.halving"),
        (HalvingSettings(screen_supersample=2), 20, r"attack.halving.screen_supersample must be below"),
    ],
)
def test_halving_refuses_a_budget_too_small_for_its_screening_or_a_screening_as_fine_as_the_render(
    settings, budget, message, tiny_objective, differentiable, file_view
) -> None:
    with pytest.raises(ValueError, match=message):
        _run(tiny_objective, differentiable, [file_view], (H, W), "halving", settings, budget_passes=budget)


def test_the_default_search_runs_on_two_passes_the_floor_kadv_probe_takes(
    tiny_objective, differentiable, file_view
) -> None:
    # auto screens exactly under a pass budget: nothing to re-score, so the init view and one more
    view = _run(tiny_objective, differentiable, [file_view], method="halving", budget_passes=2).views[0]
    assert view.budget.passes == len(view.records) == 2 and not any(r.screened for r in view.records)


def test_halving_settings_out_of_range_name_their_key() -> None:
    with pytest.raises(ValueError, match=r"attack.budget_passes must be at least 2 for attack.halving"):
        AttackConfig("halving", budget_passes=1)  # refused when the config is made, before any work
    with pytest.raises(ValueError, match=r"attack.halving.refine must be 'gradient' or 'local', got 'adam'"):
        HalvingSettings(refine="adam")
    with pytest.raises(ValueError, match=r"attack.halving.halve_every must be an integer >= 0, got -1"):
        AttackConfig("halving", HalvingSettings(halve_every=-1))
    with pytest.raises(ValueError, match=r"attack.halving.halve_every applies to refine=local, got refine='gradient'"):
        HalvingSettings(refine="gradient", halve_every=2)
    with pytest.raises(ValueError, match=r"attack.halving.screen_fraction must be in \(0, 1\], got 1.5"):
        HalvingSettings(screen_fraction=1.5)
    with pytest.raises(ValueError, match=r"attack.halving.rescore_fraction must be in \(0, 1\], got 1.5"):
        AttackConfig("halving", HalvingSettings(rescore_fraction=1.5))
    with pytest.raises(
        ValueError, match=r"attack.halving.screen_supersample must be 'auto', an integer >= 1 or null, got 0"
    ):
        AttackConfig("halving", HalvingSettings(screen_supersample=0))


def test_a_nevergrad_meta_model_that_numpy_refuses_is_a_failure_its_optimizer_recovers_from(monkeypatch) -> None:
    # nevergrad 1.0.12 calls float() on a (1,)-shaped prediction, a TypeError under numpy 2.4, which
    # ended an NGOpt search of 240 views; kadv reports it as the MetaModelFailure NGOpt recovers from
    from nevergrad.optimization import metamodel, optimizerlib

    from kadv.attack.methods.nevergrad import _metamodel_type_errors_as_failures

    def refused(*args, **kwargs):  # what the meta-model's float() of a (1,) array raises under numpy 2.4
        raise TypeError("only 0-dimensional arrays can be converted to Python scalars")

    monkeypatch.setattr(optimizerlib, "learn_on_k_best", refused)
    with pytest.raises(TypeError):
        optimizerlib.learn_on_k_best()
    _metamodel_type_errors_as_failures()
    with pytest.raises(metamodel.MetaModelFailure, match="nevergrad's meta-model under this numpy"):
        optimizerlib.learn_on_k_best()
    guarded = optimizerlib.learn_on_k_best
    _metamodel_type_errors_as_failures()  # once only
    assert optimizerlib.learn_on_k_best is guarded


@pytest.mark.parametrize(
    "method, settings", [("halving", HalvingSettings(refine="gradient", lanes=3)), ("hybrid", None)]
)
def test_gradient_lanes_share_one_model_call_a_step(
    method, settings, tiny_objective, differentiable, file_view
) -> None:
    calls: list[tuple[int, bool]] = []  # (images, with a gradient) per call of the model
    hook = tiny_objective.model.register_forward_hook(
        lambda m, args, out: calls.append((len(args[0]), out.requires_grad))
    )
    try:
        result = _run(tiny_objective, differentiable, [file_view], method=method, settings=settings, budget_passes=40)
    finally:
        hook.remove()
    lanes = 3 if method == "halving" else HybridSettings().refine_views
    steps = [images for images, graded in calls if graded]
    # every step of the lanes is one call of the model on all of them (its backward pass one too)
    assert steps and set(steps) == {lanes}
    through_the_warp = {r.step for r in result.views[0].records if not math.isnan(r.coverage)}
    assert len(steps) == len(through_the_warp)  # one call per step of the lanes, no more


def test_turbo_closes_in_on_an_analytic_maximum_where_its_design_alone_does_not(
    tiny_objective, differentiable, file_view
) -> None:
    from kadv.attack.methods.turbo import TurboProposer

    config = AttackConfig("turbo", TurboSettings(init_views=8), budget_passes=None, budget_seconds=1.0)
    context = SearchContext(tiny_objective, differentiable, file_view, H, W, config)
    half = context.space.box()[1]
    target = torch.tensor([0.3, -0.2, 0.1, 0.4, 0.2, -0.3], dtype=torch.float64) * half

    def told(params: torch.Tensor) -> list[ViewRecord]:
        misses = ((params - target) / half).square().sum(dim=1)  # a smooth bowl in the unit box
        return _scored(params, (-misses).tolist())

    proposer = TurboProposer(context, np.random.default_rng(0))
    best = []
    for _ in range(14):
        params = proposer.ask(8)
        assert len(params) <= 8 and (params.abs() <= half + 1e-9).all()
        proposer.tell(told(params))
        best.append(float(proposer.y.max()))
    assert best == sorted(best)  # the best seen never falls
    # the design's best miss, then the process's: the trust region closes in on the bowl's bottom
    assert -best[-1] < 0.02 < -best[0]


@pytest.mark.parametrize("growth", [1.0, 1.25, 2.0])
def test_turbo_fits_its_process_again_once_the_views_have_grown_by_refit_growth(
    tiny_objective, differentiable, file_view, monkeypatch, growth
) -> None:
    import botorch.fit

    from kadv.attack.methods.turbo import TurboProposer

    fitted_on: list[int] = []  # the views each fit of the hyper-parameters saw
    fit = botorch.fit.fit_gpytorch_mll
    monkeypatch.setattr(
        botorch.fit, "fit_gpytorch_mll", lambda mll: fitted_on.append(len(mll.model.train_targets)) or fit(mll)
    )
    config = AttackConfig(
        "turbo", TurboSettings(init_views=8, refit_growth=growth), budget_passes=None, budget_seconds=1.0
    )
    proposer = TurboProposer(
        SearchContext(tiny_objective, differentiable, file_view, H, W, config), np.random.default_rng(0)
    )
    for _ in range(12):
        params = proposer.ask(8)
        proposer.tell(_scored(params, (-params.square().sum(dim=1)).tolist()))
    expected = [8]
    for views in range(12, len(proposer.y), 4):  # the process drawn before each batch of 4 after the design's 8
        if views >= growth * expected[-1]:
            expected.append(views)
    assert fitted_on == expected
    assert len(expected) == (11 if growth == 1.0 else 7 if growth == 1.25 else 3)


def test_turbo_refuses_a_trust_region_that_cannot_shrink_to_its_restart_in_one_line() -> None:
    with pytest.raises(
        ValueError, match=r"^attack.turbo needs 0 < length_min < length_init <= length_max, got 0.9, 0.8, 1.6$"
    ):
        TurboSettings(length_min=0.9)
    with pytest.raises(ValueError, match=r"^attack.turbo.candidates must be at least attack.turbo.batch \(4\), got 2$"):
        TurboSettings(candidates=2)
    with pytest.raises(ValueError, match=r"^attack.turbo.refit_growth must be at least 1, got 0.5$"):
        TurboSettings(refit_growth=0.5)


def test_turbo_scores_its_warm_starts_first(tiny_objective, differentiable, file_view) -> None:
    start = torch.tensor([[0.0, 0.1, 0.0, 0.05, 0.0, 0.0], [0.0, -0.1, 0.0, 0.0, 0.0, 0.05]], dtype=torch.float64)
    config = AttackConfig("turbo", TurboSettings(init_views=4), budget_passes=9)
    result = attack(
        tiny_objective, differentiable, [file_view], H, W, config, seed=0, progress=False, starts={0: start}
    )
    first = [r.params for r in result.views[0].records if r.step == 1]
    assert torch.allclose(torch.tensor(first[:2], dtype=torch.float64), start)  # inside the bounds: taken as they are
    assert len(first) == 6 and result.views[0].budget.passes == 9  # the starts, then the design, then one batch of 2
