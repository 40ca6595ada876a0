from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from kadv.datasets import render_procedural_views
from kadv.losses import gradient_matching, ssi_loss
from kadv.models import KadvTiny, TinyDepthNet, load_kadv_tiny, load_kadv_tiny_dpt, save_kadv_tiny, save_kadv_tiny_dpt
from kadv.training import tiny as training
from kadv.training.tiny import TinyTrainConfig, fit, load_soup, soup, train_tiny


def _views():
    torch.manual_seed(0)
    depth = 0.5 + 4 * torch.rand(3, 1, 8, 10, dtype=torch.float64)
    mask = torch.rand(3, 1, 8, 10) > 0.2
    return depth, mask


def test_ssi_loss_is_zero_for_any_positive_affine_disparity() -> None:
    depth, mask = _views()
    for gradient_weight in (0.0, 0.5):
        assert ssi_loss(3.0 / depth + 0.7, depth, mask, gradient_weight) < 1e-12


def test_ssi_loss_is_invariant_to_the_ground_truth_scale() -> None:
    depth, mask = _views()
    prediction = torch.rand_like(depth)
    assert torch.allclose(ssi_loss(prediction, depth, mask, 0.5), ssi_loss(prediction, 7.0 * depth, mask, 0.5))


def test_gradient_matching_by_hand() -> None:
    residual = torch.tensor([[[[0.0, 1.0, 3.0], [0.0, 0.0, 0.0]]]])
    mask = torch.ones_like(residual, dtype=torch.bool)
    # x pairs |1| + |2| + 0 + 0, y pairs 0 + |1| + |3|: 7 over 7 pairs.
    assert torch.allclose(gradient_matching(residual, mask, 1), torch.tensor([1.0]))
    mask[..., 0, 2] = False  # drops the x pair (1, 3) and the y pair (3, 0): 2 over 5 pairs
    assert torch.allclose(gradient_matching(residual, mask, 1), torch.tensor([0.4]))


def test_fit_is_deterministic_and_learns() -> None:
    views = render_procedural_views(8, seed=3, height=32, width=64, progress=False)
    config = TinyTrainConfig(steps=100, batch_size=4, lr=5e-3, channels=(8, 8, 8, 8, 8))
    weights = []
    for _ in range(2):
        torch.manual_seed(0)
        network = TinyDepthNet(config.channels)
        losses = fit(KadvTiny(network), views, config, progress=False)
        weights.append(torch.cat([p.detach().flatten() for p in network.parameters()]))
    assert torch.equal(weights[0], weights[1])
    # a network that learns nothing stays near 1; the ratio is 0.67 here and 0.75 on another CPU and torch
    assert sum(losses[-10:]) < 0.8 * sum(losses[:10]), losses


def test_strong_augmentation_zooms_depth_exactly() -> None:
    views = render_procedural_views(4, seed=3, height=32, width=40, progress=False)
    rgb, depth, mask = views.rgb, views.depth, views.mask
    basic = training._augment(rgb, depth, mask, torch.Generator().manual_seed(0))
    again = training._augment(rgb, depth, mask, torch.Generator().manual_seed(0))
    strong = training._augment(rgb, depth, mask, torch.Generator().manual_seed(0), strong=True)
    assert all(torch.equal(a, b) for a, b in zip(basic, again))
    assert all(torch.equal(b, d) or torch.equal(b, d.flip(-1)) for b, d in zip(basic[1], depth))  # flips only
    assert strong[0].shape == rgb.shape and not torch.equal(strong[0], basic[0])
    # zoomed by nearest samples: every depth is one the view had, and its mask still marks the hits
    assert bool(torch.isin(strong[1], depth).all()) and torch.equal(strong[2], strong[1] > 0)
    assert not torch.equal(strong[1], basic[1])


def test_train_tiny_continues_from_init_weights(tmp_path) -> None:
    torch.manual_seed(1)
    start = save_kadv_tiny(TinyDepthNet((8, 8, 8, 8, 16)), tmp_path / "start.safetensors")
    config = TinyTrainConfig(train_views=8, val_views=8, steps=3, batch_size=2, init_weights=str(start))
    model, log = train_tiny(config, progress=False)
    network = model.network
    assert network.channels == (8, 8, 8, 8, 16)  # the file's architecture, not config.channels
    initial = load_kadv_tiny(start).network.state_dict()
    changed = [not torch.equal(initial[k], v) for k, v in network.state_dict().items()]
    assert any(changed) and 0.0 <= log["val_delta1"] <= 1.0 and len(log["losses"]) == 3


def test_the_dpt_trains_through_its_own_preprocessing_and_continues_from_a_directory(tmp_path) -> None:
    config = TinyTrainConfig(train_views=8, val_views=8, steps=3, batch_size=2, architecture="dpt", furnished_share=1.0)
    model, log = train_tiny(config, progress=False)
    start = save_kadv_tiny_dpt(model.network, tmp_path / "start")
    again, _ = train_tiny(replace(config, init_weights=str(start)), progress=False)
    initial = load_kadv_tiny_dpt(start).network.state_dict()
    assert any(not torch.equal(initial[k], v) for k, v in again.network.state_dict().items())
    assert model.name == "kadv_tiny_dpt" and len(log["losses"]) == 3 and 0.0 <= log["val_delta1"] <= 1.0
    assert not any(p.requires_grad for p in again.parameters())  # handed back frozen, as loaded models are


