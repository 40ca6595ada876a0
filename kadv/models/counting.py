"""Counting what a depth model runs: the images it runs forward and the backward passes through it,
the currency of an attack's budget (``attack.budget_passes``)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass

import torch

__all__ = ["PassCount", "count_passes"]


@dataclass
class PassCount:
    """Images a model ran forward and backward passes through it, one per image of a batch."""

    forward: int = 0
    backward: int = 0

    @property
    def passes(self) -> int:
        return self.forward + self.backward


@contextlib.contextmanager
def count_passes(model: torch.nn.Module) -> Iterator[PassCount]:
    """Within the block, count each image ``model`` runs on (its first argument's batch) and, when
    a gradient flows back through that output, each image's backward pass.

    Hooks count what runs in Python: a CUDA graph's replay bypasses them, so a search counts its
    own passes (:class:`kadv.attack.Clock`) and this is how tests and runs check that count.

    Examples:
        >>> net = torch.nn.Conv2d(3, 1, 1)
        >>> with count_passes(net) as count:
        ...     net(torch.rand(4, 3, 8, 8, requires_grad=True)).sum().backward()
        ...     _ = net(torch.rand(2, 3, 8, 8))
        >>> count
        PassCount(forward=6, backward=4)
    """
    count = PassCount()

    def backward(batch: int) -> None:
        count.backward += batch

    def forward(module: torch.nn.Module, args: tuple, output: torch.Tensor) -> None:
        batch = len(args[0])
        count.forward += batch
        if isinstance(output, torch.Tensor) and output.requires_grad:
            output.register_hook(lambda grad: backward(batch))

    handle = model.register_forward_hook(forward)
    try:
        yield count
    finally:
        handle.remove()
