"""Every Python block of README.md and of the guide in docs/ runs as written, on its own (so they cannot drift)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.conftest import scenes_root

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
BLOCKS = [
    (page.relative_to(ROOT), block)
    for page in PAGES
    for block in re.findall(r"```python\n(.*?)```", page.read_text(), re.S)
]


def test_the_readme_and_the_guide_have_python_blocks() -> None:
    pages = [str(page) for page, _ in BLOCKS]
    assert pages.count("README.md") >= 3 and len(BLOCKS) >= 6


@pytest.mark.real_scenes
@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=[f"{page}-{i}" for i, (page, _) in enumerate(BLOCKS)])
def test_python_block_runs(index: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    page, block = BLOCKS[index]
    # the pages name the scenes where a checkout finds them; tests honour KADV_TEST_SCENES
    code = block.replace("../shared/scenes", str(scenes_root()))
    exec(compile(code, f"{page} python block {index + 1}", "exec"), {"__name__": f"readme_block_{index}"})
