from __future__ import annotations

import os

from kadv.runtime import configure_runtime  # noqa: E402  (before torch loads)

configure_runtime()

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

from kadv.scenes import Scene, box_room, load_scene  # noqa: E402

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


_REAL_SCENE_USES = ("scenes_root(", "cached_real_scene(", "real_scene_root", "grey_white_room")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark the tests of every module that reads the real scenes ``real_scenes``, so that
    ``pytest -m "not real_scenes"`` runs the rest where the scenes are absent."""
    sources: dict[Path, str] = {}
    for item in items:
        path = Path(str(item.fspath))
        if path not in sources:
            sources[path] = path.read_text() if path.suffix == ".py" else ""
        if any(use in sources[path] for use in _REAL_SCENE_USES):
            item.add_marker(pytest.mark.real_scenes)
