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


class Camera(Brightness):
    """Declares that it takes the camera by a forward parameter named K; records what it receives."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: list = []

    def forward(self, rgb: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        self.seen.append(None if K is None else K.clone())
        return super().forward(rgb)


def _K(fx: float, width: int, height: int) -> torch.Tensor:
    return torch.tensor([[fx, 0.0, width / 2], [0.0, fx, height / 2], [0.0, 0.0, 1.0]])


def test_a_model_that_takes_the_camera_receives_the_view_s_K_when_given_and_none_when_withheld() -> None:
    module = Camera()
    model = wrap_model(module, "depth")
    assert model.takes_K and model.camera_text == "given"
    K = _K(50.0, 32, 24)
    model(torch.rand(1, 3, 24, 32), K)
    assert torch.equal(module.seen[-1], K)
    model.intrinsics = "withheld"
    model(torch.rand(1, 3, 24, 32), K)
    assert module.seen[-1] is None and model.camera_text == "withheld"
    # a module without a K parameter never sees it; the flag declares one that takes it another way
    assert wrap_model(Brightness(), "depth").camera_text == "not taken"
    assert wrap_model(Brightness(), "depth", takes_K=False).takes_K is False


def test_the_K_a_model_receives_is_that_of_the_image_its_network_sees() -> None:
    module = Camera()
    model = wrap_model(module, "depth", Preprocess(size=(48, 64), pad_multiple=32))  # x2, then 48 -> 64 rows
    model(torch.rand(2, 3, 24, 32), _K(50.0, 32, 24))
    assert torch.allclose(module.seen[-1], _K(100.0, 64, 48) + torch.tensor([[0, 0, 0], [0, 0, 8.0], [0, 0, 0]]))


def test_the_objective_passes_each_view_s_K_to_a_model_that_takes_it() -> None:
    from kadv import ExactRenderer, box_room
    from kadv.attack import Objective, PenaltyConfig
    from kadv.geometry import fov_intrinsics

    module = Camera()
    renderer = ExactRenderer(box_room(seed=0))
    objective = Objective(
        wrap_model(module, "depth"), lambda a, b: (a - b).abs().mean((1, 2, 3)), renderer, PenaltyConfig()
    )
    K = fov_intrinsics(torch.tensor([60.0, 90.0]), 24, 32)
    world_T_cam = torch.eye(4, dtype=torch.float64).expand(2, 4, 4).clone()
    world_T_cam[:, :3, 3] = torch.tensor(renderer.scene.bounds.mean(axis=0))  # the room's middle
    depth, mask = torch.ones(2, 1, 24, 32, dtype=torch.float64), torch.ones(2, 1, 24, 32, dtype=torch.bool)
    objective(torch.rand(2, 3, 24, 32), depth, mask, world_T_cam, K)
    assert torch.allclose(module.seen[-1].double(), K)  # each view's own K, two fields of view


def test_model_intrinsics_is_read_from_the_config_and_a_bad_value_named() -> None:
    from kadv.cli.common import model_from_config

    node = {"name": "custom", "target": f"{__name__}.Camera", "output_kind": "depth", "intrinsics": "withheld"}
    assert model_from_config(node).camera_text == "withheld"
    with pytest.raises(ValueError, match=r"model\.intrinsics must be given or withheld, got 'sometimes'"):
        model_from_config(node | {"intrinsics": "sometimes"})
