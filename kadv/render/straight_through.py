"""The straight-through idiom: a value from one computation with the gradient of another."""

from __future__ import annotations

import torch

__all__ = ["straight_through"]


def straight_through(x: torch.Tensor, onto: torch.Tensor | None = None) -> torch.Tensor:
    """``onto`` (zero when None) in value, with the gradient of ``x``: ``(onto + x) - x.detach()``.

    The renderer's values come from the exact ray cast, which has no gradient; its gradients come
    from a smooth model of the same image (the reprojection, the edge blend). Evaluated in this
    order, ``onto``'s value is kept to the last bit when x is small beside it.

    >>> x = torch.tensor([2.0], requires_grad=True)
    >>> y = straight_through(3.0 * x)
    >>> y.backward(); (y.item(), x.grad.item())
    (0.0, 3.0)
    """
    return (x if onto is None else onto + x) - x.detach()
