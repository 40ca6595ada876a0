"""Every adapter family, loaded from tiny random configs through the same path real checkpoints take."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from transformers import DepthAnythingConfig, Dinov2Config, DPTConfig
from transformers.models.dpt.image_processing_pil_dpt import (
    get_resize_output_image_size,
)

from kadv.models import load_model, resized_shape
from kadv.models.huggingface import family_preprocess, output_kind
from tests.models.tiny_families import FAMILIES, save_family


@pytest.fixture(scope="module", params=sorted(FAMILIES))
def saved(request, tmp_path_factory) -> tuple[str, Path]:
    return request.param, save_family(request.param, tmp_path_factory.mktemp(request.param))


@pytest.mark.parametrize("size", [(48, 48), (37, 53)], ids=["square", "odd"])
def test_loads_from_save_pretrained_and_keeps_the_input_size(saved, size) -> None:
    family, directory = saved
    model = load_model(directory)
    assert model.output_kind == FAMILIES[family].kind
    assert not model.training and not any(p.requires_grad for p in model.parameters())
    rgb = torch.rand(2, 3, *size, requires_grad=True)
    out = model(rgb)
    assert out.shape == (2, 1, *size)
    out.mean().backward()
    assert torch.isfinite(rgb.grad).all() and rgb.grad.abs().sum() > 0
    assert all(p.grad is None for p in model.parameters())


def test_preprocessor_config_is_honoured(saved) -> None:
    family, directory = saved
    model, processor = load_model(directory), FAMILIES[family].processor or {}
    if family == "depth_pro":  # no processor file: the fixed square of its patching, patch_size / min(ratio)
        assert model.preprocess.size == (64 / 0.5, 64 / 0.5)
    if "height" in processor.get("size", {}):
        assert model.preprocess.size == (processor["size"]["height"], processor["size"]["width"])
    assert model.preprocess.multiple == processor.get("ensure_multiple_of", 1)


@pytest.mark.parametrize(
    "config, processor, expected",
    [
        ("GLPNConfig", {"size_divisor": 32}, {"size": None, "floor_multiple": 32, "mean": None}),
        ("ZoeDepthConfig", {"do_pad": False}, {"reflect_pad": False, "size": (384, 512)}),
        ("DPTConfig", {"do_resize": False, "do_pad": True, "size_divisor": 14}, {"size": None, "pad_multiple": 14}),
        ("DPTConfig", {"do_normalize": False, "resample": 2}, {"mean": None, "std": None, "interpolation": "bilinear"}),
        (
            "DPTConfig",
            {"size": 256, "keep_aspect_ratio": True, "ensure_multiple_of": 14},
            {"size": (256, 256), "multiple": 14},
        ),
    ],
    ids=["glpn", "zoedepth_no_pad", "dinov2_pad", "no_normalize", "int_size"],
)
def test_processor_settings_become_the_preprocess(config, processor, expected) -> None:
    import transformers

    preprocess = family_preprocess(getattr(transformers, config)(), processor)
    assert {key: getattr(preprocess, key) for key in expected} == expected


def test_a_resampling_filter_kadv_cannot_reproduce_is_refused() -> None:
    with pytest.raises(ValueError, match="resample=1"):
        family_preprocess(DPTConfig(), {"resample": 1})


@pytest.mark.parametrize("shape", [(480, 640), (240, 320), (181, 333), (518, 518)])
@pytest.mark.parametrize("keep, multiple", [(True, 14), (False, 1), (True, 32)])
def test_resize_matches_the_transformers_processor(shape, keep, multiple) -> None:
    theirs = get_resize_output_image_size(
        torch.zeros(3, *shape).numpy(), output_size=(518, 518), keep_aspect_ratio=keep, multiple=multiple
    )
    assert resized_shape(*shape, (518, 518), keep, multiple) == (theirs.height, theirs.width)


def _load_without_weights(env: dict[str, str]) -> tuple[dict[str, int], str]:
    """The network calls load_model('depth_anything_v2_small') made before it gave up (host-name
    look-ups and connections), and its message (a subprocess)."""
    script = """
import socket
calls = {"resolve": 0, "connect": 0}
_resolve, _connect = socket.getaddrinfo, socket.socket.connect
def resolve(*args, **kwargs):
    calls["resolve"] += 1
    return _resolve(*args, **kwargs)
