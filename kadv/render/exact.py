"""Exact renderer, the output stage: pixel rays cast (:mod:`kadv.render.casting`) against the
scene's surfaces (:mod:`kadv.render.surface`), shaded (:mod:`kadv.render.shading`), and assembled
into images and maps.

All cameras of a call are cast in one batch against casters built once per scene, and shaded on
the casters' device. Values are exact and bit-identical across runs; nothing here carries a gradient.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np
import torch
from torch.nn import functional as F

from kadv.checks import check_shape
from kadv.geometry.camera import pixel_rays
from kadv.render.bake import load_or_bake
from kadv.render.colour import tone_map
from kadv.render.irradiance import BakedLighting
from kadv.render.shading import Shader, Shading, compact_rows
from kadv.render.surface import RayHits, Surfaces
from kadv.scenes.scene import Scene

__all__ = [
    "DEFAULT_MAX_RAYS",
    "ExactRenderer",
    "RayHits",
    "RenderOutput",
    "concatenated",
    "pixel_angle",
    "views_apart",
]

_MIN_HIT_DEPTH = 1e-6  # metres


@dataclass
class RenderOutput:
    """What one exact render returns (B cameras, H x W pixels).

    Attributes:
        rgb: (B, 3, H, W) float32 in [0, 1]; None for a cast without shading (``colour=False``).
        depth: (B, 1, H, W) float32 z-depth in metres, 0 where invalid.
        mask: (B, 1, H, W) bool, True where a ray hit a surface (beyond a micrometre of the eye).
        normals: (B, 3, H, W) float32 world-frame unit normals facing the camera side, 0 if invalid;
            None for a cast without shading.
        triangle_ids: (B, 1, H, W) int64, -1 where invalid.
        points: (B, 3, H, W) float32 world-frame hit points, 0 where invalid.
        back_face: (B, 1, H, W) bool, True where the ray hit the back of a triangle.
    """

    rgb: torch.Tensor | None
    depth: torch.Tensor
    mask: torch.Tensor
    normals: torch.Tensor
    triangle_ids: torch.Tensor
    points: torch.Tensor
    back_face: torch.Tensor

    def to(self, device: torch.device | str) -> RenderOutput:
        """The same maps on ``device``."""
        return RenderOutput(**{f.name: _apply(getattr(self, f.name), lambda t: t.to(device)) for f in fields(self)})

    def cropped(self, border: int) -> RenderOutput:
        """The same maps without ``border`` pixels on each side."""
        inner = (..., slice(border, -border), slice(border, -border))
        return RenderOutput(**{f.name: _apply(getattr(self, f.name), lambda t: t[inner]) for f in fields(self)})


def _apply(tensor: torch.Tensor | None, fn) -> torch.Tensor | None:
    return None if tensor is None else fn(tensor)


def _sub_pixel_rows(rows: torch.Tensor, height: int, width: int, s: int) -> torch.Tensor:
    """(M * s * s,) the rows, in (B, s * height, s * width) images, of the s x s sub-pixel rays of
    the pixels ``rows`` (M,) of (B, height, width) images, each pixel's s * s together."""
    image, pixel = rows // (height * width), rows % (height * width)
    offsets = torch.arange(s, device=rows.device)
    sub_y = (pixel // width * s)[:, None] + offsets.repeat_interleave(s)
    sub_x = (pixel % width * s)[:, None] + offsets.repeat(s)
    return ((image[:, None] * (s * height) + sub_y) * (s * width) + sub_x).reshape(-1)


def pixel_angle(K: torch.Tensor) -> float:
    """Angle in radians one pixel subtends at the image centre (the smallest of the batch)."""
    K = torch.as_tensor(K, dtype=torch.float64).reshape(-1, 3, 3)
    return float(1.0 / torch.maximum(K[:, 0, 0], K[:, 1, 1]).max())


def views_apart(K: torch.Tensor) -> bool:
    """Whether the intrinsics (B, 3, 3) differ over the batch (a searched field of view). Each view
    is then rendered on its own, so that a pixel's footprint (:func:`pixel_angle`: texture
    filtering, the smoothing of reflections) is its own view's and a view renders the same in any batch."""
    K = torch.as_tensor(K)
    return K.ndim == 3 and len(K) > 1 and not bool((K == K[:1]).all())


def concatenated(parts: list):
    """One dataclass of the batches ``parts`` (dataclasses of one type): tensors concatenated along
    the batch, anything else (None, a count) the first's."""
    first = parts[0]
    values = {f.name: getattr(first, f.name) for f in fields(first)}
    joined = {k: torch.cat([getattr(p, k) for p in parts]) for k, v in values.items() if isinstance(v, torch.Tensor)}
    return type(first)(**(values | joined))


DEFAULT_MAX_RAYS = 2**22  # rays cast and shaded at once: about 1 GiB of temporaries (220 bytes a ray, measured)


def _image(values: torch.Tensor, channels: int, batch: int, height: int, width: int) -> torch.Tensor:
    """Per-ray values (B * H * W, channels) as images (B, channels, H, W)."""
    return values.reshape(batch, height, width, channels).permute(0, 3, 1, 2).contiguous()


class ExactRenderer:
    """Ray-cast renderer of a :class:`Scene`: casting, shading and the output maps all run on the
    casters' device, where the scene's data are uploaded once.

    Args:
        scene: the scene; its triangles go into one ray caster reused by every call.
        shading: shading parameters; with ``lighting="baked"`` the scene's lighting is read from the
            bake cache, or baked there first.
        progress: show the bake's progress bar.
        backend: the ray caster: ``"open3d"`` (Embree, CPU), ``"warp"`` (Warp's BVH on ``device``)
            or ``"auto"`` (Warp on CUDA, Open3D on the CPU).
        device: where the rays are cast and shaded.
        max_rays: the most rays cast and shaded at once; a render of more (views x pixels x
            samples) goes through in parts of this many, so that a large batch fits the device.
        baked: lighting already baked for this scene, shaded instead of the cache's (with
            ``lighting="baked"``): the error budget shades one term of the light at a time.
    """

    def __init__(
        self,
        scene: Scene,
        shading: Shading | None = None,
        progress: bool = True,
        backend: str = "auto",
        device: torch.device | str = "cpu",
        max_rays: int = DEFAULT_MAX_RAYS,
        baked: BakedLighting | None = None,
    ) -> None:
        if max_rays < 1:
            raise ValueError(f"render.max_rays must be a positive number of rays, got {max_rays}")
        self.scene = scene
        self.shading = shading or Shading()
        self.max_rays = max_rays
        self.surfaces = Surfaces(scene, backend, device)
        self.device = self.surfaces.device
        self.caster = self.surfaces.caster
        if baked is not None and self.shading.lighting != "baked":
            raise ValueError(
                f"ExactRenderer: baked lighting was given to a renderer with render.lighting={self.shading.lighting}"
            )
        if self.shading.lighting == "baked" and baked is None:
            baked = load_or_bake(self.surfaces, self.shading.bake, progress)
        self.baked = baked
        self.shader = Shader(self.surfaces, self.shading, self.baked)
        self.lights = self.shader.lights

    def cast(self, origins: torch.Tensor | np.ndarray, directions: torch.Tensor | np.ndarray) -> RayHits:
        """First opaque hits of rays (..., 3), flattened, on the renderer's device (:meth:`Surfaces.cast`)."""
        return self.surfaces.cast(origins, directions)

    def intersections(
        self, origins: torch.Tensor | np.ndarray, directions: torch.Tensor | np.ndarray
    ) -> tuple[torch.Tensor, ...]:
        """Every opaque intersection of rays (N, 3), by ray then distance (:meth:`Surfaces.intersections`)."""
        return self.surfaces.intersections(origins, directions)

    def back_facing(self, hits: RayHits, directions: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(N,) True where a ray hit the back of a triangle (:meth:`Surfaces.back_facing`)."""
        return self.surfaces.back_facing(hits, directions)

    def hidden_side(self, hits: RayHits, directions: torch.Tensor | np.ndarray) -> torch.Tensor:
        """(N,) True where a ray met a side of a surface that the scene's free space does not face.

        With direct lighting that is the back of a triangle (:meth:`back_facing`). With baked
        lighting it is a side outside the bake's flood fill from the cameras
        (:meth:`BakedLighting.enclosed_at`), whatever the file's windings: a room whose walls are
        wound outwards is still a room. The fill can leak through a crack into a hollow (under a
        staircase, behind panelling), whose inside then counts as free, as it does for the bake's
        light; sampled init views keep a clearance that no such hollow has room for.
        """
        back = self.back_facing(hits, directions)
        if self.baked is None:
            return back
        return hits.hit & self.baked.enclosed_at(hits.triangle_ids.clamp_min(0), hits.barycentrics.double(), back)

    def cast_and_shade(
        self,
        origins: torch.Tensor,
        directions: torch.Tensor,
        pixel_angle: float,
        colour: bool,
        geometry: bool,
        normals: bool = True,
    ) -> tuple[RayHits, dict[str, torch.Tensor]]:
        """Hits and shaded maps (:meth:`Shader.shade`) of rays (N, 3) float64 on the renderer's
        device, cast and shaded in parts of at most :attr:`max_rays`."""
        parts = []
        for o, d in zip(origins.split(self.max_rays), directions.split(self.max_rays)):
            hits = self.cast(o, d)
            parts.append((hits, self.shader.shade(hits, o, d, pixel_angle, colour, geometry, normals)))
        if len(parts) == 1:
            return parts[0]
        hits = RayHits(*(torch.cat([getattr(h, f.name) for h, _ in parts]) for f in fields(RayHits)))
        return hits, {key: torch.cat([maps[key] for _, maps in parts]) for key in parts[0][1]}

    def _with_reflections(
        self,
        rgb: torch.Tensor,
        triangle_ids: torch.Tensor,
        terms: torch.Tensor,
        hits: RayHits,
        normals: torch.Tensor,
        origins: torch.Tensor,
        directions: torch.Tensor,
        angle: float,
        height: int,
        width: int,
    ) -> torch.Tensor:
        """``rgb`` (B, 3, sH, sW) of s x s rays per pixel, on triangles ``triangle_ids`` (B, 1, sH,
        sW) with reflection ``terms`` (B, 6, sH, sW) (:meth:`Shader.shade`'s "reflecting"), with
        what coats and metals mirror (:meth:`Shader.reflections`) as the pixel-centre rays (B * H *
        W, 3) and their ``hits`` (with shading ``normals`` (B * H * W, 3) turned towards the eye)
        see it, on each of the pixel's rays on the centre ray's surface
        (:meth:`Shader.same_surface`)."""
        batch, _, fine_height, fine_width = rgb.shape
        s = fine_height // height
        mirrored = self.shader.reflections(hits, normals, origins, directions, angle, (batch, height, width))

        def fine(values: torch.Tensor) -> torch.Tensor:
            """(B * sH * sW, C) of per-pixel (B * H * W, C): each pixel's value on its s x s rays."""
            channels = values.shape[1]
            values = values.reshape(batch, height, 1, width, 1, channels)
            return values.expand(-1, -1, s, -1, s, -1).reshape(-1, channels)

        colours = rgb.permute(0, 2, 3, 1).reshape(-1, 3)
        terms = terms.permute(0, 2, 3, 1).reshape(-1, 6)
        rows = compact_rows(mirrored.glossy)
        if rows is None:
            glossy = fine(mirrored.glossy[:, None])[:, 0]
            glossy = glossy & self.shader.same_surface(triangle_ids.reshape(-1), fine(hits.triangle_ids[:, None])[:, 0])
            shown = terms[:, :3] + terms[:, 3:] * fine(mirrored.mirrored)
            colours = torch.where(glossy[:, None], tone_map(shown), colours)
        else:
            sub_rows, centres = _sub_pixel_rows(rows, height, width, s), rows.repeat_interleave(s * s)
            same = self.shader.same_surface(
                triangle_ids.reshape(-1).index_select(0, sub_rows), hits.triangle_ids.index_select(0, centres)
            )
            sub_rows, centres = sub_rows[same], centres[same]
            kept, factor = terms.index_select(0, sub_rows).split(3, dim=1)
            shown = kept + factor * mirrored.mirrored.index_select(0, centres)
            colours = colours.index_copy(0, sub_rows, tone_map(shown))
        return colours.reshape(batch, fine_height, fine_width, 3).permute(0, 3, 1, 2)

    def _pixel_colours(
        self,
        sub_rgb: torch.Tensor,
        sub_ids: torch.Tensor | None,
        sub_terms: torch.Tensor | None,
        hits: RayHits,
        normals: torch.Tensor,
        origins: torch.Tensor,
        directions: torch.Tensor,
        angle: float,
    ) -> torch.Tensor:
        """(B, 3, H, W) pixel colours: the mean of the s x s rays' colours (B, 3, sH, sW), with
        what coats and metals mirror (:meth:`_with_reflections`) where they reflect."""
        height, width = origins.shape[1], origins.shape[3]
        s = sub_rgb.shape[2] // height
        if self.shader.reflecting:
            flat = (origins.reshape(-1, 3), directions.reshape(-1, 3))
            sub_rgb = self._with_reflections(sub_rgb, sub_ids, sub_terms, hits, normals, *flat, angle, height, width)
        return F.avg_pool2d(sub_rgb, s).contiguous() if s > 1 else sub_rgb.contiguous()

    def render(
        self,
        world_T_cam: torch.Tensor,
        K: torch.Tensor,
        height: int,
        width: int,
        supersample: int = 1,
        sub_rgb: torch.Tensor | None = None,
        sub_ids: torch.Tensor | None = None,
        sub_terms: torch.Tensor | None = None,
        colour: bool = True,
    ) -> RenderOutput:
        """Render B cameras in one cast (in parts of :attr:`max_rays` rays when they are more): the
        maps, on the renderer's device.

        Args:
            world_T_cam: (B, 4, 4) or (4, 4) poses (OpenCV camera, metres).
            K: (3, 3) or (B, 3, 3) intrinsics.
            height, width: the image size.
            supersample: s; RGB averages s x s rays per pixel, depth and the other maps come from the
                pixel-centre ray.
            sub_rgb, sub_ids, sub_terms: (B, 3 | 1 | 6, s * height, s * width) the colours of those
                s x s rays, their triangles (-1: none) and reflection terms (:meth:`Shader.shade`'s
                "reflecting"; both where coats and metals reflect), when the caller has already
                shaded them (an anchor render at this pose covers them): they are not cast again.
            colour: shade the colour; False casts the pixel-centre rays alone and returns every
                map but ``rgb`` and the shading ``normals`` (None): a tenth of a shaded render's time.

        Raises:
            ValueError: on a NaN or non-rigid pose, bad intrinsics or a bad size.
        """
        if views_apart(K):
            return self._render_apart(world_T_cam, K, height, width, supersample, sub_rgb, sub_ids, sub_terms, colour)
        origins, directions = pixel_rays(world_T_cam, K, height, width, device=self.device)
        batch, s = origins.shape[0], supersample
        angle, shade_centres = pixel_angle(K), colour and s == 1
        flat = (origins.reshape(-1, 3), directions.reshape(-1, 3))
        hits, maps = self.cast_and_shade(*flat, angle, shade_centres, True, normals=colour)
        image = functools.partial(_image, batch=batch, height=height, width=width)
        rgb = None
        if colour:
            given = (sub_rgb, sub_ids, sub_terms)
            rgb = self._colours(world_T_cam, K, s, angle, hits, maps, origins, directions, given)
        # a ray that meets a surface within a micrometre of the eye starts on it (the eye lies on the
        # surface): it measures no depth, so it is no hit in the mask
        mask = hits.hit & (hits.t > _MIN_HIT_DEPTH)
        return RenderOutput(
            rgb=rgb,
            depth=image(torch.where(mask, hits.t, 0.0), 1),
            mask=image(mask, 1),
            normals=image(maps["normals"], 3) if colour else None,
            triangle_ids=image(hits.triangle_ids, 1),
            points=image(maps["points"], 3),
            back_face=image(maps["back_face"], 1),
        )

    def _colours(self, world_T_cam, K, s: int, angle: float, hits, maps, origins, directions, given) -> torch.Tensor:
        """(B, 3, H, W) the pixels' colours from their s x s rays: those a caller has shaded
        (``given``: sub_rgb, sub_ids, sub_terms, as :meth:`render` takes them), else cast here, or
        with s = 1 the centre rays' ``hits`` and ``maps``."""
        batch, height, width = origins.shape[0], origins.shape[1], origins.shape[3]
        if given[0] is not None:
            sub_rgb, sub_ids, sub_terms = self._given_sub_colours(*given, batch, s, height, width)
        elif s > 1:
            sub_rgb, sub_ids, sub_terms = self._sub_colours(world_T_cam, K, height, width, s, angle)
        else:
            image = functools.partial(_image, batch=batch, height=height, width=width)
            sub_rgb, sub_ids = image(maps["rgb"], 3), image(hits.triangle_ids, 1)
            sub_terms = image(maps["reflecting"], 6) if self.shader.reflecting else given[2]
        return self._pixel_colours(sub_rgb, sub_ids, sub_terms, hits, maps["normals"], origins, directions, angle)

    def _render_apart(self, world_T_cam, K, height, width, supersample, sub_rgb, sub_ids, sub_terms, colour):
        """:meth:`render` of views whose intrinsics differ, one by one (a pixel's footprint is its view's)."""
        pose = world_T_cam.reshape(-1, 4, 4)
        given = {"sub_rgb": sub_rgb, "sub_ids": sub_ids, "sub_terms": sub_terms}
        return concatenated([
            self.render(pose[b : b + 1], K[b], height, width, supersample, colour=colour,
                        **{key: None if value is None else value[b : b + 1] for key, value in given.items()})
            for b in range(len(pose))
        ])  # fmt: skip

    def _given_sub_colours(self, sub_rgb, sub_ids, sub_terms, batch: int, s: int, height: int, width: int) -> tuple:
        """The sub-pixel rays' colours (and, where coats reflect, triangles and reflection terms) a
        caller has shaded, checked and on the renderer's device."""
        if s == 1:
            raise ValueError("sub_rgb: given with supersample 1, where there are no sub-pixel rays")
        check_shape(sub_rgb, f"B 3 {s * height} {s * width}", "sub_rgb", {"B": batch})
        sub_rgb = sub_rgb.to(self.device)
        if self.shader.reflecting:
            for name, given, channels in (("sub_ids", sub_ids, 1), ("sub_terms", sub_terms, 6)):
                if given is None:
                    raise ValueError(f"{name}: needed with the sub-pixel rays' colours when coats reflect")
                check_shape(given, f"B {channels} {s * height} {s * width}", name, {"B": batch})
            sub_ids, sub_terms = sub_ids.to(self.device), sub_terms.to(self.device)
        return sub_rgb, sub_ids, sub_terms

    def _sub_colours(self, world_T_cam, K, height: int, width: int, s: int, angle) -> tuple:
        """The s x s sub-pixel rays of every pixel cast and shaded: their colours (B, 3, sH, sW),
        triangles (B, 1, sH, sW) and, where coats reflect, reflection terms (B, 6, sH, sW)."""
        sub_origins, sub_dirs = pixel_rays(world_T_cam, K, height, width, s, device=self.device)
        sub_hits, sub = self.cast_and_shade(sub_origins.reshape(-1, 3), sub_dirs.reshape(-1, 3), angle / s, True, False)
        batch = sub_origins.shape[0]
        sub_rgb = sub["rgb"].reshape(batch, s * height, s * width, 3).permute(0, 3, 1, 2)
        sub_ids = sub_hits.triangle_ids.reshape(batch, 1, s * height, s * width)
        reflecting = self.shader.reflecting
        terms = sub["reflecting"].reshape(batch, s * height, s * width, 6).permute(0, 3, 1, 2) if reflecting else None
        return sub_rgb, sub_ids, terms
