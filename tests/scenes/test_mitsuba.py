from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from kadv.geometry import intrinsics_from_fov
from kadv.render import ExactRenderer, Shading
from kadv.scenes import load_scene

FLAT = Shading(ambient=1.0, diffuse=0.0)

# A 4 m x 3 m wall in the plane z = 5 (built from the unit rectangle), a textured floor, and a
# sensor at the origin looking down +z. The two dialects describe the same scene.
SCENE_05 = """<?xml version="1.0"?>
<scene version="0.5.0">
  <default name="texname" value="tex.png"/>
  <integrator type="path"/>
  <sensor type="perspective">
    <float name="fov" value="{fov}"/>
    <string name="fovAxis" value="{axis}"/>
    <transform name="toWorld"><lookat origin="0, 0, 0" target="0, 0, 1" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/></film>
  </sensor>
  <bsdf type="twosided" id="wall"><bsdf type="diffuse"><srgb name="reflectance" value="#804020"/></bsdf></bsdf>
  <bsdf type="roughplastic" id="floor">
    <texture name="diffuseReflectance" type="bitmap"><string name="filename" value="$texname"/></texture>
  </bsdf>
  <bsdf type="dielectric" id="glass"/>
  <shape type="rectangle">
    <transform name="toWorld"><scale x="2" y="1.5"/><rotate y="1" angle="180"/><translate z="5"/></transform>
    <ref id="wall"/>
  </shape>
  <shape type="rectangle">
    <transform name="toWorld"><scale x="3" y="3"/><rotate x="1" angle="-90"/><translate y="-1"/></transform>
    <ref id="floor"/>
  </shape>
  <shape type="rectangle">
    <transform name="toWorld"><translate z="2" x="30"/></transform>
    <ref id="glass"/>
  </shape>
  <shape type="disk">
    <transform name="toWorld"><translate y="3"/></transform>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter>
  </shape>
</scene>
"""

SCENE_3 = """<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="{fov}"/>
    <string name="fov_axis" value="{axis}"/>
    <transform name="to_world"><lookat origin="0, 0, 0" target="0, 0, 1" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/></film>
  </sensor>
  <bsdf type="twosided" id="wall"><bsdf type="diffuse"><srgb name="reflectance" value="0.50196, 0.25098, 0.12549"/></bsdf></bsdf>
  <bsdf type="roughplastic" id="floor">
    <texture name="diffuse_reflectance" type="bitmap"><string name="filename" value="tex.png"/></texture>
  </bsdf>
  <bsdf type="dielectric" id="glass"/>
  <shape type="rectangle">
    <transform name="to_world"><scale value="2, 1.5, 1"/><rotate value="0, 1, 0" angle="180"/><translate value="0, 0, 5"/></transform>
    <ref id="wall"/>
  </shape>
  <shape type="rectangle">
    <transform name="to_world"><scale value="3"/><rotate value="1, 0, 0" angle="-90"/><translate value="0, -1, 0"/></transform>
    <ref id="floor"/>
  </shape>
  <shape type="rectangle">
    <transform name="to_world"><translate value="30, 0, 2"/></transform>
    <ref id="glass"/>
  </shape>
  <shape type="disk">
    <transform name="to_world"><translate value="0, 3, 0"/></transform>
    <emitter type="area"><rgb name="radiance" value="1"/></emitter>
  </shape>
</scene>
"""


def _write(tmp_path: Path, template: str, fov: float = 60.0, axis: str = "x") -> Path:
    texture = np.zeros((8, 8, 3), np.uint8)
    texture[:, :, 1] = 200
    Image.fromarray(texture).save(tmp_path / "tex.png")
    path = tmp_path / "scene.xml"
    path.write_text(template.format(fov=fov, axis=axis))
    return path


