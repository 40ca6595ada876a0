"""Old names that still answer for one release, each with a ``FutureWarning`` naming the new one."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable

__all__ = ["renamed_attribute", "renamed_exports"]


def _warn(old: str, new: str) -> None:
    warnings.warn(f"{old} was renamed {new}; the old name goes in the next release", FutureWarning, stacklevel=3)


def renamed_exports(package: str, renamed: dict[str, str]) -> Callable[[str], object]:
    """The module-level ``__getattr__`` (PEP 562) of ``package``: each old name of ``renamed`` warns and
    returns the object of its new name (``renamed[old]``, in the package); any other name is an
    ``AttributeError``."""

    def __getattr__(name: str) -> object:
        if name in renamed:
            _warn(f"{package}.{name}", f"{package}.{renamed[name]}")
            return getattr(importlib.import_module(package), renamed[name])
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


class renamed_attribute:
    """A class attribute that reads the attribute ``new`` with a warning: the old name of a field."""

    def __init__(self, new: str) -> None:
        self.new = new

    def __set_name__(self, owner: type, name: str) -> None:
        self.old, self.owner = name, owner.__name__

    def __get__(self, instance: object, owner: type | None = None) -> object:
        if instance is None:
            return self
        _warn(f"{self.owner}.{self.old}", f"{self.owner}.{self.new}")
        return getattr(instance, self.new)
