from __future__ import annotations

from pathlib import Path

import pytest
import torch

from kadv.models import TinyDepthNet, load_kadv_tiny, load_model, save_kadv_tiny
from kadv.models.tiny import TINY_METRIC_WEIGHTS, TINY_WEIGHTS


def test_shipped_weights_are_small_and_load_without_network(monkeypatch) -> None:
    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    assert TINY_WEIGHTS.stat().st_size <= 15 * 2**20
    model = load_model("kadv_tiny")
    assert model.output_kind == "disparity" and not model.training
    assert not any(p.requires_grad for p in model.parameters())


@pytest.mark.parametrize("size", [(64, 64), (90, 160), (37, 53)])
def test_output_size_and_input_gradient(size) -> None:
    model = load_kadv_tiny()
    rgb = torch.rand(2, 3, *size, requires_grad=True)
    out = model(rgb)
    assert out.shape == (2, 1, *size) and (out > 0).all()
    out.mean().backward()
    assert torch.isfinite(rgb.grad).all() and rgb.grad.abs().sum() > 0


def test_save_load_round_trip(tmp_path: Path) -> None:
    torch.manual_seed(0)
    network = TinyDepthNet((8, 8, 16, 16, 16))
    path = save_kadv_tiny(network, tmp_path / "w.safetensors", metadata={"note": "test"})
    first, second = load_kadv_tiny(path), load_kadv_tiny(path)
    rgb = torch.rand(1, 3, 64, 96)
    assert torch.equal(first(rgb), second(rgb))
    assert first.network.channels == (8, 8, 16, 16, 16)


def test_missing_weights_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="kadv-train-tiny"):
        load_kadv_tiny(tmp_path / "none.safetensors")


def test_kadv_tiny_metric_ships_loads_offline_and_predicts_metric_depth_on_a_box_room(monkeypatch) -> None:
    from kadv import ExactRenderer, box_room
    from kadv.geometry import intrinsics_from_fov
    from kadv.losses import depth_metrics

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    assert TINY_METRIC_WEIGHTS.stat().st_size <= 15 * 2**20
    model = load_model("kadv_tiny_metric")
    assert model.output_kind == "depth" and model.name == "kadv_tiny_metric"
    renderer = ExactRenderer(box_room(seed=3))  # a box room no training run drew
    K = intrinsics_from_fov(70.0, 96, 128)
    out = renderer.render(renderer.scene.cameras[0].world_T_cam, K, 96, 128)
    with torch.no_grad():
        prediction = model(out.rgb, K)
    # in metres as predicted: the median ratio to the truth near 1, most pixels right unaligned
    ratio = (prediction / out.depth.clamp_min(1e-3))[out.mask].median()
    assert 0.75 < float(ratio) < 1.33
    assert float(depth_metrics(prediction, out.depth, out.mask, "depth", alignment="none")["delta1"]) > 0.5
    # kadv-tiny's weights predict relative disparity: refused as the metric model's
    with pytest.raises(ValueError, match="predict disparity"):
        load_kadv_tiny(TINY_WEIGHTS, "depth")
