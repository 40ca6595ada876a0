"""Mitsuba scene XML importer (0.5/0.6 and 3.x dialects).

Reads shapes (obj, ply, rectangle, cube, disk, sphere) with their ``toWorld``/``to_world``
transforms, BSDF chains reduced to a base colour or texture plus flags, and the perspective sensor.
Mitsuba's camera looks down +z with +y up and +x to the left; kadv's (OpenCV) camera has x right
and y down, so ``world_T_cam = to_world @ diag(-1, -1, 1, 1)``.
"""

from __future__ import annotations

import math
import re
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import trimesh

from kadv.geometry.camera import Camera
from kadv.scenes.emitters import MISSING_ENVMAP_RADIANCE, SUNSKY_SKY_PER_SCALE, Emitters
from kadv.scenes.scene import CONDUCTOR_GREY, Material, MeshPart
from kadv.scenes.textures import linear_to_srgb, load_hdr_image, load_image, srgb_to_linear
from kadv.scenes.trimesh_loader import mesh_parts

__all__ = ["parse_mitsuba"]

_IGNORED = {
    "integrator",
    "sampler",
    "film",
    "rfilter",
    "medium",
    "phase",
    "default",
    "boolean",
    "integer",
    "float",
    "string",
    "rgb",
    "srgb",
    "spectrum",
    "vector",
    "point",
    "transform",
    "ref",
}
_TRANSPARENT = {"dielectric", "thindielectric", "roughdielectric"}
_WRAPPERS = {"twosided", "bumpmap", "normalmap", "blendbsdf", "mixturebsdf", "coating", "roughcoating"}
_DIFFUSE_KEYS = {
    "diffuse": ("reflectance",),
    "roughdiffuse": ("reflectance",),
    "plastic": ("diffuse_reflectance",),
    "roughplastic": ("diffuse_reflectance",),
    "phong": ("diffuse_reflectance",),
    "ward": ("diffuse_reflectance",),
    "principled": ("base_color",),
    "conductor": ("specular_reflectance",),
    "roughconductor": ("specular_reflectance",),
}
# A mirror has no colour of its own; a light grey reads as "shiny surface" in a diffuse render.
_DEFAULT_REFLECTANCE = 0.5
# Mitsuba's named indices of refraction that coats use, and its defaults for plastic
_IOR = {"vacuum": 1.0, "air": 1.000277, "water": 1.333, "acrylic glass": 1.49, "polypropylene": 1.49}
_IOR |= {"bk7": 1.5046, "pet": 1.575, "diamond": 2.419}
_PLASTIC = {"plastic", "roughplastic"}


def _snake(name: str) -> str:
    return re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", name).lower()


def _floats(text: str) -> list[float]:
    return [float(v) for v in re.split(r"[,\s]+", text.strip()) if v]


@dataclass
class _Context:
    root_dir: Path
    missing: str
    ids: dict[str, ET.Element] = field(default_factory=dict)
    defaults: dict[str, str] = field(default_factory=dict)
    warned: set[str] = field(default_factory=set)
    missing_files: list[str] = field(default_factory=list)
    materials: list[Material] = field(default_factory=list)
    material_of: dict[int, int] = field(default_factory=dict)
    images: dict[Path, tuple[np.ndarray, np.ndarray | None]] = field(default_factory=dict)

    def attr(self, element: ET.Element, key: str, default: str | None = None) -> str | None:
        value = element.get(key, default)
        if value is None:
            return None
        return re.sub(r"\$(\w+)", lambda m: self.defaults.get(m.group(1), m.group(0)), value)

    def warn_once(self, kind: str, message: str) -> None:
        if kind not in self.warned:
            self.warned.add(kind)
            warnings.warn(message, stacklevel=4)

    def resolve(self, element: ET.Element) -> ET.Element:
        if element.tag != "ref":
            return element
        ref_id = self.attr(element, "id")
        if ref_id not in self.ids:
            raise ValueError(f"Mitsuba XML: <ref id={ref_id!r}> names no element")
        return self.ids[ref_id]

    def file(self, relative: str) -> Path | None:
        path = (self.root_dir / relative).resolve()
        if path.is_file():
            return path
        if self.missing == "skip":
            self.missing_files.append(relative)
            return None
        raise FileNotFoundError(f"Mitsuba XML references a missing file: {path}")

    def image(self, path: Path) -> tuple[np.ndarray, np.ndarray | None]:
        if path not in self.images:
            self.images[path] = load_image(path)
        return self.images[path]


