"""Every Python block of README.md runs as written, on its own (so the README cannot drift)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.conftest import scenes_root

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)


def test_the_readme_has_python_blocks() -> None:
    assert len(BLOCKS) >= 4


@pytest.mark.real_scenes
@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_python_block_runs(index: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    # the README names the scenes where a checkout finds them; tests honour KADV_TEST_SCENES
    code = BLOCKS[index].replace("../shared/scenes", str(scenes_root()))
    exec(compile(code, f"README.md python block {index + 1}", "exec"), {"__name__": f"readme_block_{index}"})
