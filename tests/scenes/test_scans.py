"""Scans recognised by their layout: Z-up metres, ScanNet's axisAlignment, and the captured colour
shown as it is (render.lighting=auto becomes scanned), every choice overridable."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from kadv.scenes import box_room, load_scene
from kadv.scenes.load import UNLIT_GLTF
from kadv.scenes.scans import recognise_scan
from tests.cli.in_process import call_main

ROOM = (4.0, 5.0, 2.5)  # x, y and, up, z extent in the scans' Z-up metres


def _room_ply(path: Path) -> None:
    """A closed room, inward-facing, Z-up, its floor (z = 0) red, its walls and ceiling grey."""
    box = trimesh.creation.box(extents=ROOM)
    box.apply_translation(np.array(ROOM) / 2)
    box.invert()
    colours = np.where(box.vertices[:, 2:3] < 1e-6, [[200, 30, 30, 255]], [[120, 120, 120, 255]])
    box = trimesh.Trimesh(box.vertices, box.faces, vertex_colors=colours, process=False)
    path.write_bytes(trimesh.exchange.ply.export_ply(box, encoding="binary"))


@pytest.mark.parametrize(
    "name, dataset",
    [
        ("scene0000_00_vh_clean_2.ply", "ScanNet"),
        ("scene0707_01_vh_clean.ply", "ScanNet"),
        ("41069025_3dod_mesh.ply", "ARKitScenes"),
        ("mesh.ply", "Replica"),
        ("mesh.refined.v2.obj", "3RScan"),
        ("00800-TEEsavR23oF.basis.glb", "HM3D"),
        ("bd7e6c2b2a4e4e8c9e0b3f5d1a2c4e6f.obj", "Matterport3D"),
        ("room.ply", None),
        ("scene.xml", None),
    ],
)
def test_scan_layouts_are_recognised_by_their_file_names(name: str, dataset: str | None) -> None:
    layout = recognise_scan(Path("/data") / name)
    assert (layout and layout.dataset) == dataset
    if layout is not None:
        assert (layout.up_axis, layout.scale) == ("z", 1.0)


def test_a_scannet_scan_is_z_up_in_metres_and_moved_by_its_axis_alignment(tmp_path: Path) -> None:
    path = tmp_path / "scene0000_00_vh_clean_2.ply"
    _room_ply(path)
    unaligned = load_scene(path)  # no scene0000_00.txt: identity
    assert unaligned.captured_by == "ScanNet" and unaligned.colors is not None
    # Z-up metres to kadv's y-up: the room's height (2.5 m) is its y extent
    np.testing.assert_allclose(unaligned.bounds[1] - unaligned.bounds[0], [4.0, 2.5, 5.0], atol=1e-6)
    (tmp_path / "scene0000_00.txt").write_text(
        "colorHeight = 968\naxisAlignment = 1 0 0 -2 0 1 0 -2.5 0 0 1 0 0 0 0 1\nsceneType = Bedroom\n"
    )
    aligned = load_scene(path)
    np.testing.assert_allclose(aligned.bounds[0], unaligned.bounds[0] + [-2.0, 0.0, 2.5], atol=1e-6)
    overridden = load_scene(path, up_axis="y", scale=0.5)  # one override each
    np.testing.assert_allclose(overridden.bounds[1] - overridden.bounds[0], [2.0, 2.5, 1.25], atol=1e-6)
    (tmp_path / "scene0000_00.txt").write_text("axisAlignment = 1 0 0\n")
    with pytest.raises(ValueError, match=r"scene0000_00.txt: axisAlignment must be 16 finite numbers"):
        load_scene(path)


def test_kadv_render_shows_a_recognised_scan_as_scanned_and_names_the_lighting(tmp_path: Path) -> None:
    from kadv.cli.render import main as render_main

    path = tmp_path / "41069025_3dod_mesh.ply"  # ARKitScenes: no alignment
    # in kadv's y-up world the file's y runs along -z: eye 1.2 m above the floor, looking down the room
    _room_ply(path)
    args = ["kadv-render", "hydra.run.dir=run", "scene=file", f"scene.path={path}", "render.height=24"]
    args += ["render.width=32", "camera.eye=[2.0,1.2,-1.0]", "camera.target=[2.0,0.0,-4.0]", "camera.fov_x_deg=60"]
    result = call_main(render_main, args, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "run" / "render.json").read_text())
    assert summary["lighting"] == "scanned" and summary["validity"]["verdict"] == "valid"
    baked = call_main(render_main, [*args, "hydra.run.dir=baked", "render.lighting=direct"], cwd=tmp_path)
    assert json.loads((tmp_path / "baked" / "render.json").read_text())["lighting"] == "direct", baked.stderr


def _patched_glb(source: Path, path: Path, patch) -> Path:
    """``source`` (a GLB) written to ``path`` with ``patch`` applied to its JSON chunk."""
    data = source.read_bytes()
    length = int.from_bytes(data[12:16], "little")
    gltf = json.loads(data[20 : 20 + length])
    patch(gltf)
    text = json.dumps(gltf).encode()
    text += b" " * (-len(text) % 4)
    patched = data[:12] + len(text).to_bytes(4, "little") + data[16:20] + text + data[20 + length :]
    path.write_bytes(patched[:8] + len(patched).to_bytes(4, "little") + patched[12:])  # the file's new length
    return path


def test_a_gltf_with_basis_universal_textures_is_refused_naming_the_texture(tmp_path: Path) -> None:
    box = trimesh.creation.box()
    box.export(tmp_path / "plain.glb")

    def basis(gltf: dict) -> None:
        gltf["extensionsUsed"] = ["KHR_texture_basisu"]
        gltf["images"] = [{"name": "floor_atlas", "mimeType": "image/ktx2", "bufferView": 0}]

    path = _patched_glb(tmp_path / "plain.glb", tmp_path / "00800-TEEsavR23oF.basis.glb", basis)
    with pytest.raises(ValueError, match=r"texture 'floor_atlas' is Basis Universal \(image/ktx2\), which kadv cannot"):
        load_scene(path)
    assert load_scene(tmp_path / "plain.glb").num_triangles == 12  # a glTF without them loads


def test_an_obj_whose_texture_atlas_is_missing_is_refused_naming_it(tmp_path: Path) -> None:
    obj = "mtllib house.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl wall\nf 1/1 2/2 3/3\n"
    (tmp_path / "house.obj").write_text(obj)
    (tmp_path / "house.mtl").write_text("newmtl wall\nKd 1 1 1\nmap_Kd -bm 1 atlas/house_0.jpg\n")
    message = r"house.obj: the texture 'atlas/house_0.jpg' of material 'wall' in house.mtl is missing"
    with pytest.raises(ValueError, match=message):
        load_scene(tmp_path / "house.obj")
    (tmp_path / "atlas").mkdir()
    from PIL import Image

    Image.new("RGB", (4, 4), (200, 10, 10)).save(tmp_path / "atlas" / "house_0.jpg")
    (tmp_path / "house.mtl").write_text("newmtl wall\nKd 1 1 1\nmap_Kd atlas/house_0.jpg\n")
    assert load_scene(tmp_path / "house.obj").materials[0].texture is not None
    (tmp_path / "house.mtl").unlink()
    with pytest.raises(ValueError, match=r"house.obj: its material library 'house.mtl' is missing"):
        load_scene(tmp_path / "house.obj")


def test_an_unlit_gltf_shows_its_colour_as_captured(tmp_path: Path) -> None:
    """glTF's KHR_materials_unlit (Habitat's and scan exporters' captured colour): render.lighting=auto
    shows it as scanned, in glTF's own frame (Y-up metres); a lit glTF stays baked."""
    from omegaconf import OmegaConf

    from kadv.cli.common import resolve_lighting

    box = trimesh.creation.box()
    box.visual.vertex_colors = np.tile([[10, 200, 30, 255]], (len(box.vertices), 1))
    box.export(tmp_path / "lit.glb")

    def unlit(gltf: dict) -> None:
        gltf["extensionsUsed"] = ["KHR_materials_unlit"]
        for material in gltf.setdefault("materials", [{}]):
            material.setdefault("extensions", {})["KHR_materials_unlit"] = {}
        for mesh in gltf["meshes"]:
            for primitive in mesh["primitives"]:
                primitive.setdefault("material", 0)

    scene = load_scene(_patched_glb(tmp_path / "lit.glb", tmp_path / "room.glb", unlit))
    assert scene.captured_by == UNLIT_GLTF  # its COLOR_0 is kept beside its material, linear
    np.testing.assert_allclose(scene.colors[0, 0], np.array([10, 200, 30]) / 255.0, atol=1e-6)
    np.testing.assert_allclose(scene.bounds, load_scene(tmp_path / "lit.glb").bounds)  # no axes changed
    render = OmegaConf.create({"lighting": "auto"})
    assert resolve_lighting(scene, render) == "scanned" and render.lighting == "scanned"
    assert resolve_lighting(load_scene(tmp_path / "lit.glb"), OmegaConf.create({"lighting": "auto"})) == "baked"


