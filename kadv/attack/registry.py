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

__all__ = ["METHODS", "NoSettings", "SearchMethod", "check_searchable", "get_method", "register_method"]


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
        gradient: whether it follows the model's gradient (then a model whose prediction is not
            differentiable, a Marigold ensemble, is refused); black-box proposers do not.
    """

    name: str
    settings: type
    search: Callable[..., Any]
    passes: Callable[[Any], int | None]
    check: Callable[..., None] = lambda settings, passes, supersample=None: None
    gradient: bool = True


METHODS: dict[str, SearchMethod] = {}


def register_method(
    name: str,
    settings: type = NoSettings,
    passes: Callable[[Any], int | None] = lambda settings: None,
    check: Callable[..., None] | None = None,
    gradient: bool = True,
) -> Callable:
    """Decorator: register ``search(context, rng, bar)`` as method ``name``."""

    def decorate(search: Callable) -> Callable:
        method = SearchMethod(name, settings, search, passes, gradient=gradient)
        METHODS[name] = method if check is None else dataclasses.replace(method, check=check)
        return search

    return decorate


def get_method(name: str) -> SearchMethod:
    """The method registered as ``name``; a ValueError naming the known ones otherwise."""
    if name not in METHODS:
        raise ValueError(f"attack.method must be one of {', '.join(sorted(METHODS))}, got {name!r}")
    return METHODS[name]


def check_searchable(method: str, model: Any) -> None:
    """Refuse, in one line, a gradient method on a model that is not differentiable as set.

    Raises:
        ValueError: naming ``attack.method`` and the black-box methods that would do.
    """
    if get_method(method).gradient and not getattr(model, "differentiable", True):
        black_box = sorted(name for name, other in METHODS.items() if not other.gradient)
        raise ValueError(
            f"attack.method={method} follows the gradient, and model {getattr(model, 'name', '')!r} is not "
            f"differentiable as set (model.ensemble_size above 1); use a black-box method ({', '.join(black_box)}) "
            "or model.ensemble_size=1"
        )
