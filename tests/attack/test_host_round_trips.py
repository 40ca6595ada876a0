"""Whole gradient attack steps read nothing back to the host: on Warp's backend, on its CPU device
(and on CUDA, under ``torch.cuda.set_sync_debug_mode("error")``), every step of a batched Adam run
(differentiable render with edges searched pair by pair, model, loss, penalty, validity, backward,
update, step guard) runs under a guard that fails on any host round trip, and gives the records an
unguarded run gives."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import pytest
import torch
from tqdm import tqdm

from kadv import ExactRenderer, box_room, load_model, look_at
from kadv.attack import (
    AttackConfig,
    GradientSettings,
    InitView,
    Objective,
    PenaltyConfig,
    SearchContext,
    gradient_ascent,
)
from kadv.losses import depth_loss
from kadv.render import DifferentiableRenderer, DiffRenderConfig
from tests.round_trips import DEVICES, lit_room_emitters, no_host_round_trips

H, W = 24, 32
STEPS = 3


def _run(objective: Objective, view: InitView, start: torch.Tensor, guarded: str | None) -> list:
    """The records of a gradient run of STEPS steps from ``start`` (R, 6), its steps under the guard
    on device ``guarded`` (None: unguarded); the records are read once the run has ended."""
    config = AttackConfig("gradient", GradientSettings(steps=STEPS, restarts=len(start)), budget_evaluations=None)
    # edges found without compacting: a compacted search waits for its counts on a GPU
    config_render = DiffRenderConfig(edge_search="every_pair")
    differentiable = DifferentiableRenderer(objective.renderer, config_render, objective.device)
    context = SearchContext(objective, differentiable, view, H, W, config)
    settings = config.settings
    with tqdm(disable=True) as bar:
        if guarded is None:
            measures = gradient_ascent(context, start, STEPS, settings.lr_rotation, settings.lr_translation, bar)
        else:
            # Adam keeps its step count on the host (torch's design, on every device): it reads no device
            with no_host_round_trips(guarded, allow=((torch.optim.Adam, "step"),)):
                measures = gradient_ascent(context, start, STEPS, settings.lr_rotation, settings.lr_translation, bar)
    # the clock's seconds differ between runs; everything else must not
    return [replace(record, seconds=0.0) for step in measures for record in step.records()]


@pytest.mark.parametrize("device", DEVICES)
def test_gradient_attack_steps_read_nothing_back_to_the_host(device: str, tmp_path) -> None:
    emitters, shading = lit_room_emitters(str(tmp_path))
    scene = replace(box_room(seed=0), emitters=emitters)
    renderer = ExactRenderer(scene, shading, progress=False, backend="warp", device=device)
    objective = Objective(load_model("kadv_tiny"), depth_loss("ssim"), renderer, PenaltyConfig(), device=device)
    pose = look_at(torch.tensor([1.0, 1.4, 1.0]), torch.tensor([3.0, 1.0, 3.5])).double()
    view = InitView("corner", "file", pose, 70.0)
    # two restarts: the init view, and one turned and moved 20 cm towards the wall x = 0
    start = torch.tensor([[0.0] * 6, [0.05, -0.03, 0.02, -0.2, 0.0, 0.0]], dtype=torch.float64)
    reference = _run(objective, view, start, None)
    records = _run(objective, view, start, device)
    if device == "cpu":
        assert records == reference  # the guarded steps are the steps, bit for bit
    else:  # CUDA's atomic sums reorder from run to run: the same run, to rounding
        assert [(r.step, r.restart, r.verdict) for r in records] == [(r.step, r.restart, r.verdict) for r in reference]
        numbers = [[r.l_depth, r.loss, r.objective, r.abs_rel, *r.params, *r.centre] for r in records]
        expected = [[r.l_depth, r.loss, r.objective, r.abs_rel, *r.params, *r.centre] for r in reference]
        torch.testing.assert_close(torch.tensor(numbers), torch.tensor(expected), rtol=1e-4, atol=1e-5)
        delta1 = torch.tensor([[r.delta1 for r in run] for run in (records, reference)])
        assert (delta1[0] - delta1[1]).abs().max() <= 2 / (H * W)  # a pixel or two either side of 1.25
    assert len(records) == 2 * (STEPS + 1) and {r.step for r in records} == set(range(STEPS + 1))
    # the steps moved the cameras, and everything a record holds was measured
    assert records[-1].params != records[1].params and records[-2].params != records[0].params
    assert all(r.verdict == "valid" and r.refreshed for r in records)
    fields = ("l_depth", "loss", "objective", "delta1", "abs_rel", "coverage", "rgb_error", "depth_error")
    assert all(torch.isfinite(torch.tensor([getattr(r, f) for f in fields])).all() for r in records)
    assert all(0.0 <= r.guard_fraction <= 1.0 for r in records)
    assert dataclasses.asdict(records[0])["params"] == [0.0] * 6