@pytest.mark.parametrize("template", [SCENE_05, SCENE_3], ids=["mitsuba0.5", "mitsuba3"])
def test_both_dialects_give_the_analytic_scene(tmp_path: Path, template: str) -> None:
    scene = load_scene(_write(tmp_path, template))
    assert scene.num_triangles == 4  # glass and the emitter disk dropped
    assert np.allclose(scene.lights, [[0.0, 3.0, 0.0]])
    camera = scene.cameras[0]
    assert camera.fov_x_deg == pytest.approx(60.0)
    # Mitsuba looks down +z with x to the left; our camera also looks down +z, with x right.
    assert torch.allclose(camera.world_T_cam[:3, :3], torch.diag(torch.tensor([-1.0, -1.0, 1.0], dtype=torch.float64)))
    out = ExactRenderer(scene, FLAT).render(camera.world_T_cam, camera.intrinsics(48, 64), 48, 64)
    # Upper image half (y down in our camera = world -y, so rows < 24 look up) sees the wall at z = 5.
    assert torch.allclose(out.depth[0, 0, 10, 32], torch.tensor(5.0), rtol=1e-5)
    assert torch.allclose(out.rgb[0, :, 10, 32], torch.tensor([128, 64, 32]) / 255.0, atol=1e-3)
    # Bottom row sees the textured floor (green texture, untouched by shading with ambient 1).
    assert torch.allclose(out.rgb[0, :, 47, 32], torch.tensor([0.0, 200 / 255.0, 0.0]), atol=1e-3)


