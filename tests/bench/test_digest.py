from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import trimesh

from kadv.bench import LENGTH_STEP, scene_digest
from kadv.scenes import box_room, load_scene


def test_the_digest_ignores_rounding_below_its_quanta_and_names_but_not_a_moved_vertex() -> None:
    scene = box_room(seed=0)
    digest = scene_digest(scene)
    # another loader's rounding: every position off by a hundredth of the quantum
    nudged = dataclasses.replace(scene, vertices=scene.vertices + LENGTH_STEP / 100, name="renamed")
    assert scene_digest(nudged) == digest
    moved = scene.vertices.copy()
    moved[0, 1] += 1e-4
    assert scene_digest(dataclasses.replace(scene, vertices=moved)) != digest


def test_the_digest_sees_every_material_field_and_texel() -> None:
    scene = box_room(seed=0)
    digest = scene_digest(scene)
    textured = next(i for i, m in enumerate(scene.materials) if m.texture is not None)
    texture = scene.materials[textured].texture.copy()
    texture[0, 0] = 1.0 - texture[0, 0]  # one texel edited
    for change in (
        {"texture": texture},
        {"roughness": 0.3},
        {"conductor": True},
        {"mirror": True},
        {"base_color": np.array([0.1, 0.2, 0.3], np.float32)},
    ):
        materials = list(scene.materials)
        materials[textured] = dataclasses.replace(materials[textured], **change)
        assert scene_digest(dataclasses.replace(scene, materials=materials)) != digest, change
    renamed = [dataclasses.replace(m, name=f"other{k}") for k, m in enumerate(scene.materials)]
    assert scene_digest(dataclasses.replace(scene, materials=renamed)) == digest


def test_the_same_file_in_two_folders_has_one_digest_and_an_edited_copy_another(tmp_path: Path) -> None:
    mesh = trimesh.creation.box(extents=(4.0, 3.0, 5.0))
    mesh.invert()  # a room seen from inside
    for folder in ("lab_a", "lab_b/deeper"):
        (tmp_path / folder).mkdir(parents=True)
        mesh.export(tmp_path / folder / "room.glb")
    first, second = (scene_digest(load_scene(tmp_path / f / "room.glb")) for f in ("lab_a", "lab_b/deeper"))
    assert first == second
    mesh.vertices[0] += 0.01
    mesh.export(tmp_path / "lab_b" / "deeper" / "room.glb")
    assert scene_digest(load_scene(tmp_path / "lab_b" / "deeper" / "room.glb")) != first


@pytest.mark.real_scenes
def test_the_real_suite_s_scenes_load_with_their_frozen_digests(real_scene_root: Path) -> None:
    from kadv.bench import load_suite

    suite = load_suite("real-v1")
    assert [s.name for s in suite.scenes] == ["grey_white_room", "modern_hall", "japanese_classroom"]
    for scene in suite.scenes:
        assert scene.node["path"].endswith("scene.xml") and len(scene.source["commit"]) == 40
        assert scene.load(real_scene_root).num_triangles > 1000
