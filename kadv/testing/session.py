"""What the pytest plugin sets for the checks a session runs: the budget factor, the folder for
pictures, and who hears of each verdict. Plain Python: outside pytest the defaults hold."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

__all__ = ["CheckSettings", "current", "settings"]


@dataclass(frozen=True)
class CheckSettings:
    """Settings of the checks in force.

    Attributes:
        budget_factor: every check's evaluation budget is multiplied by this (``--kadv-budget``).
        artifacts: the folder for the worst views' pictures; None: a new temporary folder per check.
        observer: called with (result, passed) after each assertion (the plugin's terminal summary).
    """

    budget_factor: float = 1.0
    artifacts: Path | None = None
    observer: Callable[[Any, bool], None] | None = None

    def report(self, result: Any, passed: bool) -> None:
        if self.observer is not None:
            self.observer(result, passed)


# a stack, not one value: a pytest session run inside another (pytester) pushes its own on top
_STACK: list[CheckSettings] = [CheckSettings()]


def current() -> CheckSettings:
    """The settings in force: the innermost :func:`settings` block's, else the defaults."""
    return _STACK[-1]


@contextmanager
def settings(**changes: Any) -> Iterator[CheckSettings]:
    """Within the block, the settings in force with ``changes`` (fields of :class:`CheckSettings`)."""
    _STACK.append(replace(current(), **changes))
    try:
        yield _STACK[-1]
    finally:
        _STACK.pop()
