"""Inner and matrix-vector products of 3-vectors, for numpy arrays and torch tensors alike.

The sums over the last axis are written out: a reduction over an axis of length 3 takes several times
as long in both libraries (per-ray code calls these on hundreds of thousands of rays), and the
written-out form adds the same terms in the same order, so results are unchanged to the bit.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import torch

__all__ = ["dot", "mat_vec"]

Array = TypeVar("Array", np.ndarray, torch.Tensor)


def dot(a: Array, b: Array) -> Array:
    """Inner products (...) of 3-vectors ``a`` and ``b`` (..., 3), broadcast."""
    product = a * b
    return product[..., 0] + product[..., 1] + product[..., 2]


def mat_vec(M: Array, x: Array) -> Array:
    """M x (N, ..., 3) for matrices M (N, 3, 3) and vectors x (N, ..., 3)."""
    M = M.reshape(M.shape[:1] + (1,) * (x.ndim - 2) + (3, 3))
    return M[..., 0] * x[..., 0:1] + M[..., 1] * x[..., 1:2] + M[..., 2] * x[..., 2:3]