def test_a_gltf_whose_colours_are_not_one_per_vertex_is_refused_naming_the_mesh(tmp_path: Path) -> None:
    box = trimesh.creation.box()
    box.visual.vertex_colors = np.tile([[10, 200, 30, 255]], (len(box.vertices), 1))
    box.export(tmp_path / "box.glb")

    def miscounted(gltf: dict) -> None:
        gltf["accessors"][gltf["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"]]["count"] = 4

    path = _patched_glb(tmp_path / "box.glb", tmp_path / "bad.glb", miscounted)
    with pytest.raises(ValueError, match=r"bad.glb: 'geometry_0' has 4 COLOR_0 colours for 8 vertices"):
        load_scene(path)


def test_a_photo_textured_mesh_in_no_known_layout_says_its_lighting_and_can_be_said_captured(tmp_path, caplog) -> None:
    """A textured OBJ named as no dataset names its files: lit as a modelled scene, and the log says
    so and how to show it as captured; scene.options.captured=true makes it a scan (scanned under
    render.lighting=auto), captured=false lights a recognised scan again."""
    import logging

    from omegaconf import OmegaConf

    import kadv
    from kadv.cli.common import resolve_lighting
    from kadv.datasets.scan_rooms import scan_like, write_scan
    from kadv.scenes.load import CAPTURED

    obj = write_scan(scan_like(kadv.box_room(seed=0), seed=0), tmp_path, "matterport")
    renamed = obj.with_name("my_phone_scan.obj")
    renamed.write_text(obj.read_text())
    renamed.with_suffix(".mtl").write_text(obj.with_suffix(".mtl").read_text())
    with caplog.at_level(logging.INFO, logger="kadv.scenes.load"):
        plain = load_scene(renamed)
    assert plain.captured_by is None and "scene.options.captured=true shows it as captured" in caplog.text
    assert resolve_lighting(plain, OmegaConf.create({"lighting": "auto"})) == "baked"
    captured = load_scene(renamed, captured=True)
    assert captured.captured_by == CAPTURED
    assert resolve_lighting(captured, OmegaConf.create({"lighting": "auto"})) == "scanned"
    assert load_scene(obj, captured=False).captured_by is None  # a recognised scan, lit again on request
    with pytest.raises(ValueError, match=r"scene.options.captured must be true, false or null, got 'maybe'"):
        load_scene(obj, captured="maybe")
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="kadv.scenes.load"):
        load_scene(obj)
    assert "captured=true" not in caplog.text  # a recognised scan needs no word


