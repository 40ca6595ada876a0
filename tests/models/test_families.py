"""Every transformers depth family, proven from a tiny random checkpoint saved with save_pretrained
and loaded through load_model: it predicts what transformers' own processor + model +
post-processing predict, a pose gradient moves the camera through it, and its output kind holds
on the box room, where near and far are known."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
import torch.nn.functional as F
from transformers import AutoImageProcessor, AutoModelForDepthEstimation

from kadv import DifferentiableRenderer, ExactRenderer, load_model
from kadv.attack import (
    AttackConfig,
    GradientSettings,
    Objective,
    PenaltyConfig,
    attack,
    file_init_views,
)
from kadv.geometry import intrinsics_from_fov
from kadv.losses import depth_loss, depth_metrics
from tests.models.tiny_families import FAMILIES, save_family

H, W = 60, 80  # not a multiple of any family's patch, so every sizing rule acts
# transformers' PIL-backend processors (DPT, Depth Anything, GLPN) round the resized image to 8
# bits, half a level at most, which a random network amplifies at a few pixels: their mean and
# largest differences are bounded relative to the prediction's range. The torch-only paths
# (ZoeDepth, DepthPro, TIPSv2, DPT-DINOv2 without resizing) agree to float rounding.
PIL_MEAN, PIL_MAX, TORCH_RELATIVE = 0.005, 0.06, 1e-4


@dataclass(frozen=True)
class View:
    rgb: torch.Tensor  # (1, 3, H, W), 8-bit levels as a float image
    depth: torch.Tensor  # (1, 1, H, W) metres
    mask: torch.Tensor
    K: torch.Tensor  # (1, 3, 3)


@pytest.fixture(scope="module")
def view(room) -> View:
    renderer = ExactRenderer(room)
    init = file_init_views(renderer, PenaltyConfig().margin)[0]
    K = intrinsics_from_fov(init.fov_x_deg, H, W)[None]
    out = renderer.render(init.world_T_cam[None], K, H, W)
    return View((out.rgb * 255).round() / 255, out.depth.double(), out.mask, K)


@pytest.fixture(scope="module", params=sorted(FAMILIES))
def family(request, tmp_path_factory) -> tuple[str, Path]:
    return request.param, save_family(request.param, tmp_path_factory.mktemp(request.param))


def _restated(name: str, network: torch.nn.Module, rgb: torch.Tensor, K: torch.Tensor | None) -> torch.Tensor:
    """DepthPro's and TIPSv2's processors need torchvision (no CPU build): their steps, restated
    from transformers' source in plain torch (tvF.resize on a float tensor is F.interpolate)."""
    if name == "depth_pro":  # normalise, then resize to the fixed square without antialiasing
        x = F.interpolate((rgb - 0.5) / 0.5, (128, 128), mode="bilinear", align_corners=False)
        out = network(pixel_values=x)
        focal = K[0, 0, 0] if K is not None else 0.5 * W / torch.tan(0.5 * torch.deg2rad(out.field_of_view[0]))
        inverse = F.interpolate(out.predicted_depth[:, None] * W / focal, (H, W), mode="bilinear")
        return 1.0 / inverse[0, 0].clamp(1e-4, 1e4)
    x = F.interpolate(rgb, (56, 56), mode="bilinear", align_corners=False, antialias=True)  # tipsv2_dpt
    return F.interpolate(network(pixel_values=x).predicted_depth[:, None], (H, W), mode="bilinear")[0, 0]


