"""Errors that name a user's input and say how to fix it (commands report them in one line)."""

from __future__ import annotations

__all__ = ["WeightsUnavailable"]


class WeightsUnavailable(RuntimeError):
    """Network weights (a depth model's, VGG-16's) are neither given, cached nor downloadable."""
