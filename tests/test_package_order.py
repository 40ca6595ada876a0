"""kadv's packages import in the order the data flows: each imports only those before it."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "kadv"

# foundations, then scene -> render -> penalty and loss -> model -> search -> what is built on the
# search (datasets, training, the catalogue of named scenes) -> reports -> checks -> commands;
# docs/design.md draws it
ORDER = (
    "errors",
    "checks",
    "interrupts",
    "io",
    "runtime",
    "device",
    "_lazy",
    "_renamed",
    "geometry",
    "scenes",
    "render",
    "penalties",
    "losses",
    "models",
    "attack",
    "datasets",
    "training",
    "catalogue",
    "probes",
    "report",
    "diagnostics",
    "bench",
    "testing",
    "cli",
)


def package_imports(root: Path) -> dict[str, set[tuple[str, str]]]:
    """Per package (or top-level module) of the package at ``root``, the (package, file) pairs it
    imports from, imports inside functions included; the package's ``__init__`` (its facade) aside."""
    name = root.name
    found: dict[str, set[tuple[str, str]]] = {}
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(root)
        if relative == Path("__init__.py"):
            continue
        source = relative.parts[0].removesuffix(".py")
        found.setdefault(source, set())
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                modules = [node.module]
            elif isinstance(node, ast.Import):
                modules = [alias.name for alias in node.names]
            else:
                continue
            for module in modules:
                parts = module.split(".")
                if parts[0] == name and len(parts) > 1 and parts[1] != source:
                    found[source].add((parts[1], str(relative)))
    return found


def out_of_order(imports: dict[str, set[tuple[str, str]]], order: tuple[str, ...]) -> list[str]:
    """Each import of a package by one before it in ``order`` (a cycle has at least one), and each
    package ``order`` leaves out."""
    rank = {name: k for k, name in enumerate(order)}
    wrong = [f"{source} is not in the order" for source in sorted(imports) if source not in rank]
    for source, pairs in sorted(imports.items()):
        for target, path in sorted(pairs):
            if source in rank and target not in rank:
                wrong.append(f"{path} imports kadv.{target}, which the order leaves out")
            elif source in rank and rank[target] >= rank[source]:
                wrong.append(f"{path} imports kadv.{target}, which comes after {source}")
    return wrong


def test_every_package_imports_only_those_before_it() -> None:
    assert out_of_order(package_imports(PACKAGE), ORDER) == []


def test_a_cycle_between_two_packages_is_found_even_through_an_import_inside_a_function(tmp_path) -> None:
    root = tmp_path / "kadv"
    for folder in ("scenes", "render"):
        (root / folder).mkdir(parents=True)
        (root / folder / "__init__.py").write_text("")
    (root / "render" / "cast.py").write_text("from kadv.scenes.scene import Scene\n")
    (root / "scenes" / "photo.py").write_text("def photograph():\n    from kadv.render.cast import cast\n")
    imports = package_imports(root)
    assert out_of_order(imports, ("scenes", "render")) == [
        "scenes/photo.py imports kadv.render, which comes after scenes"
    ]
    assert out_of_order(imports, ("render",)) == [
        "scenes is not in the order",
        "render/cast.py imports kadv.scenes, which the order leaves out",
    ]


def test_the_library_never_imports_hydra() -> None:
    """Only the commands (``kadv.cli``) import Hydra: the library and the benchmark do not."""
    import subprocess
    import sys

    packages = [name for name in ORDER if name != "cli" and (PACKAGE / name).is_dir()]
    code = "; ".join(f"import kadv.{name}" for name in packages) + "; import sys; print('hydra' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "bench" in packages and result.stdout.strip() == "False"
