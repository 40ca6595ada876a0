"""A guard that fails on any host round trip, and a box room lit by every kind of emitter, shared by
the render's and the attack's round-trip tests."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import torch

from kadv.render import BakeConfig, Shading
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
