"""Errors that name a user's input and say how to fix it (commands report them in one line)."""

from __future__ import annotations

__all__ = ["MissingExtra", "WeightsUnavailable", "WriteError"]


class MissingExtra(ImportError):
    """An optional dependency a feature needs is not installed; the message says what to install."""


class WeightsUnavailable(RuntimeError):
    """Network weights (a depth model's, VGG-16's) are neither given, cached nor downloadable."""


class WriteError(OSError):
    """A file could not be written (a full disk, a read-only folder, no permission): a fault of the
    environment, not of the user's input. Its message names the file and the system's error."""

    def __init__(self, path: object, error: OSError) -> None:
        super().__init__(error.errno, f"cannot write {path}: {error.strerror or error}")

    def __str__(self) -> str:
        return str(self.strerror)
