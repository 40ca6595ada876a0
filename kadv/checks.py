"""Declared shape checks, in the spirit of kornia's ``KORNIA_CHECK_SHAPE``."""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["check_shape"]


def check_shape(
    x: torch.Tensor | np.ndarray, spec: str, name: str, sizes: dict[str, int] | None = None
) -> dict[str, int]:
    """Check that ``x`` has the shape ``spec`` declares, e.g. ``"B 6"`` or ``"B 3 H W"``.

    Each space-separated entry is a size (``3``) or a name (``B``) that any size satisfies; a name
    seen before (in this spec or in ``sizes``, the result of an earlier check) must repeat its size.

    Returns:
        The sizes the names took, merged into ``sizes``.

    Raises:
        ValueError: naming ``name``, the expected and the actual shape.
    """
    dims = spec.split()
    bound = dict(sizes or {})
    ok = len(x.shape) == len(dims)
    for dim, size in zip(dims, x.shape) if ok else ():
        if dim.isdigit():
            ok &= size == int(dim)
        else:
            ok &= bound.setdefault(dim, size) == size
    if not ok:
        raise ValueError(f"{name}: expected shape ({', '.join(dims)}), got {tuple(x.shape)}")
    return bound
