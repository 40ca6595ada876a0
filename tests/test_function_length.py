"""kadv's functions stay short: at most three run over 60 lines, docstring included."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "kadv"
LONGEST = 60
ALLOWED = 3


def long_functions(package: Path = PACKAGE, longest: int = LONGEST) -> list[tuple[int, str]]:
    """(lines, "path:name") of every function or method in ``package`` longer than ``longest`` lines."""
    found = []
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > longest:
                    found.append((lines, f"{path.relative_to(package.parent)}:{node.name}"))
    return sorted(found, reverse=True)


def test_at_most_three_functions_run_over_sixty_lines() -> None:
    found = long_functions()
    assert len(found) <= ALLOWED, f"functions over {LONGEST} lines (split one where its parts have names): {found}"


def test_the_count_sees_a_long_function(tmp_path: Path) -> None:
    package = tmp_path / "pkg"
    package.mkdir()
    body = "\n".join(f"    x{k} = {k}" for k in range(61))
    (package / "long.py").write_text(f"def long():\n{body}\n\n\ndef short():\n    return 1\n")
    assert long_functions(package) == [(62, "pkg/long.py:long")]
