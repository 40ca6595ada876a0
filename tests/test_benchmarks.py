"""The benchmark scripts' own stand-ins keep up with what the library asks of the parts they replace."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest
import torch

from kadv.attack import AttackConfig, GradientSettings, Study, StudySettings, attack, file_init_views
from kadv.geometry import intrinsics_from_fov
from kadv.losses import LossConfig
from kadv.models import load_model
from kadv.scenes import box_room

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture
def attack_step(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    return importlib.import_module("attack_step")


def test_a_gradient_run_on_attack_step_s_fixed_render_sees_its_one_render_at_every_pose(attack_step) -> None:
    """``benchmarks/attack_step.py`` times a step without its render by handing the attack a
    stand-in (``FixedRender``) that returns one render's output at every pose: the whole run goes
    through (every call the attack makes of a differentiable renderer is there) and every view it
    scores is that render."""
    height, width = 24, 32
    settings = StudySettings(size=(height, width), loss=LossConfig(kind="ssim"))
    study = Study.build(box_room(seed=0), load_model("kadv_tiny"), settings)
    view = file_init_views(study.renderer, settings.penalty.margin)[0]
    K = intrinsics_from_fov(view.fov_x_deg, height, width)
    output = study.differentiable(torch.zeros(1, 6, dtype=torch.float64), view.world_T_cam[None], K, height, width)
    fixed = attack_step.FixedRender(study.differentiable, output)
    config = AttackConfig("gradient", GradientSettings(steps=3, restarts=1), budget_passes=None)
    result = attack(study.objective, fixed, [view], height, width, config, 0, progress=False)
    records = result.views[0].records
    assert len(records) >= 4
    assert len({round(record.delta1, 9) for record in records}) == 1
