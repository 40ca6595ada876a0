"""The embedded models: shipped weights that load offline and predict a room's structure."""
from __future__ import annotations

import pytest
import torch

from kadv.losses import depth_metrics
from kadv.models import load_model
from kadv.models.huggingface import HuggingFaceDepthModel
from kadv.models.tiny_dpt import TINY_DPT_DIR
from kadv.render import DifferentiableRenderer, ExactRenderer
from kadv.scenes import procedural_room

EMBEDDED = ("kadv_tiny", "kadv_tiny_dpt")


@pytest.fixture(scope="module")
def room_view():
    scene = procedural_room(seed=11)  # a room no training run drew (they use seeds 0 and 1 times 100003, plus i)
    camera = scene.cameras[0]
    renderer = ExactRenderer(scene)
    return renderer, camera, renderer.render(camera.world_T_cam, camera.intrinsics(90, 120), 90, 120, supersample=2)


@pytest.mark.parametrize("name", EMBEDDED)
def test_loads_offline_and_keeps_the_input_size(name: str, monkeypatch, tmp_path) -> None:
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_HOME", str(tmp_path / "empty_cache"))
    model = load_model(name)
    assert model.output_kind == "disparity" and not any(p.requires_grad for p in model.parameters())
    for shape in ((1, 3, 90, 120), (2, 3, 77, 131)):
        assert model(torch.rand(shape)).shape == (shape[0], 1, *shape[2:])


def test_the_dpt_goes_through_the_hugging_face_adapter() -> None:
    model = load_model("kadv_tiny_dpt")
    assert isinstance(model, HuggingFaceDepthModel) and type(model.network).__name__ == "DPTForDepthEstimation"
    assert (TINY_DPT_DIR / "config.json").is_file() and (TINY_DPT_DIR / "preprocessor_config.json").is_file()
    shipped = sum(path.stat().st_size for path in TINY_DPT_DIR.iterdir())
    assert shipped < 5e6


@pytest.mark.parametrize("name", EMBEDDED)
def test_predicts_the_structure_of_an_unseen_room(name: str, room_view) -> None:
    _, _, out = room_view
    with torch.no_grad():
        delta1 = depth_metrics(load_model(name)(out.rgb), out.depth, out.mask)["delta1"]
    assert float(delta1) > 0.8


@pytest.mark.parametrize("name", EMBEDDED)
def test_a_pose_gradient_comes_back_through_the_model(name: str, room_view) -> None:
    renderer, camera, _ = room_view
    model = load_model(name)
    params = torch.zeros(1, 6, dtype=torch.float64, requires_grad=True)
    view = DifferentiableRenderer(renderer)(params, camera.world_T_cam[None], camera.intrinsics(90, 120), 90, 120)
    prediction = model(view.rgb.float())
    (prediction * torch.linspace(0, 1, 120)).mean().backward()
    assert params.grad is not None and torch.isfinite(params.grad).all() and params.grad.abs().sum() > 0
