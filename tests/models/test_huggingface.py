"""Every adapter family, loaded from tiny random configs through the same path real checkpoints take."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from transformers import (
    BeitConfig,
    BitConfig,
    DepthAnythingConfig,
    DepthAnythingForDepthEstimation,
    Dinov2Config,
    DPTConfig,
    DPTForDepthEstimation,
    ZoeDepthConfig,
    ZoeDepthForDepthEstimation,
)
from transformers.models.dpt.image_processing_pil_dpt import get_resize_output_image_size

from kadv.models import load_model, resized_shape
from kadv.models.huggingface import output_kind

VIT = dict(hidden_size=32, num_hidden_layers=4, num_attention_heads=2, intermediate_size=64, image_size=64, patch_size=16)


def _dpt() -> torch.nn.Module:
    return DPTForDepthEstimation(DPTConfig(**VIT, backbone_out_indices=[0, 1, 2, 3], neck_hidden_sizes=[16, 16, 32, 32],
                                           fusion_hidden_size=16, reassemble_factors=[4, 2, 1, 0.5]))


def _dpt_hybrid() -> torch.nn.Module:
    bit = BitConfig(embedding_size=32, hidden_sizes=[64, 64, 64], depths=[1, 1, 1], layer_type="bottleneck", num_groups=8,
                    global_padding="same", out_features=["stage1", "stage2", "stage3"], embedding_dynamic_padding=True)
    return DPTForDepthEstimation(DPTConfig(**VIT, is_hybrid=True, backbone_config=bit, backbone_out_indices=[0, 1, 2, 3],
                                           neck_hidden_sizes=[64, 64, 32, 32], fusion_hidden_size=32,
                                           reassemble_factors=[1, 1, 1, 0.5], readout_type="project",
                                           backbone_featmap_shape=[1, 64, 4, 4]))


def _zoedepth() -> torch.nn.Module:
    beit = BeitConfig(**VIT, out_indices=[1, 2, 3, 4], use_relative_position_bias=True, reshape_hidden_states=False)
    bins = [{"name": "nyu", "n_bins": 8, "min_depth": 1e-3, "max_depth": 10.0},
            {"name": "kitti", "n_bins": 8, "min_depth": 1e-3, "max_depth": 80.0}]
    return ZoeDepthForDepthEstimation(ZoeDepthConfig(
        backbone_config=beit, neck_hidden_sizes=[16, 16, 32, 32], fusion_hidden_size=16, reassemble_factors=[4, 2, 1, 0.5],
        bottleneck_features=16, num_relative_features=8, bin_embedding_dim=16, num_attractors=[4, 2, 2, 2],
        num_patch_transformer_layers=4, patch_transformer_hidden_size=128, patch_transformer_intermediate_size=128,
        patch_transformer_num_attention_heads=2, bin_configurations=bins))


def _depth_anything(out_indices: list[int], **extra) -> torch.nn.Module:
    dino = Dinov2Config(hidden_size=32, num_hidden_layers=8, num_attention_heads=2, intermediate_size=64, image_size=56,
                        patch_size=14, out_indices=out_indices, apply_layernorm=True, reshape_hidden_states=False)
    return DepthAnythingForDepthEstimation(DepthAnythingConfig(
        backbone_config=dino, reassemble_hidden_size=32, patch_size=14, neck_hidden_sizes=[8, 16, 32, 32],
        fusion_hidden_size=16, head_hidden_size=8, **extra))


# v1 reads the last four backbone layers, v2 four evenly spaced ones (as the original code does).
FAMILIES = {
    "dpt_vit": (_dpt, None, "disparity"),
    "dpt_hybrid": (_dpt_hybrid, {"size": {"height": 64, "width": 64}, "keep_aspect_ratio": False, "ensure_multiple_of": 1,
                                 "image_mean": [0.5] * 3, "image_std": [0.5] * 3}, "disparity"),
    "zoedepth": (_zoedepth, {"size": {"height": 64, "width": 96}, "keep_aspect_ratio": True, "ensure_multiple_of": 32,
                             "image_mean": [0.5] * 3, "image_std": [0.5] * 3}, "depth"),
    "depth_anything_v1": (lambda: _depth_anything([5, 6, 7, 8]), {"size": {"height": 56, "width": 56},
                          "keep_aspect_ratio": True, "ensure_multiple_of": 14}, "disparity"),
    "depth_anything_v2": (lambda: _depth_anything([2, 4, 6, 8]), {"size": {"height": 70, "width": 70},
                          "keep_aspect_ratio": True, "ensure_multiple_of": 14}, "disparity"),
    "depth_anything_v2_metric": (lambda: _depth_anything([2, 4, 6, 8], depth_estimation_type="metric", max_depth=20),
                                 None, "depth"),
}


@pytest.fixture(scope="module", params=sorted(FAMILIES))
def saved(request, tmp_path_factory) -> tuple[str, Path]:
    build, processor, _ = FAMILIES[request.param]
    torch.manual_seed(0)
    directory = tmp_path_factory.mktemp(request.param)
    build().save_pretrained(directory)
    if processor is not None:
        (directory / "preprocessor_config.json").write_text(json.dumps(processor))
    return request.param, directory


@pytest.mark.parametrize("size", [(48, 48), (40, 70), (37, 53)], ids=["square", "wide", "odd"])
def test_loads_from_save_pretrained_and_keeps_the_input_size(saved, size) -> None:
    family, directory = saved
    model = load_model(directory)
    assert model.output_kind == FAMILIES[family][2]
    assert not model.training and not any(p.requires_grad for p in model.parameters())
    rgb = torch.rand(2, 3, *size, requires_grad=True)
    out = model(rgb)
    assert out.shape == (2, 1, *size)
    out.mean().backward()
    assert torch.isfinite(rgb.grad).all() and rgb.grad.abs().sum() > 0
    assert all(p.grad is None for p in model.parameters())


def test_preprocessor_config_is_honoured(saved) -> None:
    family, directory = saved
    model = load_model(directory)
    processor = FAMILIES[family][1]
    if processor is None:  # architecture defaults of the original processors
        expected = {"dpt_vit": (384, 384), "depth_anything_v2_metric": (518, 518)}[family]
        assert model.preprocess.size == expected
    else:
        assert model.preprocess.size == (processor["size"]["height"], processor["size"]["width"])
        assert model.preprocess.multiple == processor["ensure_multiple_of"]


@pytest.mark.parametrize("shape", [(480, 640), (240, 320), (181, 333), (518, 518)])
@pytest.mark.parametrize("keep, multiple", [(True, 14), (False, 1), (True, 32)])
def test_resize_matches_the_transformers_processor(shape, keep, multiple) -> None:
    theirs = get_resize_output_image_size(torch.zeros(3, *shape).numpy(), output_size=(518, 518),
                                          keep_aspect_ratio=keep, multiple=multiple)
    assert resized_shape(*shape, (518, 518), keep, multiple) == (theirs.height, theirs.width)


def _load_without_weights(env: dict[str, str]) -> tuple[float, str]:
    """Seconds until load_model('depth_anything_v2_small') gave up, and its message (a subprocess)."""
    script = (
        "import time\nfrom kadv.models import load_model, ModelWeightsUnavailable\nstart = time.perf_counter()\n"
        "try:\n    load_model('depth_anything_v2_small')\nexcept ModelWeightsUnavailable as error:\n"
        "    print('SECONDS', time.perf_counter() - start)\n    print(error)\n"
    )
    result = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    lines = result.stdout.splitlines()
    assert lines and lines[0].startswith("SECONDS"), result.stdout + result.stderr
    return float(lines[0].split()[1]), "\n".join(lines[1:])


def test_offline_without_weights_raises_the_documented_error_quickly(tmp_path: Path) -> None:
    seconds, message = _load_without_weights({**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path / "hf")})
    assert seconds < 5.0
    assert "depth_anything_v2_small" in message and "depth-anything/Depth-Anything-V2-Small-hf" in message
    assert "HF_HUB_OFFLINE" in message and "save_pretrained" in message


def test_without_network_loading_fails_within_seconds_not_after_retries(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE")}
    env.update(HF_HOME=str(tmp_path / "hf"), HF_ENDPOINT="https://hub.kadv-test.invalid")  # a name that never resolves
    seconds, message = _load_without_weights(env)
    assert seconds < 10.0
    assert "cannot be reached" in message and "model.weights=" in message


def test_unknown_model_name() -> None:
    with pytest.raises(ValueError, match="unknown model 'not_a_model'"):
        load_model("not_a_model")


@pytest.mark.parametrize("path", ["/tmp/does/not/exist", "./no_such_model", "~/no_such_model_dir"])
def test_a_missing_path_is_reported_as_a_missing_directory_not_a_hub_id(path: str) -> None:
    with pytest.raises(FileNotFoundError, match="no such model directory"):
        load_model(path)


@pytest.mark.parametrize("family, config, kind", [
    ("glpn", "GLPNConfig", "depth"), ("zoedepth", "ZoeDepthConfig", "depth"), ("tipsv2_dpt", "Tipsv2DptConfig", "depth"),
    ("dpt", "DPTConfig", "disparity"), ("depth_pro", "DepthProConfig", "disparity"),
    ("depth_anything", "DepthAnythingConfig", "disparity")])
def test_each_family_declares_what_its_output_holds(family: str, config: str, kind: str) -> None:
    import transformers

    built = getattr(transformers, config)()
    assert built.model_type == family and output_kind(built) == kind


def test_metric_depth_anything_is_depth() -> None:
    assert output_kind(DepthAnythingConfig(depth_estimation_type="metric")) == "depth"


@pytest.mark.parametrize("config, why", [("CHMv2Config", "canopy-height"), ("PromptDepthAnythingConfig", "prompt depth")])
def test_families_kadv_cannot_attack_are_refused_in_one_line(config: str, why: str, tmp_path: Path) -> None:
    import transformers

    getattr(transformers, config)().save_pretrained(tmp_path / "model")
    with pytest.raises(ValueError, match=why) as error:
        load_model(str(tmp_path / "model"))
    assert "\n" not in str(error.value)
