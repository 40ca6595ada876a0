"""The one registry of search methods: config validation, the driver, progress and reports read it.

A method is a function ``search(context, rng, bar) -> InitViewResult`` with a settings dataclass
(its ``attack.<name>`` config node). Black-box methods are written as ask/tell proposers
(:class:`kadv.attack.loop.Proposer`) and registered with :func:`kadv.attack.loop.register_proposer`;
the shared loop owns the budgets, the init view at step 0, the step guard, validity and records.
The built-in methods register themselves when :mod:`kadv.attack` imports :mod:`kadv.attack.methods`.

Dependencies point one way: registry <- search <- loop <- methods <- driver.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["METHODS", "NoSettings", "SearchMethod", "get_method", "register_method"]


@dataclass(frozen=True)
class NoSettings:
    """Settings of a method that has none."""


@dataclass(frozen=True)
class SearchMethod:
    """A registered search method.

    Attributes:
        name: its ``attack.method`` name.
        settings: its settings dataclass (the ``attack.<name>`` node).
        search: ``search(context, rng, bar) -> InitViewResult`` for one init view.
        passes: the model passes (forward and backward) it ends after by itself, given its
            settings (None: it runs until the budget ends).
        check: ``check(settings, passes, supersample=None)`` raises a ValueError naming the
            key when its settings cannot work within a budget of model passes (None: no count limit)
            or with the run's rays per pixel side; called when an attack's config is made (without
            ``supersample``) and before an attack starts (with it).
    """

    name: str
    settings: type
    search: Callable[..., Any]
    passes: Callable[[Any], int | None]
    check: Callable[..., None] = lambda settings, passes, supersample=None: None


METHODS: dict[str, SearchMethod] = {}


def register_method(
    name: str,
    settings: type = NoSettings,
    passes: Callable[[Any], int | None] = lambda settings: None,
    check: Callable[..., None] | None = None,
) -> Callable:
    """Decorator: register ``search(context, rng, bar)`` as method ``name``."""

    def decorate(search: Callable) -> Callable:
        method = SearchMethod(name, settings, search, passes)
        METHODS[name] = method if check is None else dataclasses.replace(method, check=check)
        return search

    return decorate


def get_method(name: str) -> SearchMethod:
    """The method registered as ``name``; a ValueError naming the known ones otherwise."""
    if name not in METHODS:
        raise ValueError(f"attack.method must be one of {', '.join(sorted(METHODS))}, got {name!r}")
    return METHODS[name]