def _reference(name: str, directory: Path, rgb: torch.Tensor, K: torch.Tensor | None) -> torch.Tensor:
    """The (H, W) prediction of transformers' own processor, model and post-processing."""
    network = AutoModelForDepthEstimation.from_pretrained(directory).eval()
    if not FAMILIES[name].processor_runs:
        return _restated(name, network, rgb, K)
    processor = AutoImageProcessor.from_pretrained(directory)
    inputs = processor(images=[rgb[0]], do_rescale=False, return_tensors="pt")
    outputs = network(**inputs)
    if name == "zoedepth":
        # its post-processing removes the reflect padding with tvF.resize (torchvision): the same
        # bicubic resize to the padded image, then the crop
        pad_h, pad_w = int((H / 2) ** 0.5 * 3), int((W / 2) ** 0.5 * 3)
        raw = processor.post_process_depth_estimation(outputs, do_remove_padding=False)[0]["predicted_depth"]
        full = F.interpolate(raw[None, None], (H + 2 * pad_h, W + 2 * pad_w), mode="bicubic")
        return full[0, 0, pad_h:-pad_h, pad_w:-pad_w]
    if FAMILIES[name].processor.get("do_pad"):
        # DPT's post-processing resizes the centre-padded prediction as it is; the padding is
        # cropped here first, as kadv does, so that prediction pixels line up with image pixels
        h_in, w_in = inputs["pixel_values"].shape[-2:]
        h_out, w_out = outputs.predicted_depth.shape[-2:]
        pad_h, pad_w = -H % 14, -W % 14
        top, left = round(pad_h // 2 * h_out / h_in), round(pad_w // 2 * w_out / w_in)
        bottom, right = round((pad_h - pad_h // 2) * h_out / h_in), round((pad_w - pad_w // 2) * w_out / w_in)
        outputs.predicted_depth = outputs.predicted_depth[:, top : h_out - bottom, left : w_out - right]
    return processor.post_process_depth_estimation(outputs, target_sizes=[(H, W)])[0]["predicted_depth"]


_PIL_FAMILIES = {
    name
    for name, family in FAMILIES.items()
    if family.processor_runs and family.processor.get("do_resize", True) and name != "zoedepth"
}


def test_the_prediction_is_the_family_processor_model_and_post_processing(family, view) -> None:
    name, directory = family
    model = load_model(directory)
    assert model.output_kind == FAMILIES[name].kind
    with torch.no_grad():
        for K in (view.K, None) if name == "depth_pro" else (None,):
            ours, theirs = model(view.rgb, K)[0, 0], _reference(name, directory, view.rgb, K)
            assert ours.shape == theirs.shape == (H, W)
            spread, error = float(theirs.max() - theirs.min()), (ours - theirs).abs()
            assert spread > 1e-3 * float(theirs.abs().mean()), name  # the prediction depends on the image
            if name in _PIL_FAMILIES:
                assert float(error.mean()) <= PIL_MEAN * spread and float(error.max()) <= PIL_MAX * spread, name
            else:
                torch.testing.assert_close(ours, theirs, rtol=TORCH_RELATIVE, atol=TORCH_RELATIVE * spread)


def test_two_gradient_steps_move_the_camera(family, room) -> None:
    name, directory = family
    objective = Objective(load_model(directory), depth_loss("ssim"), ExactRenderer(room), PenaltyConfig())
    init = file_init_views(objective.renderer, PenaltyConfig().margin)[0]
    config = AttackConfig("gradient", GradientSettings(steps=2, restarts=1), budget_passes=None)
    result = attack(
        objective, DifferentiableRenderer(objective.renderer), [init], 48, 64, config, seed=0, progress=False
    )
    path = result.views[0].records
    assert [r.step for r in path] == [0, 1, 2]
    assert path[0].params == [0.0] * 6 and all(any(abs(p) > 1e-6 for p in r.params) for r in path[1:]), name
    assert path[1].params != path[2].params


def _raw_truth(name: str, kind: str, depth: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """The ground truth as the family's head would output it at the image's size."""
    if name == "depth_pro":  # canonical inverse depth: f / (W * depth)
        return K[0, 0, 0] / (W * depth)
    return depth if kind == "depth" else 1.0 / depth


def test_the_output_kind_holds_where_near_and_far_are_known(family, view) -> None:
    """A network whose head outputs the box room's ground truth in the family's convention: read
    with kadv's output kind the prediction matches; read with the other kind it does not."""
    name, directory = family
    model = load_model(directory)
    geometry = replace(model.preprocess, mean=None, std=None)
    raw = _raw_truth(name, model.output_kind, view.depth.float(), view.K.float()).expand(-1, 3, -1, -1)
    at_network = geometry.to_network(raw)[0][:, 0]
    model.network.forward = lambda pixel_values, **_: SimpleNamespace(predicted_depth=at_network, field_of_view=None)
    with torch.no_grad():
        prediction = model(view.rgb, view.K).double()
    other = "disparity" if model.output_kind == "depth" else "depth"
    # the view sees 1.4-5.4 m: read as the other kind, the best affine fit is off by ~9 % (abs_rel)
    right = float(depth_metrics(prediction, view.depth, view.mask, model.output_kind)["abs_rel"])
    wrong = float(depth_metrics(prediction, view.depth, view.mask, other)["abs_rel"])
    assert right < 0.02 and wrong > 0.06, (name, right, wrong)
    if model.output_kind == "depth":  # metric: the scale is the scene's without any alignment
        relative = ((prediction - view.depth).abs() / view.depth)[view.mask]
        assert float(relative.median()) < 0.02, name
