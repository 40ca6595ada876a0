"""The exact render reads nothing back to the host: on Warp's backend, on its CPU device and on CUDA,
a render of a batch of views and the model's forward pass on it run under a guard that fails on any
host round trip; and a batch split by ``max_rays`` renders as one."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from kadv import ExactRenderer, box_room, load_model, look_at
from kadv.geometry import intrinsics_from_fov
from tests.round_trips import DEVICES, lit_room_emitters, no_host_round_trips

H, W = 24, 32


def test_the_guard_fails_on_each_kind_of_round_trip() -> None:
    tensor = torch.ones(3)
    for leak in (
        lambda: tensor.numpy(),
        lambda: tensor.tolist(),
        lambda: tensor.sum().item(),
        lambda: np.asarray(tensor),
        lambda: torch.from_numpy(np.ones(3)),
        lambda: torch.as_tensor(np.ones(3)),
    ):
        with pytest.raises(AssertionError, match="host round trip"), no_host_round_trips("cpu"):
            leak()
    with no_host_round_trips("cpu"):
        assert (torch.as_tensor(tensor) * 2).sum() > 0  # tensors themselves pass
    assert tensor.tolist() == [1.0, 1.0, 1.0]  # and everything is restored after


@pytest.mark.parametrize("device", DEVICES)
def test_a_warp_render_and_the_models_forward_pass_read_nothing_back_to_the_host(device: str, tmp_path) -> None:
    emitters, shading = lit_room_emitters(str(tmp_path))
    scene = replace(box_room(seed=0), emitters=emitters)
    renderer = ExactRenderer(scene, shading, progress=False, backend="warp", device=device)
    model = load_model("kadv_tiny").to(device)
    eyes = torch.tensor([[1.0, 1.5, 1.0], [3.0, 1.2, 3.2], [1.2, 2.0, 3.0]])
    poses = look_at(eyes, torch.tensor([[3.0, 1.0, 3.0], [1.0, 2.8, 1.0], [3.0, 1.0, 1.0]])).double()
    K = intrinsics_from_fov(70.0, H, W)
    first = renderer.render(poses, K, H, W, supersample=2)  # kernels compiled, tables uploaded
    with no_host_round_trips(device), torch.no_grad():
        out = renderer.render(poses, K, H, W, supersample=2)
        prediction = model(out.rgb)
    assert out.rgb.device.type == device and prediction.device.type == device
    assert prediction.shape == (3, 1, H, W) and out.mask.all()
    torch.testing.assert_close(out.rgb, first.rgb, rtol=0, atol=0)  # one render, bit for bit
    # the area lamp is seen (its tone-mapped glow, brighter than any wall) from the view below it
    assert float(out.rgb[1].amax()) > 0.9
    # and the same views on the CPU's default path agree with it (depth bit for bit where ids agree)
    reference = ExactRenderer(scene, shading, progress=False, backend="open3d").render(poses, K, H, W, 2)
    out = out.to("cpu")
    same = out.triangle_ids == reference.triangle_ids
    assert same.float().mean() >= 0.999
    assert ((out.rgb - reference.rgb).abs() <= 2 / 255).all(dim=1).float().mean() >= 0.99


def test_a_batch_split_by_max_rays_renders_as_one(tmp_path) -> None:
    emitters, shading = lit_room_emitters(str(tmp_path))
    scene = replace(box_room(seed=0), emitters=emitters)
    eyes = torch.tensor([[1.0, 1.5, 1.0], [3.0, 1.2, 3.2], [1.2, 2.0, 3.0]])
    poses = look_at(eyes, torch.tensor([[3.0, 1.0, 3.0], [1.0, 2.8, 1.0], [3.0, 1.0, 1.0]])).double()
    K = intrinsics_from_fov(70.0, H, W)
    whole = ExactRenderer(scene, shading, progress=False).render(poses, K, H, W, supersample=2)
    # 1000 rays at once: the pixel-centre rays in three parts, the sub-pixel rays in ten, none on a view's edge
    parts = ExactRenderer(scene, shading, progress=False, max_rays=1000).render(poses, K, H, W, supersample=2)
    for name in ("depth", "mask", "normals", "triangle_ids", "points", "back_face"):
        assert torch.equal(getattr(parts, name), getattr(whole, name)), name
    # colours to float32 rounding: torch's CPU kernels compute a tensor's last few elements (its
    # tail after whole SIMD vectors) with scalar code, whose exp and pow round differently
    torch.testing.assert_close(parts.rgb, whole.rgb, rtol=0, atol=1e-6)
    with pytest.raises(ValueError, match=r"render\.max_rays must be a positive number of rays, got 0"):
        ExactRenderer(scene, max_rays=0)