def connect(self, *args, **kwargs):
    calls["connect"] += 1
    return _connect(self, *args, **kwargs)
socket.getaddrinfo, socket.socket.connect = resolve, connect
from kadv.models import load_model, ModelWeightsUnavailable
try:
    load_model("depth_anything_v2_small")
except ModelWeightsUnavailable as error:
    print("CALLS", calls["resolve"], calls["connect"])
    print(error)
"""
    result = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300)
    lines = result.stdout.splitlines()
    assert lines and lines[0].startswith("CALLS"), result.stdout + result.stderr
    resolve, connect = map(int, lines[0].split()[1:])
    return {"resolve": resolve, "connect": connect}, "\n".join(lines[1:])


def test_offline_without_weights_raises_the_documented_error_without_the_network(tmp_path: Path) -> None:
    calls, message = _load_without_weights({**os.environ, "HF_HUB_OFFLINE": "1", "HF_HOME": str(tmp_path / "hf")})
    assert calls == {"resolve": 0, "connect": 0}
    assert "depth_anything_v2_small" in message and "depth-anything/Depth-Anything-V2-Small-hf" in message
    assert "HF_HUB_OFFLINE" in message and "save_pretrained" in message


def test_without_network_loading_fails_after_one_look_up_not_after_retries(tmp_path: Path) -> None:
    """kadv asks once whether the hub answers (hub_reachable) instead of waiting out the hub
    client's retries: two host look-ups (the client's first request and kadv's check), where each
    retry would add one."""
    env = {k: v for k, v in os.environ.items() if k not in ("HF_HUB_OFFLINE", "TRANSFORMERS_OFFLINE")}
    env.update(HF_HOME=str(tmp_path / "hf"), HF_ENDPOINT="https://hub.kadv-test.invalid")  # a name that never resolves
    calls, message = _load_without_weights(env)
    assert calls["resolve"] <= 2 and calls["connect"] == 0
    assert "cannot be reached" in message and "model.weights=" in message


def test_unknown_model_name() -> None:
    with pytest.raises(ValueError, match="unknown model 'not_a_model'"):
        load_model("not_a_model")


@pytest.mark.parametrize("path", ["/tmp/does/not/exist", "./no_such_model", "~/no_such_model_dir"])
def test_a_missing_path_is_reported_as_a_missing_directory_not_a_hub_id(path: str) -> None:
    with pytest.raises(FileNotFoundError, match="no such model directory"):
        load_model(path)


@pytest.mark.parametrize(
    "family, config, kind",
    [
        ("glpn", "GLPNConfig", "depth"),
        ("zoedepth", "ZoeDepthConfig", "depth"),
        ("tipsv2_dpt", "Tipsv2DptConfig", "depth"),
        ("dpt", "DPTConfig", "disparity"),
        ("depth_pro", "DepthProConfig", "depth"),
        ("depth_anything", "DepthAnythingConfig", "disparity"),
    ],
)
def test_each_family_declares_what_its_output_holds(family: str, config: str, kind: str) -> None:
    import transformers

    built = getattr(transformers, config)()
    assert built.model_type == family and output_kind(built) == kind


def test_metric_depth_anything_and_dinov2_dpt_heads_are_depth() -> None:
    assert output_kind(DepthAnythingConfig(depth_estimation_type="metric")) == "depth"
    assert output_kind(DPTConfig(backbone_config=Dinov2Config())) == "depth"


def test_a_family_kadv_does_not_know_is_refused_with_what_to_do() -> None:
    config = DPTConfig()
    config.model_type = "future_depth"
    with pytest.raises(ValueError, match=r"'future_depth' is not one kadv knows.*wrap_model"):
        output_kind(config)


@pytest.mark.parametrize(
    "config, why", [("CHMv2Config", "canopy-height"), ("PromptDepthAnythingConfig", "prompt depth")]
)
def test_families_kadv_cannot_attack_are_refused_in_one_line(config: str, why: str, tmp_path: Path) -> None:
    import transformers

    getattr(transformers, config)().save_pretrained(tmp_path / "model")
    with pytest.raises(ValueError, match=why) as error:
        load_model(str(tmp_path / "model"))
    assert "\n" not in str(error.value)
