"""What every robustness check shares: the modules build on it in one direction."""

from __future__ import annotations

import ast
from pathlib import Path

import kadv.testing


def _imports(module: str) -> set[str]:
    """Every kadv.testing module a module imports, at its top or inside its functions."""
    tree = ast.parse((Path(kadv.testing.__file__).parent / f"{module}.py").read_text())
    found = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module}
    return {name for name in found if name.startswith("kadv.testing.")}


def test_the_check_modules_import_each_other_in_one_direction() -> None:
    # options <- profile <- robustness, and card on top: no module imports one that imports it
    assert not _imports("options") & {"kadv.testing.profile", "kadv.testing.robustness", "kadv.testing.card"}
    assert "kadv.testing.robustness" not in _imports("profile") and "kadv.testing.card" not in _imports("profile")
    assert "kadv.testing.card" not in _imports("robustness")
