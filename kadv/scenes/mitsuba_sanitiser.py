"""A scene file as Mitsuba 3 loads it: the 0.5/0.6-era gallery files sanitised, with our sensors.

The file's sensors and integrator are replaced by ours (a path tracer), an ``envmap`` whose image is
absent becomes a constant sky, the old ``sunsky`` (whose parameters Mitsuba 3 no longer takes)
becomes a constant sky plus a directional sun, and texture filters Mitsuba 3 dropped become
bilinear. Plain XML: Mitsuba itself is needed only to load the result
(:mod:`kadv.diagnostics.reference`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from kadv.scenes.emitters import MISSING_ENVMAP_RADIANCE, SUNSKY_SKY_PER_SCALE

__all__ = ["MAX_DEPTH", "sanitised_scene_root"]

# Mitsuba's camera looks along +z with +y up and +x to the left: OpenCV's camera turned half a turn about z.
_CV_TO_MITSUBA = np.diag([-1.0, -1.0, 1.0, 1.0])
MAX_DEPTH = 8  # path tracer bounces


def _sensor(world_T_cam: np.ndarray, fov_x_deg: float, height: int, width: int, spp: int) -> ET.Element:
    matrix = " ".join(f"{v:.17g}" for v in (world_T_cam @ _CV_TO_MITSUBA).ravel())
    return ET.fromstring(f"""<sensor type="perspective">
        <float name="fov" value="{fov_x_deg:.17g}"/><string name="fovAxis" value="x"/>
        <transform name="toWorld"><matrix value="{matrix}"/></transform>
        <sampler type="independent"><integer name="sampleCount" value="{spp}"/></sampler>
        <film type="hdrfilm"><integer name="width" value="{width}"/><integer name="height" value="{height}"/>
            <rfilter type="box"/></film></sensor>""")


def sanitised_scene_root(
    path: Path,
    views: list[tuple[np.ndarray, float]],
    height: int,
    width: int,
    spp: int,
    max_depth: int = MAX_DEPTH,
    aovs: bool = False,
) -> ET.Element:
    """The scene file's element tree with our sensors (one per (world_T_cam, fov_x_deg) view) and a
    path tracer of ``max_depth`` bounces; with ``aovs`` the image has six more channels, the
    albedo and the shading normal a denoiser reads.

    The scene must have been loaded by kadv with the default options (metres = file units, y up),
    so that kadv's world frame is the file's.
    """
    root = ET.parse(path).getroot()
    for tag in ("sensor", "integrator"):
        for element in root.findall(tag):
            root.remove(element)
    for emitter in root.findall("emitter"):
        _replace_emitter(root, emitter, path.parent)
    for texture in root.iter("texture"):
        for child in texture:
            # Mitsuba 0.6's "trilinear" and "ewa" mip-map filters are gone; bilinear is the nearest left
            if child.get("name") in ("filterType", "filter_type") and child.get("value") not in ("nearest", "bilinear"):
                child.set("value", "bilinear")
    integrator = f'<integrator type="path"><integer name="maxDepth" value="{max_depth}"/></integrator>'
    if aovs:
        integrator = (
            f'<integrator type="aov"><string name="aovs" value="albedo:albedo,nn:sh_normal"/>{integrator}</integrator>'
        )
    root.insert(0, ET.fromstring(integrator))
    for index, (world_T_cam, fov) in enumerate(views):
        root.insert(1 + index, _sensor(world_T_cam, fov, height, width, spp))
    return root


def _replace_emitter(root: ET.Element, emitter: ET.Element, folder: Path) -> None:
    """Replace an emitter Mitsuba 3 cannot load: an environment map whose image is missing (by a
    constant sky), and Mitsuba 0.6's sun and sky (by a constant sky and a directional sun)."""
    kind = emitter.get("type")
    names = {child.get("name"): child for child in emitter}
    if kind == "envmap" and not (folder / names["filename"].get("value")).is_file():
        root.remove(emitter)
        root.append(
            ET.fromstring(
                f'<emitter type="constant"><rgb name="radiance" value="{MISSING_ENVMAP_RADIANCE}"/></emitter>'
            )
        )
    elif kind == "sunsky":
        root.remove(emitter)
        sky = float(names["skyScale"].get("value")) if "skyScale" in names else 1.0
        root.append(
            ET.fromstring(
                f'<emitter type="constant"><rgb name="radiance" value="{SUNSKY_SKY_PER_SCALE * sky}"/></emitter>'
            )
        )
        sun = names.get("sunDirection")
        if sun is not None:
            direction = [-float(sun.get(axis)) for axis in "xyz"]
            scale = float(names["sunScale"].get("value")) if "sunScale" in names else 1.0
            root.append(
                ET.fromstring(
                    f'<emitter type="directional"><vector name="direction" x="{direction[0]}" '
                    f'y="{direction[1]}" z="{direction[2]}"/><rgb name="irradiance" '
                    f'value="{scale}"/></emitter>'
                )
            )