def test_a_soup_averages_the_trained_weights_with_the_named_ones(tmp_path) -> None:
    torch.manual_seed(1)
    first, second = (TinyDepthNet((8, 8, 8, 8, 16)) for _ in range(2))
    paths = [str(save_kadv_tiny(net, tmp_path / f"{i}.safetensors")) for i, net in enumerate((first, second))]
    trained = load_kadv_tiny(paths[0])
    generator_state = torch.get_rng_state()
    ingredients = load_soup(trained, paths[1:], "unet")
    assert torch.equal(torch.get_rng_state(), generator_state)  # loading leaves a seeded generator as it was
    soup(trained, ingredients)
    other = load_kadv_tiny(paths[1]).network.state_dict()
    for name, value in load_kadv_tiny(paths[0]).network.state_dict().items():
        assert torch.allclose(trained.network.state_dict()[name], (value + other[name]) / 2)
    narrow = str(save_kadv_tiny(TinyDepthNet((8, 8, 8, 8, 8)), tmp_path / "narrow.safetensors"))
    with pytest.raises(ValueError, match=r"train\.soup_with: .*narrow.safetensors is not shaped like"):
        load_soup(trained, [narrow], "unet")


def test_a_soup_of_other_channels_is_refused_before_any_rendering(tmp_path, monkeypatch) -> None:
    narrow = str(save_kadv_tiny(TinyDepthNet((8, 8, 8, 8, 8)), tmp_path / "narrow.safetensors"))
    monkeypatch.setattr(training, "render_training_views", lambda *args: pytest.fail("rendered before the check"))
    with pytest.raises(ValueError, match=r"narrow\.safetensors is not shaped like"):
        train_tiny(TinyTrainConfig(channels=(8, 8, 8, 8, 16), soup_with=[narrow]), progress=False)


def test_train_tiny_soups_with_the_weights_it_names(tmp_path) -> None:
    torch.manual_seed(1)
    start = str(save_kadv_tiny(TinyDepthNet((8, 8, 8, 8, 16)), tmp_path / "start.safetensors"))
    config = TinyTrainConfig(train_views=8, val_views=8, steps=3, batch_size=2, init_weights=start)
    plain, _ = train_tiny(config, progress=False)
    souped, log = train_tiny(replace(config, soup_with=[start]), progress=False)
    initial = load_kadv_tiny(start).network.state_dict()
    for name, value in plain.network.state_dict().items():
        assert torch.allclose(souped.network.state_dict()[name], (value + initial[name]) / 2)
    assert log["config"]["soup_with"] == [start]


@pytest.mark.parametrize(
    "field, value",
    [
        ("steps", 0),
        ("train_views", -4),
        ("batch_size", 1.5),
        ("lr", 0.0),
        ("weight_decay", -1e-4),
        ("channels", ()),
        ("init_weights", "/no/such/file"),
        ("architecture", "resnet"),
        ("furnished_share", 1.5),
        ("corridor_share", -0.1),
        ("hall_share", 0.9),  # with the corridors' 0.15, over 1
        ("seed", 7),  # the held-out rooms
        ("val_seed", 7),
        ("seed", 1),  # the validation rooms
        ("attack_view_share", -0.5),
        ("squeeze_share", 2.0),
        ("baked_share", -0.1),
        ("stairs_share", 1.5),
        ("sun_share", -0.2),
        ("glazing_share", 2.0),
        ("bake", {"rays": 0}),
        ("bake", {"glow": 1}),
        ("augment", "heavy"),
        ("device", "tpu"),
        ("soup_with", ["/no/such/file"]),
    ],
)
def test_bad_settings_are_refused_before_any_rendering(field, value) -> None:
    with pytest.raises((ValueError, FileNotFoundError), match=rf"train\.{field}"):
        TinyTrainConfig(**{field: value})


def test_metric_log_loss_is_zero_for_the_depth_and_counts_a_scale_error() -> None:
    depth, mask = _views()
    assert training.metric_log_loss(depth, depth, mask, gradient_weight=0.5).abs().item() < 1e-12
    # off by a factor of 2 everywhere: |log 2| per pixel, and no gradient-matching term (the residual is flat)
    assert training.metric_log_loss(2 * depth, depth, mask, gradient_weight=0.5).item() == pytest.approx(0.693147)
    # unlike the scale-and-shift-invariant loss, which a scaled disparity leaves at 0
    assert ssi_loss(2 / depth, depth, mask).abs().item() < 1e-9


def test_a_metric_target_trains_kadv_tiny_metric_from_kadv_tiny_s_weights(tmp_path) -> None:
    torch.manual_seed(1)
    start = save_kadv_tiny(TinyDepthNet((8, 8, 8, 8, 16)), tmp_path / "start.safetensors")
    small = {"train_views": 8, "val_views": 8, "steps": 3, "batch_size": 2}
    config = TinyTrainConfig(**small, init_weights=str(start), target="metric")
    model, log = train_tiny(config, progress=False)
    assert model.name == "kadv_tiny_metric" and model.output_kind == "depth" and log["output_kind"] == "depth"
    assert 0.0 <= log["val_delta1_metric"] <= 1.0 and 0.0 <= log["val_delta1"] <= 1.0
    saved = save_kadv_tiny(model.network, tmp_path / "metric.safetensors", metadata={"output_kind": "depth"})
    assert load_kadv_tiny(saved, "depth").output_kind == "depth"
    with pytest.raises(ValueError, match="predict depth, not the disparity of kadv_tiny"):
        load_kadv_tiny(saved)


@pytest.mark.parametrize(
    ("settings", "words"),
    [
        ({"target": "metres"}, "train.target must be one of disparity, metric"),
        ({"target": "metric", "architecture": "dpt"}, "train.target=metric trains the U-Net"),
        ({"target": "metric", "augment": "strong"}, "train.augment=strong zooms"),
    ],
)
def test_a_metric_target_the_network_cannot_learn_is_refused_by_key(settings, words) -> None:
    with pytest.raises(ValueError, match=words):
        TinyTrainConfig(**settings)
