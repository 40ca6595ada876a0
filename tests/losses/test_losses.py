from __future__ import annotations

import urllib.error
from pathlib import Path

import numpy as np
import pytest
import torch
from torch import nn

from kadv.losses import (
    VGG16_TAPS,
    PerceptualLoss,
    align_scale_shift,
    depth_metrics,
    minmax_normalize,
    ssim_loss,
    to_comparison_space,
    vgg16_features,
)
from kadv.losses.perceptual import IMAGENET_MEAN, IMAGENET_STD


def _two_layer() -> nn.Sequential:
    first = nn.Conv2d(3, 1, 1, bias=False)
    second = nn.Conv2d(1, 1, 1)
    with torch.no_grad():
        first.weight.copy_(torch.tensor([0.5, -1.0, 2.0]).view(1, 3, 1, 1))
        second.weight.fill_(2.0)
        second.bias.fill_(-0.1)
    return nn.Sequential(first, nn.ReLU(), second, nn.ReLU())


def test_perceptual_loss_matches_hand_computation() -> None:
    a = [0.0, 0.25, 0.5, 1.0]
    b = [0.2, 0.25, 0.9, 0.4]
    mean, std, w = IMAGENET_MEAN.tolist(), IMAGENET_STD.tolist(), [0.5, -1.0, 2.0]

    def taps(values):
        first = [max(0.0, sum(w[c] * (v - mean[c]) / std[c] for c in range(3))) for v in values]
        return first, [max(0.0, 2.0 * f - 0.1) for f in first]

    (a1, a2), (b1, b2) = taps(a), taps(b)
    expected = sum(abs(x - y) for x, y in zip(a1, b1)) / 4 + sum(abs(x - y) for x, y in zip(a2, b2)) / 4
    loss = PerceptualLoss(_two_layer(), taps=(1, 3))
    value = loss(torch.tensor(a).view(1, 1, 2, 2), torch.tensor(b).view(1, 1, 2, 2))
    assert float(value) == pytest.approx(expected, rel=1e-6)
    assert expected > 0


def test_perceptual_loss_zero_for_identical_and_gradients_in_both_arguments() -> None:
    loss = PerceptualLoss(vgg16_features(), VGG16_TAPS)
    a = torch.rand(2, 1, 32, 40, requires_grad=True)
    b = torch.rand(2, 1, 32, 40, requires_grad=True)
    assert torch.equal(loss(a, a.detach().clone()), torch.zeros(2))
    loss(a, b).sum().backward()
    for grad in (a.grad, b.grad):
        assert torch.isfinite(grad).all() and grad.abs().sum() > 0
    assert all(p.grad is None for p in loss.parameters())


def _torchvision_layout_checkpoint(path: Path) -> dict[str, torch.Tensor]:
    torch.manual_seed(1)
    features = vgg16_features()
    state = {f"features.{k}": v for k, v in features.state_dict().items()}
    state["classifier.0.weight"] = torch.zeros(4, 4)  # present in real checkpoints, ignored
    torch.save(state, path)
    return features.state_dict()


def test_loads_torchvision_layout_from_path_and_torch_home(tmp_path: Path, monkeypatch) -> None:
    expected = _torchvision_layout_checkpoint(tmp_path / "vgg.pth")
    loaded = PerceptualLoss.vgg16(weights=tmp_path / "vgg.pth").network.state_dict()
    assert all(torch.equal(loaded[k], expected[k]) for k in expected)
    checkpoints = tmp_path / "home" / "hub" / "checkpoints"
    checkpoints.mkdir(parents=True)
    (tmp_path / "vgg.pth").rename(checkpoints / "vgg16-397923af.pth")
    monkeypatch.setenv("TORCH_HOME", str(tmp_path / "home"))
    loaded = PerceptualLoss.vgg16().network.state_dict()
    assert all(torch.equal(loaded[k], expected[k]) for k in expected)


