from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from kadv.scenes import load_scene

OBJ = """mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 3 0 0
v 3 1 0
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl red
f 1/1 2/2 3/3
f 1/1 3/3 4/4
usemtl checker
f 5/1 6/2 7/3
"""
MTL = """newmtl red
Kd 1 0 0
newmtl checker
Kd 1 1 1
map_Kd checker.png
"""


def _checker() -> np.ndarray:
    return ((np.indices((8, 8)).sum(axis=0) % 2) * 255).astype(np.uint8)


def test_obj_with_mtl_keeps_every_material_and_texture(tmp_path: Path) -> None:
    (tmp_path / "scene.obj").write_text(OBJ)
    (tmp_path / "scene.mtl").write_text(MTL)
    Image.fromarray(_checker()).save(tmp_path / "checker.png")
    scene = load_scene(tmp_path / "scene.obj")
    assert scene.num_triangles == 3
    textured = [m for m in scene.materials if m.texture is not None]
    untextured = [m for m in scene.materials if m.texture is None]
    assert len(textured) == 1 and textured[0].texture.shape == (8, 8, 3)
    assert len(untextured) == 1 and np.allclose(untextured[0].base_color, [1, 0, 0])
    assert scene.uvs.shape == (3, 3, 2) and np.allclose(scene.uvs[0], [[0, 0], [1, 0], [1, 1]])


def test_glb_round_trip_with_texture(tmp_path: Path) -> None:
    mesh = trimesh.creation.box()
    uv = np.random.default_rng(0).random((len(mesh.vertices), 2))
    image = Image.fromarray(np.dstack([_checker()] * 3))
    mesh.visual = trimesh.visual.TextureVisuals(
        uv=uv, material=trimesh.visual.material.PBRMaterial(baseColorTexture=image)
    )
    trimesh.Scene(mesh).export(tmp_path / "box.glb")
    scene = load_scene(tmp_path / "box.glb")
    assert scene.num_triangles == 12
    assert scene.materials[0].texture is not None
    assert np.allclose(scene.uvs, uv[np.asarray(mesh.faces)], atol=1e-5)


@pytest.mark.parametrize("suffix", [".ply", ".off", ".stl"])
def test_other_trimesh_formats(tmp_path: Path, suffix: str) -> None:
    mesh = trimesh.creation.box(extents=(2, 3, 4))
    mesh.export(tmp_path / f"box{suffix}")
    scene = load_scene(tmp_path / f"box{suffix}", scale=0.5)
    assert scene.num_triangles == 12
    assert np.allclose(scene.bounds, [[-0.5, -0.75, -1.0], [0.5, 0.75, 1.0]])


def test_z_up_file_is_rotated_to_y_up(tmp_path: Path) -> None:
    mesh = trimesh.creation.box(extents=(1, 2, 4))  # tallest along the file's z
    mesh.export(tmp_path / "box.ply")
    scene = load_scene(tmp_path / "box.ply", up_axis="z")
    assert np.allclose(scene.bounds[1] - scene.bounds[0], [1, 4, 2])


def test_nonexistent_path() -> None:
    with pytest.raises(FileNotFoundError, match=r"nowhere.glb"):
        load_scene("/nonexistent/nowhere.glb")


BAD_FILES = [
    ("scene.fbx", "x", ValueError, "unsupported scene format '.fbx'"),
    ("bad.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", ValueError, "NaN"),
    ("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", ValueError, "area is zero"),
    ("empty.obj", "v 0 0 0\n", ValueError, "no triangle mesh"),
]


@pytest.mark.parametrize("name, text, error, message", BAD_FILES, ids=[b[0] for b in BAD_FILES])
def test_a_bad_file_raises_a_clear_error(tmp_path: Path, name: str, text: str, error: type, message: str) -> None:
    (tmp_path / name).write_text(text)
    with pytest.raises(error, match=message):
        load_scene(tmp_path / name)
