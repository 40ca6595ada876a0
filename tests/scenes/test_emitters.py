"""Light sources as the bake sees them: Mitsuba's emitters, generated rooms' lamps and sky, transforms."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import OpenEXR
import pytest
import torch
from PIL import Image

from kadv.render.lights import Sky
from kadv.scenes import Emitters, load_scene, procedural_room
from kadv.scenes.emitters import DEFAULT_LAMP_RADIANCE, MISSING_ENVMAP_RADIANCE, SUNSKY_SKY_PER_SCALE

from ..conftest import cached_real_scene

_EMITTERS = """<scene version="0.6.0">
  <shape type="rectangle"><transform name="toWorld"><scale value="5"/></transform></shape>
  <shape type="rectangle">
    <transform name="toWorld"><rotate x="1" angle="90"/><translate y="2"/></transform>
    <emitter type="area"><rgb name="radiance" value="1, 2, 3"/></emitter>
  </shape>
  <emitter type="point"><point name="position" x="1" y="2" z="3"/><rgb name="intensity" value="4"/></emitter>
  <emitter type="spot">
    <transform name="toWorld"><lookat origin="0, 3, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
    <float name="cutoffAngle" value="30"/><spectrum name="intensity" value="2"/>
  </emitter>
  <emitter type="directional"><vector name="direction" x="0" y="-1" z="0"/><rgb name="irradiance" value="5"/></emitter>
  <emitter type="constant"><srgb name="radiance" value="#ffffff"/></emitter>
  <emitter type="projector"><float name="scale" value="1"/></emitter>
</scene>
"""


def test_mitsuba_emitters_are_read_and_an_unbakeable_one_is_named_once(tmp_path: Path) -> None:
    (tmp_path / "scene.xml").write_text(_EMITTERS)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = load_scene(tmp_path / "scene.xml", up_axis="z", scale=2.0)
    named = [str(w.message) for w in caught if "projector" in str(w.message)]
    assert len(named) == 1 and "cannot be baked" in named[0]
    emitters = scene.emitters
    # the emitting rectangle: two triangles of its radiance, moved like the geometry (z up -> y up, x2)
    assert emitters.area_triangles.shape == (2, 3, 3)
    np.testing.assert_allclose(emitters.area_radiance, [[1, 2, 3], [1, 2, 3]])
    np.testing.assert_allclose(emitters.area_triangles[..., 2].max(), -4.0)  # file y = 2 -> world z = -2 x 2
    np.testing.assert_allclose(emitters.point_positions, [[2, 6, -4], [0, 0, -6]], atol=1e-12)
    # the direct shading's lights: the point and spot lights, then the emitting shape's centre
    np.testing.assert_allclose(scene.lights[:2], emitters.point_positions, atol=1e-12)
    np.testing.assert_allclose(emitters.point_intensity, [[4, 4, 4], [2, 2, 2]])
    np.testing.assert_allclose(emitters.spot_cos_cutoff, [-1.0, np.cos(np.radians(30))])
    np.testing.assert_allclose(emitters.spot_directions[1], [0, 0, 1], atol=1e-12)  # file -z -> world +z
    # towards the light: file +y, which a z-up file turns to world -z
    np.testing.assert_allclose(emitters.sun_directions, [[0, 0, -1]], atol=1e-12)
    np.testing.assert_allclose(emitters.sun_irradiance, [[5, 5, 5]])
    np.testing.assert_allclose(emitters.sky_radiance, [1, 1, 1])
    assert not emitters.empty


@pytest.mark.real_scenes
def test_the_shared_scenes_emitters_are_those_the_reference_renders() -> None:
    hall = cached_real_scene("modern_hall").emitters
    # its 13 lamps' shapes, each with the radiance the file gives it (1.5 for the ceiling disks)
    assert len(hall.area_triangles) > 0 and (hall.area_radiance > 0).all() and not hall.sky_radiance.any()
    assert np.isclose(hall.area_radiance, 1.5).all(axis=1).any()
    grey = cached_real_scene("grey_white_room").emitters  # its envmap's .exr is absent
    np.testing.assert_allclose(grey.sky_radiance, MISSING_ENVMAP_RADIANCE)
    classroom = cached_real_scene("japanese_classroom").emitters  # sunsky: skyScale 6, sunScale 10
    np.testing.assert_allclose(classroom.sky_radiance, 6 * SUNSKY_SKY_PER_SCALE)
    np.testing.assert_allclose(classroom.sun_irradiance, [[10, 10, 10]])
    assert classroom.sun_directions[0, 1] > 0  # the sun is above the horizon


def test_generated_rooms_light_by_their_lamps_and_the_sky() -> None:
    room = procedural_room(seed=3)
    lamps = room.emitters.area_triangles
    assert len(lamps) > 0 and np.allclose(room.emitters.area_radiance, DEFAULT_LAMP_RADIANCE)
    normals = np.cross(lamps[:, 1] - lamps[:, 0], lamps[:, 2] - lamps[:, 0])
    assert (normals[:, 1] < 0).all()  # bulbs shine down
    assert (room.emitters.sky_radiance > 0).all()


@pytest.mark.parametrize("suffix", ["png", "exr"])
def test_an_environment_map_is_looked_up_in_latitude_and_longitude(tmp_path: Path, suffix: str) -> None:
    """An 8-bit map decoded from sRGB, an OpenEXR map (half floats, as Mitsuba's gallery ships its
    skies) as stored: the upper half of the image lights the +y hemisphere."""
    image = np.zeros((8, 16, 3), np.float32)
    image[:4] = (1, 0, 0)  # upper half (v < 0.5): the +y hemisphere, red
    image[4:] = (0, 0, 1)
    if suffix == "png":
        Image.fromarray((image * 255).astype(np.uint8)).save(tmp_path / "sky.png")
    else:
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        OpenEXR.File(header, {"RGB": image.astype(np.float16)}).write(str(tmp_path / "sky.exr"))
    (tmp_path / "scene.xml").write_text(
        '<scene version="0.6.0"><shape type="rectangle"/>'
        f'<emitter type="envmap"><string name="filename" value="sky.{suffix}"/><float name="scale" value="2"/>'
        "</emitter></scene>"
    )
    emitters = load_scene(tmp_path / "scene.xml").emitters
    seen = Sky(emitters)(torch.tensor([[0.0, 1.0, 0.0], [0.3, -0.9, 0.3]], dtype=torch.float64)).numpy()
    np.testing.assert_allclose(seen, [[2, 0, 0], [0, 0, 2]])


def test_emitters_refuse_negative_or_infinite_power() -> None:
    with pytest.raises(ValueError, match="finite and >= 0"):
        Emitters(sky_radiance=[-1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="finite and >= 0"):
        Emitters().point([0, 0, 0], [np.inf, 1, 1])
