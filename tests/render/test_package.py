"""kadv.render's modules import one another without a circle, and its stages in one direction:
cast -> surface -> shade -> output, with the bake beside the lookup that shading does."""

from __future__ import annotations

import ast
from pathlib import Path

import kadv.render

PACKAGE = Path(kadv.render.__file__).parent


def _imports() -> dict[str, set[str]]:
    """Each module of kadv.render and the modules of kadv.render it imports anywhere: at the top,
    inside functions, and under ``TYPE_CHECKING``."""
    graph = {}
    for path in sorted(PACKAGE.glob("*.py")):
        name = "kadv.render" if path.stem == "__init__" else f"kadv.render.{path.stem}"
        imported = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                imported.add(node.module)
                imported.update(f"{node.module}.{alias.name}" for alias in node.names)
            elif isinstance(node, ast.Import):
                imported.update(alias.name for alias in node.names)
        graph[name] = {m for m in imported if m.startswith("kadv.render.") and m != name}
    return {name: {m for m in imported if m in graph} for name, imported in graph.items()}


def _reaches(graph: dict[str, set[str]], start: str) -> set[str]:
    seen, stack = set(), [start]
    while stack:
        for module in graph[stack.pop()]:
            if module not in seen:
                seen.add(module)
                stack.append(module)
    return seen


def test_no_module_of_the_render_package_imports_itself_through_another() -> None:
    graph = _imports()
    assert len(graph) > 10  # the parser found the modules
    circles = sorted(name for name in graph if name in _reaches(graph, name))
    assert not circles, f"import circles through {circles}"


def test_the_stages_import_downstream_only() -> None:
    graph = _imports()
    reaches = {name: _reaches(graph, name) for name in graph}
    render = "kadv.render."
    later = {
        "casting": ["surface", "shading", "exact", "bake", "warp_caster"],
        "surface": ["shading", "exact", "bake", "irradiance", "lights"],
        "irradiance": ["bake", "shading", "exact"],  # the lookup does not need the estimator
        "bake": ["shading", "exact"],  # the estimator casts through the surfaces, not the renderer
        "shading": ["exact"],
    }
    for stage, downstream in later.items():
        for module in downstream:
            assert render + module not in reaches[render + stage], f"{stage} imports {module}"
    assert render + "shading" in reaches[render + "exact"] and render + "surface" in reaches[render + "shading"]
