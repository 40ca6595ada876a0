from __future__ import annotations

import pytest

from kadv import DifferentiableRenderer, ExactRenderer, box_room, load_model
from kadv.attack import Objective, PenaltyConfig, file_init_views
from kadv.losses import depth_loss
from kadv.render import DiffRenderConfig


@pytest.fixture(scope="session")
def tiny_objective() -> Objective:
    renderer = ExactRenderer(box_room(seed=0))
    return Objective(load_model("kadv_tiny"), depth_loss("ssim"), renderer, PenaltyConfig())


@pytest.fixture()
def differentiable(tiny_objective: Objective) -> DifferentiableRenderer:
    return DifferentiableRenderer(tiny_objective.renderer, DiffRenderConfig())


@pytest.fixture(scope="session")
def file_view(tiny_objective: Objective):
    return file_init_views(tiny_objective.renderer, PenaltyConfig().margin)[0]