def _named(element: ET.Element, ctx: _Context) -> dict[str, ET.Element]:
    return {_snake(ctx.attr(child, "name") or child.tag): child for child in element}


def _color(element: ET.Element, ctx: _Context) -> np.ndarray | None:
    """A display colour from an rgb/srgb/spectrum/float element (None for other tags)."""
    tag = element.tag
    value = ctx.attr(element, "value", "")
    if tag == "srgb":
        if value.startswith("#"):
            return np.array([int(value[i : i + 2], 16) for i in (1, 3, 5)]) / 255.0
        values = _floats(value)
        return np.array(values * 3 if len(values) == 1 else values[:3])
    if tag in ("rgb", "float"):
        values = _floats(value)
        return linear_to_srgb(np.array(values * 3 if len(values) == 1 else values[:3]))
    if tag == "spectrum":
        if ":" in value:  # wavelength:value pairs; the mean is a grey of the same brightness
            values = [float(pair.split(":")[1]) for pair in re.split(r"[,\s]+", value.strip()) if ":" in pair]
        else:
            values = _floats(value)
        return linear_to_srgb(np.full(3, float(np.mean(values))))
    return None


def _linear(element: ET.Element | None, ctx: _Context, default: float) -> np.ndarray:
    """Linear RGB of a radiance-like property (rgb/srgb/spectrum/float), unclipped; ``default`` grey if absent."""
    if element is None:
        return np.full(3, default)
    if element.tag == "srgb":
        return srgb_to_linear(_color(element, ctx))
    pairs = [v for v in re.split(r"[,\s]+", ctx.attr(element, "value", "").strip()) if v]
    if element.tag == "spectrum":  # a grey of the mean value (of wavelength:value pairs, or plain values)
        values = [float(v.split(":")[-1]) for v in pairs]
        return np.full(3, float(np.mean(values))) if values else np.full(3, default)
    values = [float(v) for v in pairs] if element.tag in ("rgb", "float") else []
    if not values:
        return np.full(3, default)
    return np.array(values * 3 if len(values) == 1 else values[:3], np.float64)


def _scalar(props: dict[str, ET.Element], key: str, ctx: _Context, default: float) -> float:
    return float(ctx.attr(props[key], "value")) if key in props else default


def _envmap(props: dict[str, ET.Element], ctx: _Context, to_world: np.ndarray, emitters: Emitters) -> Emitters:
    """``emitters`` with an environment map: its image, else (absent or unreadable, as the reference
    renders an absent one: :mod:`kadv.scenes.mitsuba_sanitiser`) a uniform sky."""
    scale = _scalar(props, "scale", ctx, 1.0)
    path = (ctx.root_dir / ctx.attr(props["filename"], "value")).resolve() if "filename" in props else None
    image = None
    if path is not None and path.is_file():
        try:
            image = load_hdr_image(path)
        except ValueError as error:
            ctx.warn_once(f"envmap:{path}", f"Mitsuba XML: {error}; the environment map lights as a uniform sky")
    if image is None:
        return replace(emitters, sky_radiance=emitters.sky_radiance + MISSING_ENVMAP_RADIANCE * scale)
    return replace(emitters, envmap=image * scale, envmap_world_T_map=to_world[:3, :3])


