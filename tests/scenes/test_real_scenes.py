"""The three real scenes in ../shared/scenes: loaders, counts, textures, file cameras."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import torch

from kadv.render import ExactRenderer
from kadv.scenes import load_scene
from tests.conftest import REAL_SCENES, cached_real_scene

pytestmark = pytest.mark.real_scenes

# Fraction of pixels hit at 320x180 from the file camera, measured by an independent reference.
REFERENCE_HIT_FRACTION = {"grey_white_room": 0.940, "modern_hall": 0.963, "japanese_classroom": 0.972}


def _attribution_triangles(root: Path) -> dict[str, int]:
    counts = {}
    for line in (root / "ATTRIBUTION.md").read_text().splitlines():
        match = re.match(r"\|\s*(\w+)\s*\|.*\|\s*(\d+)k\s*\|[^|]*\|\s*$", line)
        if match:
            counts[match.group(1)] = int(match.group(2)) * 1000
    return counts


def _bitmap_materials(xml: Path) -> set[str]:
    """Ids of the file's BSDFs whose colour comes from a bitmap (not only an opacity mask)."""
    root = ET.parse(xml).getroot()
    return {
        bsdf.get("id")
        for bsdf in root.findall("bsdf")
        if any(t.get("type") == "bitmap" and t.get("name") != "opacity" for t in bsdf.iter("texture"))
    }


@pytest.mark.parametrize("name", REAL_SCENES)
@pytest.mark.parametrize("file", ["scene.xml", "glb"])
def test_real_scene_loads_with_attributed_triangle_count_and_textures(
    real_scene_root: Path, name: str, file: str
) -> None:
    path = real_scene_root / name / (f"{name}.glb" if file == "glb" else file)
    scene = load_scene(path, drop_transparent=False, drop_emitters=False)
    expected = _attribution_triangles(real_scene_root)[name]
    assert abs(scene.num_triangles - expected) <= 0.02 * expected
    textured = {m.name for m in scene.materials if m.texture is not None}
    assert textured == _bitmap_materials(real_scene_root / name / "scene.xml")
    assert all(m.texture.shape[2] == 3 and m.texture.max() <= 1.0 for m in scene.materials if m.texture is not None)


@pytest.mark.parametrize("name", REAL_SCENES)
def test_file_camera_hit_fraction_matches_reference_and_is_bit_identical(name: str) -> None:
    scene = cached_real_scene(name)
    camera = scene.cameras[0]
    renderer = ExactRenderer(scene)
    K = camera.intrinsics(180, 320)
    first = renderer.render(camera.world_T_cam, K, 180, 320)
    assert abs(float(first.mask.float().mean()) - REFERENCE_HIT_FRACTION[name]) <= 0.01
    second = ExactRenderer(scene).render(camera.world_T_cam, K, 180, 320)
    assert torch.equal(first.rgb, second.rgb) and torch.equal(first.depth, second.depth)


def test_file_camera_is_upright(grey_white_room) -> None:
    camera = grey_white_room.cameras[0]
    # image "down" (camera +y) points at the floor (world -y) for an upright camera
    assert float(camera.world_T_cam[1, 1]) < -0.9
