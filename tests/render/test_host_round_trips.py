"""The exact render reads nothing back to the host: on Warp's backend, on its CPU device and on CUDA,
a render of a batch of views and the model's forward pass on it run under a guard that fails on any
host round trip; and a batch split by ``max_rays`` renders as one."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import numpy as np
import pytest
import torch

from kadv import ExactRenderer, box_room, load_model, look_at
from kadv.geometry import intrinsics_from_fov
from kadv.render import BakeConfig, Shading
from kadv.scenes import Emitters

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
H, W = 24, 32
_READS = ("numpy", "__array__", "item", "tolist")
_CONVERSIONS = ("from_numpy", "as_tensor", "tensor")


@contextmanager
def no_host_round_trips(device: str) -> Iterator[None]:
    """Fail on any read of a tensor's values into the host (``Tensor.numpy``, ``__array__``,
    ``.item()``, ``.tolist()``) and on any numpy array turned into a tensor; on CUDA, on any call
    that waits for the device (``torch.cuda.set_sync_debug_mode("error")``)."""

    def refuse(name: str, original=None):
        def refused(*args, **kwargs):
            if original is not None and not any(isinstance(a, np.ndarray) for a in args):
                return original(*args, **kwargs)
            raise AssertionError(f"a host round trip inside the step: {name}")

        return refused

    reads = {name: getattr(torch.Tensor, name) for name in _READS}
    conversions = {name: getattr(torch, name) for name in _CONVERSIONS}
    for name in _READS:
        setattr(torch.Tensor, name, refuse(f"Tensor.{name}"))
    for name, original in conversions.items():
        setattr(torch, name, refuse(f"torch.{name} of a numpy array", None if name == "from_numpy" else original))
    if device == "cuda":
        torch.cuda.set_sync_debug_mode("error")
    try:
        yield
    finally:
        if device == "cuda":
            torch.cuda.set_sync_debug_mode("default")
        for name, original in reads.items():
            setattr(torch.Tensor, name, original)
        for name, original in conversions.items():
            setattr(torch, name, original)


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


def _lit_room(tmp_path) -> tuple[Emitters, Shading]:
    """Baked lighting of a box room lit by every kind of emitter: a sky, an area lamp (seen by the
    camera), a point light, a spot and a sun (shaded per hit, with shadow rays)."""
    lamp = np.array([[[1.5, 2.9, 1.5], [2.5, 2.9, 1.5], [2.5, 2.9, 2.5]]])
    emitters = (
        Emitters(sky_radiance=np.full(3, 0.2))
        .area(lamp, np.full((1, 3), 4.0))
        .point(np.array([2.0, 2.0, 2.0]), np.full(3, 3.0))
        .spot(np.array([1.0, 2.5, 1.0]), np.full(3, 5.0), np.array([0.0, -1.0, 0.0]), 30.0, 20.0)
        .sun(np.array([0.3, 1.0, 0.2]), np.full(3, 2.0))
    )
    return emitters, Shading(lighting="baked", bake=BakeConfig(texel=1.0, rays=8, bounces=1, cache=str(tmp_path)))


@pytest.mark.parametrize("device", DEVICES)
def test_a_warp_render_and_the_models_forward_pass_read_nothing_back_to_the_host(device: str, tmp_path) -> None:
    emitters, shading = _lit_room(tmp_path)
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
    emitters, shading = _lit_room(tmp_path)
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