def _emitter(element: ET.Element, ctx: _Context, emitters: Emitters) -> Emitters:
    """``emitters`` with a top-level <emitter> added (file frame); a type the bake cannot use is
    named in one warning and left out."""
    kind = ctx.attr(element, "type")
    props = _named(element, ctx)
    to_world = _transform(props.get("to_world"), ctx)
    if kind == "point":
        position = (
            [float(ctx.attr(props["position"], k, "0")) for k in "xyz"] if "position" in props else to_world[:3, 3]
        )
        return emitters.point(position, _linear(props.get("intensity"), ctx, 1.0))
    if kind == "spot":
        cutoff = _scalar(props, "cutoff_angle", ctx, 20.0)
        beam = _scalar(props, "beam_width", ctx, cutoff * 0.75)
        intensity = _linear(props.get("intensity"), ctx, 1.0)
        return emitters.spot(to_world[:3, 3], intensity, to_world[:3, 2], cutoff, beam)
    if kind == "constant":
        return replace(emitters, sky_radiance=emitters.sky_radiance + _linear(props.get("radiance"), ctx, 1.0))
    if kind == "envmap":
        return _envmap(props, ctx, to_world, emitters)
    if kind in ("sunsky", "sky", "sun"):
        if kind != "sun":
            sky = SUNSKY_SKY_PER_SCALE * _scalar(props, "sky_scale", ctx, 1.0)
            emitters = replace(emitters, sky_radiance=emitters.sky_radiance + sky)
        if kind != "sky" and "sun_direction" in props:
            direction = [float(ctx.attr(props["sun_direction"], axis)) for axis in "xyz"]
            emitters = emitters.sun(direction, _scalar(props, "sun_scale", ctx, 1.0))
        return emitters
    if kind == "directional":
        direction = (
            [float(ctx.attr(props["direction"], axis, "0")) for axis in "xyz"]
            if "direction" in props
            else to_world[:3, 2]
        )
        return emitters.sun(-np.asarray(direction, np.float64), _linear(props.get("irradiance"), ctx, 1.0))
    ctx.warn_once(
        f"emitter:{kind}", f"Mitsuba XML: emitter type {kind!r} cannot be baked; it is left out, the rest is baked"
    )
    return emitters


