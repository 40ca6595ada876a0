"""Which ray caster a renderer builds: :data:`BACKENDS`, resolved per device, and the factory.

Warp loads only when a Warp caster is built (importing kadv does not import it).
"""

from __future__ import annotations

import numpy as np
import torch

from kadv.device import resolve_device
from kadv.render.casting import Open3DCaster, RayCaster

__all__ = ["BACKENDS", "make_caster", "resolve_backend"]

BACKENDS = ("auto", "open3d", "warp")


def resolve_backend(backend: str, device: torch.device | str = "cpu") -> str:
    """The backend that ``backend`` names on ``device``: "auto" is Warp on CUDA and Open3D on the CPU.

    Raises:
        ValueError: naming ``render.backend`` when it is none of :data:`BACKENDS`, or Open3D on CUDA.
    """
    if backend not in BACKENDS:
        raise ValueError(f"render.backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    device = resolve_device(device)
    if backend == "auto":
        return "warp" if device.type == "cuda" else "open3d"
    if backend == "open3d" and device.type != "cpu":
        raise ValueError(f"render.backend=open3d casts on the CPU only, not on {device}: use render.backend=warp")
    return backend


def make_caster(
    vertices: np.ndarray, faces: np.ndarray, backend: str = "auto", device: torch.device | str = "cpu"
) -> RayCaster:
    """A :class:`RayCaster` of triangles ``faces`` (F, 3) of ``vertices`` (V, 3) on ``device``."""
    if resolve_backend(backend, device) == "warp":
        from kadv.render.warp_caster import WarpCaster  # imports and initialises Warp

        return WarpCaster(vertices, faces, resolve_device(device))
    return Open3DCaster(vertices, faces)
