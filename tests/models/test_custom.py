"""Bring your own model: any torch module wrapped as a DepthModel, checked on its first call."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from kadv.models import Preprocess, load_custom, wrap_model


class Brightness(torch.nn.Module):
    """Disparity from brightness: differentiable, the right shape."""

    def __init__(self, scale: float = 1.0) -> None:
        super().__init__()
        self.scale = torch.nn.Parameter(torch.tensor(scale))

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        return self.scale * (0.1 + rgb.mean(dim=1, keepdim=True))


class Broken(torch.nn.Module):
    def __init__(self, fault: str) -> None:
        super().__init__()
        self.fault = fault

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        out = rgb.mean(dim=1, keepdim=True)
        if self.fault == "shape":
            return rgb
        if self.fault == "nan":
            return out * torch.nan
        if self.fault == "detached":
            return out.detach()
        if self.fault == "numpy":
            return out.detach().numpy()
        with torch.no_grad():
            return rgb.mean(dim=1, keepdim=True)


def test_a_wrapped_module_keeps_the_input_size_and_passes_gradients() -> None:
    model = wrap_model(Brightness(), "disparity", name="brightness")
    rgb = torch.rand(2, 3, 30, 40, requires_grad=True)
    out = model(rgb)
    assert out.shape == (2, 1, 30, 40) and model.output_kind == "disparity" and model.name == "brightness"
    torch.testing.assert_close(out, 0.1 + rgb.mean(dim=1, keepdim=True))  # no preprocessing unless declared
    out.sum().backward()
    assert rgb.grad is not None and rgb.grad.abs().sum() > 0
    assert not any(p.requires_grad for p in model.parameters()) and not model.training


def test_a_declared_preprocess_resizes_in_and_back() -> None:
    seen = []

    class Spy(Brightness):
        def forward(self, rgb):
            seen.append(tuple(rgb.shape))
            return super().forward(rgb)

    model = wrap_model(Spy(), "depth", Preprocess(size=(32, 32)))
    assert model(torch.rand(1, 3, 48, 64)).shape == (1, 1, 48, 64)
    assert seen[-1] == (1, 3, 32, 32)


@pytest.mark.parametrize(
    "fault, message",
    [
        ("shape", "must map rgb (B, 3, H, W) to (B, 1, H, W)"),
        ("nan", "NaN"),
        ("detached", "not differentiable"),
        ("no_grad", "not differentiable"),
        ("numpy", "got ndarray"),
    ],
)
def test_a_wrong_model_is_refused_on_its_first_call_naming_it(fault: str, message: str) -> None:
    with pytest.raises(ValueError, match="model 'mine'") as error:
        wrap_model(Broken(fault), "disparity", name="mine")
    assert message in str(error.value) and "\n" not in str(error.value)


def test_an_unknown_output_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="output_kind"):
        wrap_model(Brightness(), "inverse")


def test_a_factory_from_a_file_outside_the_package(tmp_path: Path) -> None:
    (tmp_path / "mine.py").write_text(
        "import torch\n\nclass M(torch.nn.Module):\n"
        "    def __init__(self, k):\n        super().__init__(); self.k = k\n"
        "    def forward(self, rgb):\n        return self.k + rgb[:, :1]\n\n"
        "def make(k=1.0):\n    return M(k)\n"
    )
    model = load_custom(f"{tmp_path / 'mine.py'}:make", "depth", {"k": 2.0})
    rgb = torch.rand(1, 3, 8, 8)
    torch.testing.assert_close(model(rgb), 2.0 + rgb[:, :1])


@pytest.mark.parametrize(
    "target, message",
    [
        ("no_such_package_kadv.make", "cannot import 'no_such_package_kadv'"),
        ("torch.no_such_factory", "has no attribute 'no_such_factory'"),
        ("make", "expected package.module.factory"),
        ("/no/such/file.py:make", "no such file"),
        ("math.pi", "is not callable"),
        ("torch.nn.Conv2d", "failed when called with {}"),
    ],
)
def test_a_bad_target_is_named(target: str, message: str) -> None:
    with pytest.raises(ValueError, match=r"model.target") as error:
        load_custom(target, "disparity")
    assert message in str(error.value)
