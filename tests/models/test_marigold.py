"""Marigold through diffusers: kadv's differentiable steps against ``MarigoldDepthPipeline.__call__``
on a tiny random checkpoint, its kinds, noise, gradient, settings and refusals."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch

from kadv.attack import Study, StudySettings
from kadv.attack.search import AttackConfig
from kadv.bench import model_identity
from kadv.cli.attack import main as attack_main
from kadv.errors import MissingExtra
from kadv.models import MarigoldDepthModel, MarigoldSettings, load_model
from kadv.models.marigold import PRESET_SETTINGS, marigold_kind
from kadv.scenes import box_room
from tests.cli.in_process import call_main
from tests.models.tiny_marigold import marigold_pipeline, save_tiny_marigold


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    """A tiny Marigold checkpoint folder, two DDIM steps by default, processing resolution 64."""
    return save_tiny_marigold(tmp_path_factory.mktemp("marigold") / "tiny", steps=2)


@pytest.fixture(scope="module")
def pipeline(checkpoint: Path):
    from diffusers import MarigoldDepthPipeline

    pipe = MarigoldDepthPipeline.from_pretrained(checkpoint)
    pipe.set_progress_bar_config(disable=True)
    return pipe


def _noise(size: tuple[int, int], seed: int, resolution: int = 64) -> torch.Tensor:
    """The starting latent (1, 4, h, w) kadv draws for an image of ``size``: its processing size over 8."""
    longest = max(size)
    shape = [side * resolution // longest for side in size]
    return torch.randn(1, 4, *(-(-side // 8) for side in shape), generator=torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("size", [(48, 64), (60, 44)])
def test_the_prediction_is_the_pipelines_own(size, checkpoint: Path, pipeline) -> None:
    # (60, 44) is resized to 64 x 46 and padded to 64 x 48: the padding comes off the output
    model = load_model("marigold_depth_v1_1", weights=checkpoint)
    assert isinstance(model, MarigoldDepthModel) and model.output_kind == "affine_depth"
    rgb = torch.rand(2, 3, *size, generator=torch.Generator().manual_seed(1))
    ours = model(rgb)
    theirs = pipeline(rgb, latents=_noise(size, 0).expand(2, -1, -1, -1), output_type="pt").prediction
    assert ours.shape == theirs.shape == (2, 1, *size)
    assert ours.std() > 0.01  # a prediction, not a constant the comparison would pass anyway
    torch.testing.assert_close(ours, theirs, atol=1e-4, rtol=0)


def test_settings_reach_the_pipeline_and_zero_noise_is_the_e2e_fine_tunes_start(checkpoint: Path, pipeline) -> None:
    rgb = torch.rand(1, 3, 40, 40, generator=torch.Generator().manual_seed(2))
    model = load_model("marigold_e2e_ft_depth", weights=checkpoint, processing_resolution=32)  # its own: 1 step, zeros
    zeros = torch.zeros(1, 4, 4, 4)
    theirs = pipeline(rgb, num_inference_steps=1, processing_resolution=32, latents=zeros, output_type="pt")
    torch.testing.assert_close(model(rgb), theirs.prediction, atol=1e-4, rtol=0)
    gaussian = load_model("marigold_e2e_ft_depth", weights=checkpoint, processing_resolution=32, noise="gaussian")
    assert (gaussian(rgb) - model(rgb)).abs().max() > 1e-3
    assert model_identity(model)["settings"] != model_identity(gaussian)["settings"]  # two identities on the board


def test_each_view_draws_the_same_noise_whatever_its_batch_and_call(checkpoint: Path) -> None:
    model = load_model("marigold_depth_v1_1", weights=checkpoint)
    rgb = torch.rand(3, 3, 32, 48, generator=torch.Generator().manual_seed(3))
    batched = model(rgb)
    alone = torch.cat([model(rgb[i : i + 1]) for i in range(3)])
    torch.testing.assert_close(batched, alone, atol=1e-5, rtol=0)
    assert torch.equal(model(rgb), batched)
    other_seed = load_model("marigold_depth_v1_1", weights=checkpoint, seed=1)
    assert (other_seed(rgb) - batched).abs().max() > 1e-3


def test_finite_differences_in_the_image_agree_with_autograd(checkpoint: Path) -> None:
    model = load_model("marigold_depth_v1_1", weights=checkpoint, processing_resolution=32).double()
    generator = torch.Generator().manual_seed(4)
    rgb = torch.rand(1, 3, 24, 32, generator=generator, dtype=torch.float64).requires_grad_(True)
    weights = torch.randn(1, 1, 24, 32, generator=generator, dtype=torch.float64)
    (model(rgb) * weights).sum().backward()
    direction = torch.randn(rgb.shape, generator=generator, dtype=torch.float64)
    eps = 1e-5
    with torch.no_grad():
        ahead, behind = ((model(rgb + sign * eps * direction) * weights).sum() for sign in (1, -1))
    numeric = float(ahead - behind) / (2 * eps)
    analytic = float((rgb.grad * direction).sum())
    assert abs(analytic) > 1e-3 and analytic == pytest.approx(numeric, rel=1e-4)


def test_an_ensemble_is_diffusers_own_and_refused_by_gradient_methods(checkpoint: Path, pipeline) -> None:
    model = load_model("marigold_depth_v1_1", weights=checkpoint, ensemble_size=3)
    rgb = torch.rand(1, 3, 32, 32, generator=torch.Generator().manual_seed(5))
    latents = torch.cat([_noise((32, 32), seed) for seed in range(3)])
    theirs = pipeline(rgb, ensemble_size=3, latents=latents, output_type="pt").prediction
    torch.testing.assert_close(model(rgb), theirs, atol=1e-4, rtol=0)
    assert not model.differentiable and model.inference_settings()["ensemble_size"] == 3
    gradient = StudySettings(attack=AttackConfig(method="gradient"))
    with pytest.raises(ValueError, match=r"attack.method=gradient follows the gradient.*random"):
        Study.build(box_room(), model, gradient)
    assert Study.build(box_room(), model, StudySettings(attack=AttackConfig(method="random"))).model is model


@pytest.mark.parametrize(
    ("flags", "kind"),
    [
        (("depth", True, True), "affine_depth"),
        (("depth", True, False), "scale_depth"),
        (("depth", False, False), "depth"),
    ],
)
def test_the_kind_is_read_from_the_pipelines_invariance_flags(flags, kind) -> None:
    assert marigold_kind(*flags) == kind
    pipe = marigold_pipeline(scale_invariant=flags[1], shift_invariant=flags[2])
    assert MarigoldDepthModel(pipe, "tiny").output_kind == kind


def test_bad_settings_and_a_missing_extra_are_one_clear_error(checkpoint: Path, monkeypatch, tmp_path: Path) -> None:
    for settings, named in (
        ({"steps": 0}, "model.steps"),
        ({"noise": "pink"}, "model.noise"),
        ({"ensemble_size": 0}, "model.ensemble_size"),
        ({"processing_resolution": 60}, "multiple of 8"),
        ({"guidance": 2}, "model.guidance"),
    ):
        with pytest.raises(ValueError, match=named):
            load_model("marigold_depth_v1_1", weights=checkpoint, **settings)
    with pytest.raises(ValueError, match=r"model\.steps: model 'kadv_tiny' takes no such setting"):
        load_model("kadv_tiny", steps=2)
    with pytest.raises(ValueError, match="scale_invariant=False, shift_invariant=True"):
        marigold_kind("depth", False, True)
    monkeypatch.setitem(sys.modules, "diffusers", None)  # as where the extra is not installed
    with pytest.raises(MissingExtra, match=r"pip install 'kadv\[diffusers\]'"):
        load_model("marigold_depth_v1_1", weights=checkpoint)
    argv = ["kadv-attack", "model=marigold_depth_v1_1", f"model.weights={checkpoint}"]
    result = call_main(attack_main, argv, cwd=tmp_path)
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        "kadv-attack: error: model 'marigold_depth_v1_1' needs diffusers: pip install 'kadv[diffusers]'"
    ]


def test_missing_weights_say_where_kadv_looked(tmp_path: Path, monkeypatch) -> None:
    from kadv.models import ModelWeightsUnavailable

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setenv("HF_HOME", str(tmp_path))
    with pytest.raises(ModelWeightsUnavailable, match="prs-eth/marigold-depth-v1-1"):
        load_model("marigold_depth_v1_1")


def test_the_presets_yaml_settings_are_the_librarys_defaults() -> None:
    from tests.cli.test_config import _compose

    for name in ("marigold_depth_v1_1", "marigold_e2e_ft_depth"):
        node = _compose("kadv_attack", f"model={name}").model
        keys = ("steps", "processing_resolution", "ensemble_size", "noise", "seed")
        assert MarigoldSettings(**{key: node[key] for key in keys}) == MarigoldSettings(**PRESET_SETTINGS.get(name, {}))
    assert PRESET_SETTINGS["marigold_e2e_ft_depth"]["noise"] == "zeros"  # the fine-tune starts from zeros
