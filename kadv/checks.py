"""Declared checks of inputs: shapes, in the spirit of kornia's ``KORNIA_CHECK_SHAPE``, and values
that may live on a device."""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["check_shape", "check_values"]


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


def check_values(ok: torch.Tensor, message: str) -> None:
    """Refuse values for which ``ok`` (a bool tensor of any shape) is not all True.

    On the CPU this raises at once. On a device it is an asynchronous assertion
    (``torch._assert_async``): the check does not wait for the device, and a failure surfaces as a
    device-side assertion at a later synchronisation, so that a step on the GPU never stops to read
    its own inputs back.

    Raises:
        ValueError: ``message``, on the CPU.

    Examples:
        >>> check_values(torch.isfinite(torch.tensor([1.0, float("nan")])), "x: contains NaN or inf")
        Traceback (most recent call last):
        ...
        ValueError: x: contains NaN or inf
    """
    if ok.device.type == "cpu":
        if not bool(ok.all()):
            raise ValueError(message)
    else:
        torch._assert_async(ok.all(), message)
