"""The packages whose names load on first use: each declared name loads, and only those."""

from __future__ import annotations

import importlib

import pytest

LAZY_PACKAGES = ("kadv", "kadv.models", "kadv.report")


@pytest.mark.parametrize("name", LAZY_PACKAGES)
def test_every_public_name_loads_from_the_module_its_package_names(name: str) -> None:
    package = importlib.import_module(name)
    assert sorted(package.__all__) == sorted(package._EXPORTS)
    for export, module in package._EXPORTS.items():
        assert getattr(package, export) is getattr(importlib.import_module(module), export)
        assert export in dir(package)


@pytest.mark.parametrize("name", LAZY_PACKAGES)
def test_an_unknown_name_is_an_attribute_error_naming_the_package(name: str) -> None:
    package = importlib.import_module(name)
    with pytest.raises(AttributeError, match=f"module '{name}' has no attribute 'no_such_name'"):
        package.no_such_name  # noqa: B018