def test_offline_without_vgg_weights_is_a_clear_error(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("TORCH_HOME", str(tmp_path))

    def offline(*args, **kwargs):
        raise urllib.error.URLError("no network")

    monkeypatch.setattr(torch.hub, "load_state_dict_from_url", offline)
    with pytest.raises(RuntimeError, match=r"VGG-16 weights .* not available.*loss=ssim"):
        PerceptualLoss.vgg16()
    with pytest.raises(FileNotFoundError, match=r"missing.pth"):
        PerceptualLoss.vgg16(weights=tmp_path / "missing.pth")


def test_ssim_loss_zero_for_identical_positive_otherwise() -> None:
    a = torch.rand(2, 1, 24, 24)
    assert torch.allclose(ssim_loss(a, a), torch.zeros(2), atol=1e-6)
    assert (ssim_loss(a, torch.rand(2, 1, 24, 24)) > 0.1).all()


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_ssim_loss_equals_kornias_value_for_value_and_in_its_gradient(dtype: torch.dtype) -> None:
    # kadv builds SSIM's window once per device (kornia uploads it at every call); nothing else differs
    from kornia.losses import ssim_loss as kornia_ssim_loss

    generator = torch.Generator().manual_seed(0)
    a, b = (torch.rand(3, 1, 40, 56, generator=generator, dtype=dtype, requires_grad=True) for _ in range(2))
    ours = ssim_loss(a, b)
    theirs = kornia_ssim_loss(a, b, window_size=11, max_val=1.0, reduction="none").mean(dim=(1, 2, 3))
    assert torch.equal(ours, theirs) and ours.dtype == dtype
    for mine, reference in zip(torch.autograd.grad(ours.sum(), (a, b)), torch.autograd.grad(theirs.sum(), (a, b))):
        assert torch.equal(mine, reference)
    with torch.no_grad():  # kornia's other path (channels-last on the CPU) gives the same values
        assert torch.equal(ssim_loss(a, b), theirs.detach())


def test_normalisation_and_spaces() -> None:
    depth = torch.tensor([[[[1.0, 2.0], [4.0, 0.0]]]])
    mask = depth > 0
    disparity = to_comparison_space(depth, "depth", "disparity", mask)
    assert torch.allclose(disparity, torch.tensor([[[[1.0, 0.5], [0.25, 0.0]]]]))
    assert torch.allclose(minmax_normalize(disparity, mask), torch.tensor([[[[1.0, 1 / 3], [0.0, 0.0]]]]))
    with pytest.raises(ValueError, match="space"):
        to_comparison_space(depth, "depth", "inverse", mask)


def test_alignment_recovers_known_scale_and_shift() -> None:
    prediction = torch.rand(3, 1, 8, 9, dtype=torch.float64)
    scale = torch.tensor([3.5, -0.2, 10.0], dtype=torch.float64).view(3, 1, 1, 1)
    shift = torch.tensor([-0.25, 2.0, 0.0], dtype=torch.float64).view(3, 1, 1, 1)
    mask = torch.rand(3, 1, 8, 9) > 0.3
    target = torch.where(mask, scale * prediction + shift, torch.full_like(prediction, 99.0))
    aligned = align_scale_shift(prediction, target, mask)
    assert torch.allclose(aligned[mask], target[mask], atol=1e-12)


def test_metrics_equal_hand_computed_values() -> None:
    gt = torch.tensor([1.0, 2.0, 4.0], dtype=torch.float64).view(1, 1, 1, 3)
    prediction = torch.tensor([1.0, 0.0, 0.25], dtype=torch.float64).view(1, 1, 1, 3)  # a disparity
    mask = torch.ones_like(gt, dtype=torch.bool)
    slope, intercept = np.polyfit([1.0, 0.0, 0.25], [1.0, 0.5, 0.25], 1)
    predicted_depth = 1.0 / (slope * np.array([1.0, 0.0, 0.25]) + intercept)
    truth = np.array([1.0, 2.0, 4.0])
    ratio = np.maximum(predicted_depth / truth, truth / predicted_depth)
    metrics = depth_metrics(prediction, gt, mask)
    for k in (1, 2, 3):
        assert float(metrics[f"delta{k}"]) == pytest.approx(np.mean(ratio < 1.25**k))
    assert float(metrics["abs_rel"]) == pytest.approx(np.mean(np.abs(predicted_depth - truth) / truth))
    assert float(metrics["rmse"]) == pytest.approx(np.sqrt(np.mean((predicted_depth - truth) ** 2)))
    assert float(metrics["delta1"]) == pytest.approx(1 / 3)  # the hand computation, as a sanity anchor


def test_perfect_prediction_scores_perfectly_in_either_kind() -> None:
    gt = 1.0 + 4.0 * torch.rand(2, 1, 6, 7, dtype=torch.float64)
    mask = torch.rand(2, 1, 6, 7) > 0.2
    for prediction, kind in ((3.0 / gt + 0.1, "disparity"), (gt, "depth")):
        metrics = depth_metrics(prediction, gt, mask, prediction_kind=kind)
        assert torch.allclose(metrics["delta1"], torch.ones(2, dtype=torch.float64))
        assert torch.allclose(metrics["abs_rel"], torch.zeros(2, dtype=torch.float64), atol=1e-9)
