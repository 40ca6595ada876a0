"""Bring your own model: any torch module behind the :class:`DepthModel` interface.

From Python, :func:`wrap_model` takes a module mapping rgb (B, 3, H, W) in [0, 1] to a prediction
(B, 1, H, W) and its declared output kind; from the command line, ``model=custom
model.target=my_package.my_factory`` (or ``path/to/file.py:my_factory``) names a factory that
returns such a module, called with ``model.args``.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
from pathlib import Path
from typing import Any

import torch
from torch import nn

from kadv.models.base import DepthModel
from kadv.models.preprocess import Preprocess

__all__ = ["ModuleDepthModel", "check_depth_model", "load_custom", "wrap_model"]

# the probe image a wrapped model is checked on when no Preprocess fixes its input size
_PROBE_SIZE = (64, 64)


class ModuleDepthModel(DepthModel):
    """A user's module; without a :class:`Preprocess` it sees rgb in [0, 1] at the render's size."""

    def __init__(
        self,
        module: nn.Module,
        output_kind: str,
        name: str,
        preprocess: Preprocess | None = None,
        takes_K: bool | None = None,
    ) -> None:
        super().__init__(preprocess, output_kind, name)
        self.module = module
        # a module declares that it takes the camera by a forward parameter named K, or by the flag
        self.takes_K = "K" in inspect.signature(module.forward).parameters if takes_K is None else takes_K
        self.freeze()

    def predict(self, pixel_values: torch.Tensor, K: torch.Tensor | None = None) -> torch.Tensor:
        out = self.module(pixel_values, K=K) if self.takes_K else self.module(pixel_values)
        if not isinstance(out, torch.Tensor):  # a user's module may return anything; say what
            raise TypeError(f"expected a tensor (B, 1, H, W), got {type(out).__name__}")
        return out


def check_depth_model(model: DepthModel) -> DepthModel:
    """Call ``model`` once on a probe image and refuse it, naming it, unless it returns a finite
    (B, 1, H, W) prediction whose gradient reaches the image.

    Raises:
        ValueError: one line naming the model and the problem.
    """
    size = model.preprocess.size if model.preprocess is not None else _PROBE_SIZE
    generator = torch.Generator().manual_seed(0)
    rgb = torch.rand(2, 3, *size, generator=generator).requires_grad_(True)
    try:
        with torch.enable_grad():
            out = model(rgb)
    except Exception as error:  # a user's module may fail in any way; its message is what helps
        raise ValueError(
            f"model {model.name!r} fails on a (2, 3, {size[0]}, {size[1]}) image: {type(error).__name__}: {error}"
        ) from error
    if not isinstance(out, torch.Tensor) or tuple(out.shape) != (2, 1, *size):
        got = tuple(out.shape) if isinstance(out, torch.Tensor) else type(out).__name__
        raise ValueError(
            f"model {model.name!r} must map rgb (B, 3, H, W) to (B, 1, H, W): "
            f"got {got} for a (2, 3, {size[0]}, {size[1]}) image"
        )
    if not torch.isfinite(out).all():
        raise ValueError(f"model {model.name!r} returns NaN or infinite values")
    if not out.requires_grad:
        raise ValueError(
            f"model {model.name!r} is not differentiable: its output carries no gradient to the image "
            "(detached, computed under no_grad, or through numpy)"
        )
    (gradient,) = torch.autograd.grad(out.sum(), rgb, allow_unused=True)
    if gradient is None or not torch.isfinite(gradient).all() or not gradient.abs().sum() > 0:
        raise ValueError(f"model {model.name!r} is not differentiable: no finite, non-zero gradient reaches the image")
    return model


def wrap_model(
    module: nn.Module | DepthModel,
    output_kind: str,
    preprocess: Preprocess | None = None,
    name: str | None = None,
    takes_K: bool | None = None,
) -> DepthModel:
    """A checked, frozen :class:`DepthModel` from any module.

    Args:
        module: maps rgb (B, 3, H, W) in [0, 1] (or, with ``preprocess``, the resized, normalised
            image) to (B, 1, H, W); a :class:`DepthModel` is only checked.
        output_kind: one of :data:`kadv.losses.KINDS`: "disparity" (relative inverse depth),
            "depth" (metres), "affine_depth" or "scale_depth".
        preprocess: how to resize and normalise the input first (None: the image as rendered).
        name: a label for reports (defaults to the module's class name).
        takes_K: whether ``module(x, K=K)`` takes the intrinsics (3, 3) or (B, 3, 3) of the image
            it sees (after ``preprocess``), or None when withheld; None: it does when its
            ``forward`` has a parameter named ``K``.

    Raises:
        ValueError: a bad output kind, or a module that fails :func:`check_depth_model`.

    Examples:
        >>> import torch
        >>> from kadv.models import wrap_model
        >>> class Ramp(torch.nn.Module):
        ...     def forward(self, rgb):
        ...         return 1.0 + rgb.mean(dim=1, keepdim=True)
        >>> model = wrap_model(Ramp(), "depth")
        >>> model(torch.rand(1, 3, 24, 32)).shape
        torch.Size([1, 1, 24, 32])
    """
    if isinstance(module, DepthModel):
        return check_depth_model(module)
    if not isinstance(module, nn.Module):
        raise ValueError(f"model {name or module!r} is a {type(module).__name__}, not a torch.nn.Module")
    return check_depth_model(ModuleDepthModel(module, output_kind, name or type(module).__name__, preprocess, takes_K))


def _resolve(target: str) -> Any:
    """``package.module.attr`` or ``path/to/file.py:attr`` -> the attribute."""
    if ":" in target:
        file, _, attr = target.rpartition(":")
        path = Path(file).expanduser()
        if not path.is_file():
            raise ValueError(f"model.target {target!r}: no such file {path}")
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    else:
        module_name, _, attr = target.rpartition(".")
        if not module_name:
            raise ValueError(f"model.target {target!r}: expected package.module.factory or path/to/file.py:factory")
        try:
            module = importlib.import_module(module_name)
        except ImportError as error:
            raise ValueError(f"model.target {target!r}: cannot import {module_name!r} ({error})") from error
    if not hasattr(module, attr):
        raise ValueError(f"model.target {target!r}: {module.__name__!r} has no attribute {attr!r}")
    return getattr(module, attr)


def load_custom(
    target: str,
    output_kind: str,
    args: dict[str, Any] | None = None,
    name: str | None = None,
    preprocess: Preprocess | None = None,
) -> DepthModel:
    """Instantiate ``target(**args)`` and wrap it with :func:`wrap_model`.

    Raises:
        ValueError: an unresolvable or failing target, or a module that fails the checks.
    """
    if not target:
        raise ValueError("model.target is empty: name a factory, e.g. model.target=my_package.make_model")
    factory = _resolve(target)
    if not callable(factory):
        raise ValueError(f"model.target {target!r} is not callable")
    try:
        module = factory(**(args or {}))
    except Exception as error:  # the factory is the user's code; say which call failed
        raise ValueError(
            f"model.target {target!r} failed when called with {args or {}}: {type(error).__name__}: {error}"
        ) from error
    return wrap_model(module, output_kind, preprocess, name or target)