def _texture(element: ET.Element, ctx: _Context) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray, np.ndarray]:
    """(texture, alpha, base colour, uv scale) of a texture element."""
    kind = ctx.attr(element, "type")
    props = _named(element, ctx)
    uv_scale = np.array(
        [
            float(ctx.attr(props["uscale"], "value")) if "uscale" in props else 1.0,
            float(ctx.attr(props["vscale"], "value")) if "vscale" in props else 1.0,
        ]
    )
    if kind == "bitmap" and "filename" in props:
        path = ctx.file(ctx.attr(props["filename"], "value"))
        if path is None:
            return None, None, np.full(3, _DEFAULT_REFLECTANCE), uv_scale
        texture, alpha = ctx.image(path)
        return texture, alpha, np.ones(3), uv_scale
    if kind == "checkerboard":
        colors = [_color(props[k], ctx) if k in props else np.full(3, v) for k, v in (("color0", 0.4), ("color1", 0.2))]
        cells = (np.indices((64, 64)).sum(axis=0) // 32) % 2 == 0
        texture = np.where(cells[:, :, None], colors[0], colors[1]).astype(np.float32)
        return texture, None, np.ones(3), uv_scale
    ctx.warn_once(f"texture:{kind}", f"Mitsuba XML: texture type {kind!r} is not supported; using grey")
    return None, None, np.full(3, _DEFAULT_REFLECTANCE), uv_scale


def _ior(props: dict[str, ET.Element], key: str, ctx: _Context, default: str) -> float:
    """An index of refraction given as a number or by one of Mitsuba's names."""
    value = ctx.attr(props[key], "value") if key in props else default
    try:
        return float(value)
    except ValueError:
        if value.lower() not in _IOR:
            ctx.warn_once(f"ior:{value}", f"Mitsuba XML: index of refraction {value!r} is not known; using {default}")
        return _IOR.get(value.lower(), _IOR[default])


def _coat(kind: str, props: dict[str, ET.Element], ctx: _Context) -> dict:
    """The dielectric coat of a plastic BSDF as :class:`Material` fields (none for other kinds)."""
    if kind not in _PLASTIC:
        return {}
    ior = _ior(props, "int_ior", ctx, "polypropylene") / _ior(props, "ext_ior", ctx, "air")
    nonlinear = "nonlinear" in props and ctx.attr(props["nonlinear"], "value", "false").lower() == "true"
    return {"coat_ior": ior, "coat_nonlinear": nonlinear}


def _roughness(kind: str, props: dict[str, ET.Element], ctx: _Context) -> float:
    """The GGX roughness of a rough BSDF (Mitsuba's default 0.1); 0 for a smooth one."""
    return _scalar(props, "alpha", ctx, 0.1) if kind in ("roughplastic", "roughconductor") else 0.0


def _material(element: ET.Element, ctx: _Context, name: str) -> Material:
    """Reduce a (possibly nested) BSDF chain to a :class:`Material`."""
    two_sided = False
    opacity = None
    while True:
        element = ctx.resolve(element)
        kind = ctx.attr(element, "type")
        name = ctx.attr(element, "id") or name
        if kind == "mask":
            props = _named(element, ctx)
            source = props.get("opacity")
            if source is not None:
                source = ctx.resolve(source)
                if source.tag == "texture":
                    texture_rgb, alpha, _, _ = _texture(source, ctx)
                    opacity = alpha if alpha is not None or texture_rgb is None else texture_rgb.mean(axis=2)
        elif kind not in _WRAPPERS:
            break
        two_sided |= kind == "twosided"
        inner = [child for child in element if child.tag in ("bsdf", "ref")]
        if not inner:
            return Material(name, two_sided=two_sided, opacity=opacity)
        element = inner[0]
    if kind in _TRANSPARENT:
        return Material(name, transparent=True, two_sided=True)
    if kind not in _DIFFUSE_KEYS:
        ctx.warn_once(f"bsdf:{kind}", f"Mitsuba XML: BSDF type {kind!r} is not supported; using grey diffuse")
        return Material(name, two_sided=two_sided, opacity=opacity)
    props = _named(element, ctx)
    key = next((k for k in _DIFFUSE_KEYS[kind] if k in props), None)
    is_conductor = kind.endswith("conductor")
    base = np.full(3, CONDUCTOR_GREY if is_conductor else linear_to_srgb(_DEFAULT_REFLECTANCE))
    texture, uv_scale = None, np.ones(2)
    if key is not None:
        source = ctx.resolve(props[key])
        if source.tag == "texture":
            texture, _, base, uv_scale = _texture(source, ctx)
        else:
            color = _color(source, ctx)
            base = color if color is not None else base
        if is_conductor:
            base = np.clip(base, 0.0, 1.0) * CONDUCTOR_GREY
    return Material(
        name, base_color=base, texture=texture, opacity=opacity, uv_scale=uv_scale, two_sided=two_sided,
        conductor=is_conductor, roughness=_roughness(kind, props, ctx), **_coat(kind, props, ctx),
    )  # fmt: skip


def _transform(element: ET.Element | None, ctx: _Context) -> np.ndarray:
    """4x4 matrix of a <transform>: each child applied after (left of) the previous ones."""
    matrix = np.eye(4)
    if element is None:
        return matrix
    for op in element:
        get = lambda key, default=None, op=op: ctx.attr(op, key, default)
        step = np.eye(4)
        if op.tag == "matrix":
            step = np.array(_floats(get("value"))).reshape(4, 4)
        elif op.tag == "translate":
            offset = _floats(get("value")) if get("value") else [float(get(k, "0")) for k in "xyz"]
            step[:3, 3] = offset
        elif op.tag == "scale":
            if get("value") is not None:
                values = _floats(get("value"))
                factors = values * 3 if len(values) == 1 else values
            else:
                factors = [float(get(k, "1")) for k in "xyz"]
            step[:3, :3] = np.diag(factors)
        elif op.tag == "rotate":
            axis = np.array(_floats(get("value")) if get("value") else [float(get(k, "0")) for k in "xyz"])
            angle = math.radians(float(get("angle", "0")))
            axis = axis / np.linalg.norm(axis)
            cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            step[:3, :3] = np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross
        elif op.tag == "lookat":
            origin, target = np.array(_floats(get("origin"))), np.array(_floats(get("target")))
            up = np.array(_floats(get("up", "0 1 0")))
            direction = (target - origin) / np.linalg.norm(target - origin)
            left = np.cross(up, direction)
            left /= np.linalg.norm(left)
            step[:3, :3] = np.stack([left, np.cross(direction, left), direction], axis=1)
            step[:3, 3] = origin
        else:
            ctx.warn_once(f"transform:{op.tag}", f"Mitsuba XML: transform <{op.tag}> is not supported; ignored")
            continue
        matrix = step @ matrix
    return matrix


def _primitive(kind: str, props: dict[str, ET.Element], ctx: _Context) -> trimesh.Trimesh | None:
    if kind == "rectangle":
        vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64)
        mesh = trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], process=False)
        mesh.visual = trimesh.visual.TextureVisuals(uv=(vertices[:, :2] + 1) / 2)
        return mesh
    if kind == "cube":
        return trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    if kind == "disk":
        angles = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        rim = np.c_[np.cos(angles), np.sin(angles), np.zeros(64)]
        vertices = np.vstack([[0.0, 0.0, 0.0], rim])
        faces = np.c_[np.zeros(64, int), np.arange(1, 65), np.roll(np.arange(1, 65), -1)]
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        mesh.visual = trimesh.visual.TextureVisuals(uv=(vertices[:, :2] + 1) / 2)
        return mesh
    if kind == "sphere":
        radius = float(ctx.attr(props["radius"], "value")) if "radius" in props else 1.0
        mesh = trimesh.creation.icosphere(subdivisions=3, radius=radius)
        if "center" in props:
            center = props["center"]
            mesh.apply_translation([float(ctx.attr(center, k, "0")) for k in "xyz"])
        return mesh
    if kind in ("obj", "ply"):
        if "filename" not in props:
            raise ValueError(f"Mitsuba XML: <shape type={kind!r}> has no filename")
        path = ctx.file(ctx.attr(props["filename"], "value"))
        if path is None:
            return None
        try:
            return trimesh.load(str(path), force="mesh", process=False)
        except Exception as error:  # trimesh raises many kinds on malformed files
            raise ValueError(f"{path}: could not be read as a mesh ({type(error).__name__}: {error})") from error
    ctx.warn_once(f"shape:{kind}", f"Mitsuba XML: shape type {kind!r} is not supported; skipped")
    return None