def test_dialects_render_identically(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    renders = []
    for folder, template in (("a", SCENE_05), ("b", SCENE_3)):
        scene = load_scene(_write(tmp_path / folder, template))
        camera = scene.cameras[0]
        renders.append(ExactRenderer(scene).render(camera.world_T_cam, camera.intrinsics(48, 64), 48, 64))
    assert torch.equal(renders[0].depth, renders[1].depth)
    assert torch.allclose(renders[0].rgb, renders[1].rgb, atol=1e-4)


def test_options_keep_transparent_and_emitters(tmp_path: Path) -> None:
    scene = load_scene(_write(tmp_path, SCENE_05), drop_transparent=False, drop_emitters=False)
    assert scene.num_triangles == 4 + 2 + 64
    flags = {(m.transparent, m.emissive) for m in scene.materials}
    assert (True, False) in flags and (False, True) in flags


@pytest.mark.parametrize(
    "axis, expected",
    [
        ("x", 60.0),
        ("y", 2 * math.degrees(math.atan(math.tan(math.radians(30)) * 64 / 48))),
        ("diagonal", 2 * math.degrees(math.atan(math.tan(math.radians(30)) * 64 / 80))),
        ("smaller", 2 * math.degrees(math.atan(math.tan(math.radians(30)) * 64 / 48))),
    ],
)
def test_fov_axis_conversion(tmp_path: Path, axis: str, expected: float) -> None:
    scene = load_scene(_write(tmp_path, SCENE_05, fov=60.0, axis=axis))
    assert scene.cameras[0].fov_x_deg == pytest.approx(expected)


def test_primitives_and_nested_bsdfs(tmp_path: Path) -> None:
    Image.fromarray(np.full((4, 4, 4), 255, np.uint8)).save(tmp_path / "alpha.png")
    (tmp_path / "scene.xml").write_text("""<scene version="0.6.0">
      <shape type="cube"><bsdf type="twosided"><bsdf type="plastic"><rgb name="diffuseReflectance" value="0.2"/></bsdf></bsdf></shape>
      <shape type="sphere"><point name="center" x="5" y="0" z="0"/><float name="radius" value="0.5"/>
        <bsdf type="roughconductor"/></shape>
      <shape type="disk"><bsdf type="mask"><texture name="opacity" type="bitmap"><string name="filename" value="alpha.png"/></texture>
        <bsdf type="diffuse"><spectrum name="reflectance" value="400:0.5, 700:0.5"/></bsdf></bsdf></shape>
      <shape type="rectangle"><transform name="toWorld"><matrix value="1 0 0 10 0 1 0 0 0 0 1 0 0 0 0 1"/></transform></shape>
    </scene>""")
    scene = load_scene(tmp_path / "scene.xml")
    assert scene.num_triangles == 12 + 1280 + 64 + 2
    by_count = {int((scene.material_ids == i).sum()): m for i, m in enumerate(scene.materials)}
    assert by_count[12].two_sided and by_count[12].base_color == pytest.approx([0.4845] * 3, abs=1e-3)
    assert by_count[64].opacity is not None
    assert np.allclose(
        scene.vertices[scene.faces[scene.material_ids == scene.material_ids[-1]]].mean(axis=(0, 1))[0], 10.0
    )
    sphere = scene.vertices[np.unique(scene.faces[scene.material_ids == scene.material_ids[12]])]
    assert np.allclose(np.linalg.norm(sphere - [5, 0, 0], axis=1), 0.5, atol=1e-6)
    # the plastic's coat: Mitsuba's defaults (polypropylene in air), linear; other BSDFs are bare
    assert by_count[12].coat_ior == pytest.approx(1.49 / 1.000277) and not by_count[12].coat_nonlinear
    assert by_count[12].roughness == 0.0  # a smooth plastic
    assert by_count[64].coat_ior is None and by_count[1280].coat_ior is None


def test_a_plastic_coat_reads_named_and_numeric_indices(tmp_path: Path) -> None:
    (tmp_path / "scene.xml").write_text("""<scene version="0.6.0">
      <shape type="rectangle"><bsdf type="roughplastic"><string name="intIOR" value="bk7"/>
        <float name="extIOR" value="1.0"/><boolean name="nonlinear" value="true"/>
        <float name="alpha" value="0.25"/></bsdf></shape>
      <shape type="cube"><bsdf type="plastic"><float name="intIOR" value="1.6"/>
        <string name="extIOR" value="unobtainium"/></bsdf></shape>
    </scene>""")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(tmp_path / "scene.xml")
    assert [str(w.message).count("unobtainium") for w in caught] == [1]
    rough, smooth = scene.materials
    assert rough.coat_ior == pytest.approx(1.5046) and rough.coat_nonlinear
    assert smooth.coat_ior == pytest.approx(1.6 / 1.000277) and not smooth.coat_nonlinear
    assert (rough.roughness, smooth.roughness) == (0.25, 0.0)


def test_unknown_elements_warn_once_per_kind(tmp_path: Path) -> None:
    (tmp_path / "scene.xml").write_text("""<scene version="0.5.0">
      <foo/><foo/><bar/>
      <shape type="rectangle"><bsdf type="weird"/></shape>
      <shape type="rectangle"><bsdf type="weird"/></shape>
    </scene>""")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scene(tmp_path / "scene.xml")
    messages = [str(w.message) for w in caught]
    assert sum("<foo>" in m for m in messages) == 1
    assert sum("<bar>" in m for m in messages) == 1
    assert sum("'weird'" in m for m in messages) == 1


def test_missing_file_is_an_error_naming_it_unless_skipped(tmp_path: Path) -> None:
    (tmp_path / "scene.xml").write_text("""<scene version="0.5.0">
      <shape type="obj"><string name="filename" value="models/nothere.obj"/></shape>
      <shape type="rectangle"><bsdf type="diffuse"><texture name="reflectance" type="bitmap">
        <string name="filename" value="gone.png"/></texture></bsdf></shape>
    </scene>""")
    with pytest.raises(FileNotFoundError, match=r"nothere.obj"):
        load_scene(tmp_path / "scene.xml")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(tmp_path / "scene.xml", missing="skip")
    listing = [str(w.message) for w in caught if "skipped missing files" in str(w.message)]
    assert len(listing) == 1 and "nothere.obj" in listing[0] and "gone.png" in listing[0]
    assert scene.num_triangles == 2


@pytest.mark.parametrize(
    "text, message",
    [
        ('<scene version="0.5.0"><integrator type="path"/></scene>', "no shapes"),
        ("<scene><shape", "not well-formed"),
    ],
    ids=["no shapes", "malformed"],
)
def test_a_bad_xml_raises_a_clear_error(tmp_path: Path, text: str, message: str) -> None:
    (tmp_path / "scene.xml").write_text(text)
    with pytest.raises(ValueError, match=message):
        load_scene(tmp_path / "scene.xml")


def test_intrinsics_agree_with_camera(tmp_path: Path) -> None:
    scene = load_scene(_write(tmp_path, SCENE_05))
    assert torch.equal(scene.cameras[0].intrinsics(48, 64), intrinsics_from_fov(60.0, 48, 64))
