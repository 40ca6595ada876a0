from __future__ import annotations

import os

from kadv.runtime import configure_runtime  # before torch loads

configure_runtime()

from pathlib import Path

import pytest

from kadv.scenes import Scene, box_room, load_scene

# pytest's own pytester runs generated test files against kadv's plugin (tests/testing)
pytest_plugins = ["pytester"]

REAL_SCENES = ("grey_white_room", "modern_hall", "japanese_classroom")


def scenes_root() -> Path:
    """The real test scenes: $KADV_TEST_SCENES, else ../shared/scenes from the project root."""
    root = Path(os.environ.get("KADV_TEST_SCENES", Path(__file__).resolve().parents[1].parent / "shared" / "scenes"))
    if not (root / "grey_white_room" / "scene.xml").is_file():
        pytest.fail(f"real test scenes not found at {root}: set KADV_TEST_SCENES to the folder holding them")
    return root


@pytest.fixture(scope="session")
def real_scene_root() -> Path:
    return scenes_root()


_cache: dict[str, Scene] = {}


def cached_real_scene(name: str) -> Scene:
    """Load a real scene's XML once per session (they take a second or two each)."""
    if name not in _cache:
        _cache[name] = load_scene(scenes_root() / name / "scene.xml")
    return _cache[name]


@pytest.fixture(scope="session")
def grey_white_room() -> Scene:
    return cached_real_scene("grey_white_room")


@pytest.fixture(scope="session")
def room() -> Scene:
    return box_room(seed=0)