def _shape(element: ET.Element, ctx: _Context, index: int) -> MeshPart | None:
    kind = ctx.attr(element, "type")
    props = _named(element, ctx)
    mesh = _primitive(kind, props, ctx)
    if mesh is None:
        return None
    to_world = _transform(props.get("to_world"), ctx)
    bsdfs = [ctx.resolve(child) for child in element if child.tag in ("bsdf", "ref")]
    bsdf = next((b for b in bsdfs if b.tag == "bsdf"), None)
    emitter = next((child for child in element if child.tag == "emitter"), None)
    if emitter is not None:
        kind = ctx.attr(emitter, "type")
        if kind != "area":
            ctx.warn_once(f"emitter:{kind}", f"Mitsuba XML: emitter type {kind!r} on a shape is baked as an area light")
        radiance = _linear(_named(emitter, ctx).get("radiance"), ctx, 1.0)
        ctx.materials.append(Material(f"emitter{index}", emissive=True, emission=radiance))
        key = len(ctx.materials) - 1
    else:  # shapes sharing a BSDF element share one material
        key = id(bsdf)
        if key not in ctx.material_of:
            ctx.material_of[key] = len(ctx.materials)
            ctx.materials.append(_material(bsdf, ctx, f"shape{index}") if bsdf is not None else Material("default"))
        key = ctx.material_of[key]
    flat = "face_normals" in props and ctx.attr(props["face_normals"], "value") == "true"
    return mesh_parts(mesh, to_world, key, f"shape {index} ({kind})", flat_normals=flat)


