"""A guard that fails on any host round trip, a box room lit by every kind of emitter, and a short
gradient attack in it: shared by the render's and the attack's round-trip tests and by
``benchmarks/sync_sites.py``."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import replace

import numpy as np
import torch
from tqdm import tqdm

from kadv import ExactRenderer, box_room, load_model, look_at
from kadv.attack import (
    AttackConfig,
    GradientSettings,
    InitView,
    Measures,
    Objective,
    PenaltyConfig,
    SearchContext,
    gradient_ascent,
)
from kadv.losses import depth_loss
from kadv.render import BakeConfig, DifferentiableRenderer, DiffRenderConfig, Shading
from kadv.scenes import Emitters

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
_READS = ("numpy", "__array__", "item", "tolist")
_CONVERSIONS = ("from_numpy", "as_tensor", "tensor")


@contextmanager
def no_host_round_trips(device: str, allow: tuple[tuple[object, str], ...] = ()) -> Iterator[None]:
    """Fail on any read of a tensor's values into the host (``Tensor.numpy``, ``__array__``,
    ``.item()``, ``.tolist()``) and on any numpy array turned into a tensor; on CUDA, on any call
    that waits for the device (``torch.cuda.set_sync_debug_mode("error")``).

    ``allow`` names functions (owner, attribute) inside which reads pass: torch's own reads of
    numbers it keeps on the host by design (Adam's step count), which wait for no device.
    """
    allowed = [0]

    def refuse(name: str, original: Callable, numpy_only: bool) -> Callable:
        def refused(*args, **kwargs):
            if allowed[0] or (numpy_only and not any(isinstance(a, np.ndarray) for a in args)):
                return original(*args, **kwargs)
            raise AssertionError(f"a host round trip inside the step: {name}")

        return refused

    def let_through(original: Callable) -> Callable:
        def run(*args, **kwargs):
            allowed[0] += 1
            try:
                return original(*args, **kwargs)
            finally:
                allowed[0] -= 1

        return run

    reads = {name: getattr(torch.Tensor, name) for name in _READS}
    conversions = {name: getattr(torch, name) for name in _CONVERSIONS}
    exempt = {(owner, name): getattr(owner, name) for owner, name in allow}
    for name, original in reads.items():
        setattr(torch.Tensor, name, refuse(f"Tensor.{name}", original, False))
    for name, original in conversions.items():
        setattr(torch, name, refuse(f"torch.{name} of a numpy array", original, name != "from_numpy"))
    for (owner, name), original in exempt.items():
        setattr(owner, name, let_through(original))
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
        for (owner, name), original in exempt.items():
            setattr(owner, name, original)


def lit_room_emitters(cache: str) -> tuple[Emitters, Shading]:
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
    return emitters, Shading(lighting="baked", bake=BakeConfig(texel=1.0, rays=8, bounces=1, cache=cache))


def corner_attack(device: str, cache: str) -> tuple[Objective, InitView, torch.Tensor]:
    """kadv-tiny + SSIM on the lit box room (Warp's caster on ``device``, its bake cached in
    ``cache``), an init view in a corner, and two restarts' start parameters (2, 6): the init view,
    and one turned and moved 20 cm towards the wall x = 0."""
    emitters, shading = lit_room_emitters(cache)
    renderer = ExactRenderer(replace(box_room(seed=0), emitters=emitters), shading, False, "warp", device)
    objective = Objective(load_model("kadv_tiny"), depth_loss("ssim"), renderer, PenaltyConfig(), device=device)
    pose = look_at(torch.tensor([1.0, 1.4, 1.0]), torch.tensor([3.0, 1.0, 3.5])).double()
    start = torch.tensor([[0.0] * 6, [0.05, -0.03, 0.02, -0.2, 0.0, 0.0]], dtype=torch.float64)
    return objective, InitView("corner", "file", pose, 70.0), start


def gradient_measures(
    objective: Objective,
    view: InitView,
    start: torch.Tensor,
    steps: int,
    size: tuple[int, int],
    edge_search: str,
    around: AbstractContextManager | None = None,
    cuda_graphs: bool = True,
) -> list[Measures]:
    """The measures of a gradient run of ``steps`` steps from ``start`` (R, 6) at ``size`` (H, W),
    its steps inside the context ``around`` (None: none), captured on CUDA with ``cuda_graphs``."""
    config = AttackConfig("gradient", GradientSettings(steps=steps, restarts=len(start)), budget_passes=None)
    render = DiffRenderConfig(edge_search=edge_search, cuda_graphs=cuda_graphs)
    context = SearchContext(
        objective, DifferentiableRenderer(objective.renderer, render, objective.device), view, *size, config
    )
    with tqdm(disable=True) as bar, around or contextlib.nullcontext():
        return gradient_ascent(context, start, steps, config.settings, bar)