def test_a_camera_in_the_files_own_coordinates_renders_what_the_same_camera_in_kadvs_world_does(tmp_path) -> None:
    """A z-up scan (ARKitScenes) and a ScanNet scan moved by its axisAlignment: camera.frame=file
    takes the camera as any viewer of the file would give it; the same numbers in kadv's world land
    elsewhere, and the log says which frame is which, with the matrix between them."""
    import kadv
    from kadv.cli.render import main as render_main
    from kadv.datasets.scan_rooms import write_scan

    arkit = tmp_path / "41069025_3dod_mesh.ply"
    _room_ply(arkit)
    scannet = write_scan(kadv.datasets.scan_rooms.scan_like(kadv.box_room(seed=0), seed=0), tmp_path, "scannet")
    for path, eye, target in ((arkit, [2.0, 1.2, -1.0], [2.0, 0.0, -4.0]), (scannet, [1.0, 1.5, 1.0], [4.0, 1.0, 2.5])):
        world_T_file = kadv.load_scene(path).world_T_file
        file_T_world = np.linalg.inv(world_T_file)
        in_file = [(file_T_world @ [*p, 1.0])[:3].round(9).tolist() for p in (eye, target)]
        up = (file_T_world[:3, :3] @ [0.0, 1.0, 0.0]).round(9).tolist()
        base = ["kadv-render", "scene=file", f"scene.path={path}", "render.height=24", "render.width=32"]
        base += ["camera.fov_x_deg=60", "render.lighting=direct"]
        world = call_main(
            render_main, [*base, "hydra.run.dir=w", f"camera.eye={eye}", f"camera.target={target}"], cwd=tmp_path
        )
        file_args = [f"camera.eye={in_file[0]}", f"camera.target={in_file[1]}", f"camera.up={up}", "camera.frame=file"]
        from_file = call_main(render_main, [*base, "hydra.run.dir=f", *file_args], cwd=tmp_path)
        assert world.returncode == 0 and from_file.returncode == 0, from_file.stderr
        poses = [json.loads((tmp_path / d / "render.json").read_text()) for d in ("w", "f")]
        np.testing.assert_allclose(poses[0]["world_T_cam"], poses[1]["world_T_cam"], atol=1e-6)
        np.testing.assert_allclose(poses[1]["world_T_file"], world_T_file)
        logged = from_file.stdout + from_file.stderr
        assert "a point p of" in logged and "camera.frame=file" in logged
        # the file's numbers read as kadv's world: another view (outside the room, for the z-up scan)
        misread = call_main(
            render_main, [*base, "hydra.run.dir=m", *file_args[:2], "camera.allow_invalid=true"], cwd=tmp_path
        )
        assert misread.returncode == 0
        assert not np.allclose(
            json.loads((tmp_path / "m" / "render.json").read_text())["world_T_cam"], poses[0]["world_T_cam"]
        )
    bad = call_main(render_main, [*base, "hydra.run.dir=b", "camera.frame=viewer"], cwd=tmp_path)
    assert bad.returncode == 2 and "camera.frame must be world or file, got 'viewer'" in bad.stderr


def test_scene_scan_answers_for_a_release_with_a_warning_naming_captured_by() -> None:
    scene = dataclasses.replace(box_room(seed=0), captured_by="ScanNet")
    with pytest.warns(FutureWarning, match="Scene.scan was renamed Scene.captured_by"):
        assert scene.scan == "ScanNet"