def _sensor(element: ET.Element, ctx: _Context) -> Camera | None:
    kind = ctx.attr(element, "type")
    if kind not in ("perspective", "thinlens"):
        ctx.warn_once(f"sensor:{kind}", f"Mitsuba XML: sensor type {kind!r} is not supported; skipped")
        return None
    props = _named(element, ctx)
    film = next((child for child in element if child.tag == "film"), None)
    film_props = _named(film, ctx) if film is not None else {}
    width = int(ctx.attr(film_props["width"], "value")) if "width" in film_props else 768
    height = int(ctx.attr(film_props["height"], "value")) if "height" in film_props else 576
    fov = float(ctx.attr(props["fov"], "value")) if "fov" in props else 45.0
    axis = ctx.attr(props["fov_axis"], "value") if "fov_axis" in props else "x"
    half = math.tan(math.radians(fov) / 2.0)
    if axis == "smaller":
        axis = "x" if width <= height else "y"
    elif axis == "larger":
        axis = "x" if width >= height else "y"
    if axis == "y":
        half *= width / height
    elif axis == "diagonal":
        half *= width / math.hypot(width, height)
    to_world = _transform(props.get("to_world"), ctx)
    axes = to_world[:3, :3] @ np.diag([-1.0, -1.0, 1.0])
    axes = axes / np.linalg.norm(axes, axis=0, keepdims=True)
    if np.linalg.det(axes) < 0:
        ctx.warn_once(
            "sensor:mirror", "Mitsuba XML: the sensor transform mirrors the image; kadv renders it unmirrored"
        )
        axes[:, 0] *= -1
    # Re-orthonormalise: exported matrices carry ~1e-6 rounding.
    u, _, vt = np.linalg.svd(axes)
    pose = np.eye(4)
    pose[:3, :3] = u @ vt
    pose[:3, 3] = to_world[:3, 3]
    return Camera(pose, math.degrees(2.0 * math.atan(half)), width, height, name="sensor")


def parse_mitsuba(
    path: Path, missing: str = "error"
) -> tuple[list[MeshPart], list[Material], list[Camera], np.ndarray, Emitters]:
    """Parse a Mitsuba scene file into parts, materials, cameras, light positions and the top-level
    emitters (file frame; area emitters come with their shapes' materials).

    Args:
        path: the ``.xml`` file; relative file names resolve against its folder.
        missing: ``"error"`` to raise on a referenced file that does not exist, ``"skip"`` to leave
            out what needs it and warn once with the list.

    Raises:
        FileNotFoundError: a referenced mesh or texture is missing (with ``missing="error"``).
        ValueError: malformed XML, no shapes, or a dangling reference.
    """
    if missing not in ("error", "skip"):
        raise ValueError(f"missing must be 'error' or 'skip', got {missing!r}")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as error:
        raise ValueError(f"{path}: not well-formed XML ({error})") from error
    if root.tag != "scene":
        raise ValueError(f"{path}: root element is <{root.tag}>, expected <scene>")
    ctx = _Context(root_dir=Path(path).parent, missing=missing)
    for element in root.iter():
        if element.tag == "default":
            ctx.defaults[element.get("name")] = element.get("value")
        if element.get("id") is not None and element.tag != "ref":
            ctx.ids[element.get("id")] = element
    parts, cameras, lights, emitters = [], [], [], Emitters()
    shapes = [element for element in root if element.tag == "shape"]
    if not shapes:
        raise ValueError(f"{path}: the Mitsuba scene defines no shapes")
    for element in root:
        if element.tag == "shape":
            part = _shape(element, ctx, len(parts) + len(ctx.missing_files))
            if part is not None:
                parts.append(part)
        elif element.tag == "sensor":
            camera = _sensor(element, ctx)
            if camera is not None:
                cameras.append(camera)
        elif element.tag == "emitter":
            emitters = _emitter(element, ctx, emitters)
            props = _named(element, ctx)
            # the direct shading's lights: the point and spot lights the file places
            if ctx.attr(element, "type") in ("point", "spot") and ("position" in props or "to_world" in props):
                lights.append(emitters.point_positions[-1])
        elif element.tag in ("bsdf", "texture") or element.tag in _IGNORED:
            continue
        else:
            ctx.warn_once(f"element:{element.tag}", f"Mitsuba XML: element <{element.tag}> is not supported; skipped")
    if ctx.missing_files:
        warnings.warn(f"{path}: skipped missing files: {', '.join(sorted(set(ctx.missing_files)))}", stacklevel=2)
    if not parts:
        raise ValueError(f"{path}: no shape could be loaded")
    return parts, ctx.materials, cameras, np.asarray(lights, np.float64).reshape(-1, 3), emitters
