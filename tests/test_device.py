"""kadv.device and the device placement of the differentiable renderer and the objective.

The placement tests run on every device this machine has: the CPU, and CUDA where present.
"""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from kadv import DifferentiableRenderer, ExactRenderer, box_room, load_model, look_at
from kadv.attack import Objective, PenaltyConfig
from kadv.datasets import render_procedural_views
from kadv.device import resolve_device
from kadv.geometry import intrinsics_from_fov
from kadv.losses import depth_loss
from kadv.models import KadvTiny, TinyDepthNet
from kadv.training.tiny import TinyTrainConfig, fit

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
H, W = 48, 64


def test_auto_is_cuda_exactly_when_cuda_is_available() -> None:
    assert resolve_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    assert resolve_device("cpu") == torch.device("cpu")


@pytest.mark.parametrize("name", ["tpu", "gpu", "cuda:x"])
def test_unknown_devices_are_refused(name: str) -> None:
    with pytest.raises(ValueError, match="device="):
        resolve_device(name)


def test_cuda_without_cuda_is_refused_with_what_to_use() -> None:
    if torch.cuda.is_available():
        with pytest.raises(ValueError, match="only"):
            resolve_device(f"cuda:{torch.cuda.device_count()}")
    else:
        with pytest.raises(ValueError, match="no CUDA device"):
            resolve_device("cuda")


@pytest.fixture(scope="module")
def renderer() -> ExactRenderer:
    return ExactRenderer(box_room(seed=0))


def _step(renderer: ExactRenderer, device: str) -> tuple:
    pose = look_at(torch.tensor([1.0, 1.5, 1.0]), torch.tensor([3.0, 1.0, 3.0])).double()[None].expand(2, 4, 4)
    params = torch.tensor([[0.0] * 6, [0.02, -0.01, 0.0, 0.05, 0.0, -0.03]], dtype=torch.float64, requires_grad=True)
    differentiable = DifferentiableRenderer(renderer, device=device)
    objective = Objective(load_model("kadv_tiny"), depth_loss("ssim"), renderer, PenaltyConfig(), device=device)
    out = differentiable(params, pose, intrinsics_from_fov(70.0, H, W), H, W)
    terms = objective(out.rgb, out.depth, out.mask, out.world_T_cam)
    terms.objective.sum().backward()
    return out, terms, params.grad


@pytest.mark.parametrize("device", DEVICES)
def test_render_and_objective_run_on_the_device_and_agree_with_the_cpu(renderer: ExactRenderer, device: str) -> None:
    out, terms, grad = _step(renderer, device)
    assert out.rgb.device.type == device and out.depth.device.type == device and out.mask.device.type == device
    # the exact render stays on the renderer's device, the poses where the pose parameters are, and
    # the objective's terms on its device: nothing comes back to the host
    assert out.exact.rgb.device.type == renderer.device.type and out.world_T_cam.device.type == "cpu"
    assert terms.objective.device.type == device and terms.prediction.device.type == device
    reference_out, reference_terms, reference_grad = _step(renderer, "cpu")
    torch.testing.assert_close(out.rgb.cpu(), reference_out.rgb, atol=1e-5, rtol=0)
    torch.testing.assert_close(terms.l_depth.cpu(), reference_terms.l_depth, atol=1e-4, rtol=1e-4)
    assert torch.isfinite(grad).all() and grad.abs().sum() > 0
    # the CPU run is deterministic; CUDA reorders float sums, so its gradient agrees closely
    torch.testing.assert_close(grad, reference_grad, atol=1e-6, rtol=1e-2 if device == "cuda" else 0)


@pytest.mark.parametrize("device", DEVICES)
def test_training_runs_on_the_device_and_hands_back_a_cpu_model_that_agrees_with_the_cpu(
    device: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # full float32 convolutions on the GPU: with TF32 ones (cuDNN's default on Ampere and later) the
    # losses of a run of three steps part from the CPU's by 2% (H200, 2026-11-26); matrix products
    # are full float32 by default
    monkeypatch.setattr(torch.backends.cudnn, "allow_tf32", False)
    views = render_procedural_views(4, seed=3, height=32, width=40, progress=False)
    config = TinyTrainConfig(steps=3, batch_size=2, channels=(8, 8, 8, 8, 8))
    runs = []
    for where in ("cpu", device):
        torch.manual_seed(0)
        model = KadvTiny(TinyDepthNet(config.channels))
        losses = fit(model, views, replace(config, device=where), progress=False)
        runs.append((losses, torch.cat([p.flatten() for p in model.network.parameters()])))
    (cpu_losses, cpu_weights), (losses, weights) = runs
    assert weights.device.type == "cpu" and not weights.requires_grad
    # the same batches everywhere; on CUDA the sums run in another order
    assert losses == pytest.approx(cpu_losses, rel=1e-3) and torch.allclose(weights, cpu_weights, atol=1e-4)
