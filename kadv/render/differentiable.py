"""DifferentiableRenderer: exact values (or warped ones) with gradients in the camera pose.

One call: pose parameters (omega, delta) -> world_T_cam -> exact ray cast (no gradient) and a
kornia reprojection of the anchor layers (gradient) -> straight-through combination, plus the
silhouette term at occlusion edges. The anchor is refreshed by policy; every call reports how
well the warp agrees with the exact render.

With ``values="exact"`` every call renders the current view exactly (shaded). With
``values="warp"`` only a refresh does: between refreshes a call casts the view's pixel-centre rays
without shading (the warp's depth test needs the exact depth), takes its colours and depths from
the warp, and shades exactly only the pixels no anchor layer holds (holes, sky).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from kadv.checks import check_shape, check_values
from kadv.device import resolve_device
from kadv.geometry.camera import batched_intrinsics
from kadv.geometry.pose import perturb_world_T_cam, pose_distance
from kadv.render.dibr import Reprojection, reproject, warp_boxed
from kadv.render.exact import ExactRenderer, RenderOutput, pixel_angle, views_apart
from kadv.render.layers import RING, AnchorLayers, camera_face_normals, render_anchor, ring_view
from kadv.render.silhouette import EdgePairs, FoundEdges, find_edge_pairs, silhouette_term, track_edge_pairs
from kadv.render.straight_through import straight_through

__all__ = ["DiffRenderConfig", "DiffRenderOutput", "DifferentiableRenderer", "WarpAgreement"]

# Missed pixels hold depth 0; the relative depth error divides by at least this (they are invalid anyway).
_MIN_DEPTH = 1e-6


@dataclass(frozen=True)
class DiffRenderConfig:
    """Options of :class:`DifferentiableRenderer` (``conf/render/``).

    Attributes:
        values: "exact" (values of the exact render, gradients of the warp) or "warp" (values
            of the warp between refreshes; the exact render only validates and refreshes, and a
            refresh's values are exact).
        refresh: "always", "on_drift" (when coverage or errors pass the tolerances) or "every_k".
        every_k: steps between refreshes for "every_k".
        min_coverage: on_drift refreshes when the valid warped fraction of hit pixels drops below.
        max_rgb_error: on_drift tolerance on mean |rgb_warp - rgb_exact| over valid pixels.
        max_depth_error: on_drift tolerance on mean relative depth error over valid pixels.
        layers: anchor depth layers.
        guard_band: extra anchor pixels on each side, for samples that leave the frame when the
            camera has moved since the anchor; with refresh "always" the anchor is only sampled at
            its own pose, within a pixel of the frame, so one pixel is rendered.
        supersample: s x s samples per pixel for the anchor, the exact RGB and the warp's box filter.
        silhouette: add the occlusion-edge term.
        edge_search: how the silhouette term finds its edges (:func:`~kadv.render.find_edge_pairs`):
            "compact" keeps only the candidate pairs at each stage (the fewest rays and operations;
            on a GPU each stage waits for its count), "every_pair" computes every neighbour pair and
            marks the candidates (nothing waits, and every shape is fixed; the arithmetic grows
            with the pixels), "auto" every_pair where the step is captured, else compact.
        cuda_graphs: on CUDA, capture the gradient step in a CUDA graph and replay it
            (:class:`~kadv.attack.capture.StepGraph`) where the anchor is rendered on every step
            (``refresh="always"``); off for debugging.
        anchor_reach_deg, anchor_reach_m: how far a view may lie from its anchor (rotation angle in
            degrees, camera centre distance in metres) and still be warped from it; a view beyond
            either renders a new anchor first, whatever ``refresh`` says. The warp's gradients are
            checked out to this distance (``benchmarks/gradcheck.py``), and Adam's steps at the
            default rates carry a view up to 8 degrees and 20 cm from its anchor in 4 steps. The
            poses are compared on the host: on a GPU such a step waits for its poses.
        depth_tolerance: relative disagreement between a warped point and the exact one that
            invalidates a pixel.
        plane_tolerance: at the anchor's own pose, relative distance from a tap's surface plane
            above which the warp takes the tap to belong to another surface.
    """

    values: str = "exact"
    refresh: str = "always"
    every_k: int = 5
    min_coverage: float = 0.9
    max_rgb_error: float = 0.02
    max_depth_error: float = 0.01
    layers: int = 1
    guard_band: int = 16
    supersample: int = 2
    silhouette: bool = True
    edge_search: str = "auto"
    cuda_graphs: bool = True
    anchor_reach_deg: float = 4.0
    anchor_reach_m: float = 0.1
    depth_tolerance: float = 0.01
    plane_tolerance: float = 0.02

    def __post_init__(self) -> None:
        if self.values not in ("exact", "warp"):
            raise ValueError(f"render.differentiable.values must be 'exact' or 'warp', got {self.values!r}")
        if self.refresh not in ("always", "on_drift", "every_k"):
            raise ValueError(
                f"render.differentiable.refresh must be 'always', 'on_drift' or 'every_k', got {self.refresh!r}"
            )
        if self.edge_search not in ("auto", "compact", "every_pair"):
            raise ValueError(
                f"render.differentiable.edge_search must be 'auto', 'compact' or 'every_pair', got {self.edge_search!r}"
            )
        if not isinstance(self.cuda_graphs, bool):
            raise ValueError(f"render.differentiable.cuda_graphs must be true or false, got {self.cuda_graphs!r}")
        if self.layers < 1 or self.supersample < 1 or self.guard_band < 0 or self.every_k < 1:
            raise ValueError(
                "render.differentiable.layers, supersample and every_k must be >= 1 and guard_band >= 0, got "
                f"{self.layers}, {self.supersample}, {self.every_k} and {self.guard_band}"
            )
        if not (self.anchor_reach_deg > 0 and self.anchor_reach_m > 0):
            raise ValueError(
                "render.differentiable.anchor_reach_deg and anchor_reach_m must be positive, got "
                f"{self.anchor_reach_deg} and {self.anchor_reach_m}"
            )
        if not (self.depth_tolerance > 0 and self.plane_tolerance > 0):
            raise ValueError(
                "render.differentiable.depth_tolerance and plane_tolerance must be positive, got "
                f"{self.depth_tolerance} and {self.plane_tolerance}"
            )


@dataclass
class DiffRenderOutput:
    """Differentiable render of B views.

    Attributes:
        rgb: (B, 3, H, W); depth: (B, 1, H, W) z-depth (0 invalid); mask: (B, 1, H, W) bool; on
            the renderer's device.
        exact: the exact render at the current poses (no gradient), on the exact renderer's device;
            between refreshes under ``values="warp"``, a cast without shading (its ``rgb`` and ``normals`` None).
        world_T_cam: (B, 4, 4) current poses (differentiable), on the pose parameters' device.
        coverage: (B,) fraction of hit pixels with a valid warp; it and the errors on the renderer's device.
        rgb_error: (B,) mean |rgb_warp - rgb_exact| over valid pixels (NaN where the values
            came from the warp: no exact colour was rendered to compare).
        depth_error: (B,) mean |depth_warp - depth_exact| / depth_exact over valid pixels.
        refreshed: whether the anchor was re-rendered at the current poses in this call.
        warped: whether the values came from the warp, between refreshes (a cheap fidelity that
            no exact render has confirmed).
    """

    rgb: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor
    exact: RenderOutput
    world_T_cam: torch.Tensor
    coverage: torch.Tensor
    rgb_error: torch.Tensor
    depth_error: torch.Tensor
    refreshed: bool
    warped: bool = False


@dataclass
class _ExactFrame:
    """One call's exact frame: ``rendered`` (the frame and its ring, on the caster's device),
    ``exact`` (the frame), ``K`` of ``rendered``, the index of the frame ``inside`` it, and on the
    renderer's device the ring's rgb (B, 3, ...) and depth, the frame's rgb, depth, mask and
    camera-frame normals (None where the values come from the warp)."""

    rendered: RenderOutput
    exact: RenderOutput
    K: torch.Tensor
    inside: tuple
    rgb_rendered: torch.Tensor
    depth_rendered: torch.Tensor
    rgb: torch.Tensor
    depth: torch.Tensor
    mask: torch.Tensor
    normals: torch.Tensor | None


class DifferentiableRenderer:
    """Renders images and depth differentiable in the pose parameters (omega, delta).

    Args:
        renderer: the scene's exact renderer.
        config: options.
        device: where the reprojection and the silhouette term run (see :mod:`kadv.device`); the
            ray casts run on the exact renderer's device.
    """

    def __init__(
        self, renderer: ExactRenderer, config: DiffRenderConfig | None = None, device: str | torch.device = "cpu"
    ) -> None:
        self.renderer = renderer
        self.config = config or DiffRenderConfig()
        self.device = resolve_device(device)
        self.anchor: AnchorLayers | None = None
        self._anchor_key: _ViewKey | None = None
        self._steps_since_refresh = 0
        self._exact_next = False
        # the last edge search's pairs and crossing points, followed between refreshes
        self._searched_edges: FoundEdges | None = None

    @property
    def compact_edges(self) -> bool:
        """Whether the edge search compacts its candidates: ``auto`` does but where the gradient
        step is captured (CUDA with ``cuda_graphs``: a captured step waits for no count)."""
        if self.config.edge_search == "auto":
            return not (self.config.cuda_graphs and self.config.refresh == "always" and self.device.type == "cuda")
        return self.config.edge_search == "compact"

    @property
    def _guard_band(self) -> int:
        return min(self.config.guard_band, 1) if self.config.refresh == "always" else self.config.guard_band

    def reset(self) -> None:
        """Forget the anchor (the next call renders a new one)."""
        self.anchor = None
        self._anchor_key = None
        self._searched_edges = None

    def validate_next(self) -> None:
        """Render the next call's views exactly (values from the exact render, as at a refresh),
        keeping the anchor: how a search under ``values="warp"`` confirms the views it ends on."""
        self._exact_next = True

    def _refresh(self, world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int) -> AnchorLayers:
        """Render a new anchor at ``world_T_cam``; returns it on the CPU and keeps it on the device."""
        c = self.config
        anchor = render_anchor(self.renderer, world_T_cam, K, height, width, c.layers, self._guard_band, c.supersample)
        self.anchor = anchor.to(self.device)
        self._anchor_key = _view_key(K, height, width)
        self._steps_since_refresh = 0
        return anchor

    def __call__(
        self, pose_params: torch.Tensor, base_world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int
    ) -> DiffRenderOutput:
        return self.forward(pose_params, base_world_T_cam, K, height, width)

    def forward(
        self, pose_params: torch.Tensor, base_world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int
    ) -> DiffRenderOutput:
        """Render at poses ``base_world_T_cam`` perturbed by ``pose_params``.

        Args:
            pose_params: (B, 6) = (omega, delta): rotation vector in the camera frame and centre
                offset in world metres; usually ``requires_grad``.
            base_world_T_cam: (B, 4, 4) poses at pose_params = 0.
            K: (3, 3) or (B, 3, 3) intrinsics; the render is differentiable in them where they
                require a gradient (a searched field of view).
            height: image height.
            width: image width.
        """
        check_shape(pose_params, "B 6", "pose_params")
        check_values(torch.isfinite(pose_params.detach()), "pose_params: contain NaN or inf")
        base = torch.as_tensor(base_world_T_cam, dtype=torch.float64).reshape(-1, 4, 4)
        world_T_cam = perturb_world_T_cam(base, pose_params[:, :3].double(), pose_params[:, 3:].double())
        K_view = batched_intrinsics(K, base.shape[0])  # the warps' and the edges' (differentiable)
        K = K_view.detach()  # the casts'
        current = world_T_cam.detach()
        refreshed = self._due_for_refresh(current, K, height, width)
        warped, exact_next, self._exact_next = False, self._exact_next, False
        if self.config.values == "warp" and not (refreshed or exact_next):
            frame, agreement = self._warped_frame(current, world_T_cam, K_view, height, width)
            # an anchor that drifted too far is rendered again, and the view with it
            refreshed = self.config.refresh == "on_drift" and agreement.drifted(self.config)
            warped = not refreshed
        if not warped:
            anchor = self._refresh(current, K, height, width) if refreshed else None
            frame = self._exact_frame(current, K, height, width, anchor)
            warp, agreement, refreshed = self._checked_warp(frame, world_T_cam, K_view, height, width, refreshed)
            rgb, depth = self._values(frame, warp)
        else:
            rgb, depth = frame.rgb, frame.depth
        self._steps_since_refresh += 1
        if self.config.silhouette:
            pairs = self._edge_pairs(frame, current, warped)
            K_edges = self._render_view(K_view, height, width)[1]  # frame.K, differentiable as K_view is
            values = torch.cat([frame.rgb_rendered, frame.depth_rendered], dim=1)
            term = silhouette_term(self.renderer, pairs, world_T_cam, K_edges, values)[frame.inside]
            rgb, depth = rgb + term[:, :3], depth + term[:, 3:]
        return DiffRenderOutput(
            rgb=rgb,
            depth=depth,
            mask=frame.mask,
            exact=frame.exact,
            world_T_cam=world_T_cam,
            coverage=agreement.coverage,
            rgb_error=agreement.rgb_error,
            depth_error=agreement.depth_error,
            refreshed=refreshed,
            warped=warped,
        )

    def _edge_pairs(self, frame: _ExactFrame, current: torch.Tensor, warped: bool) -> EdgePairs:
        """The occlusion edges of the frame: searched in an exact frame, and under ``values="warp"``
        followed from the last search between refreshes (:func:`~kadv.render.track_edge_pairs`),
        which casts no ray."""
        if warped:
            return track_edge_pairs(self.renderer, self._searched_edges, frame.rendered, current, frame.K)
        pairs = find_edge_pairs(self.renderer, frame.rendered, current, frame.K, self.compact_edges)
        if self.config.values == "warp":
            self._searched_edges = FoundEdges.of(self.renderer, pairs, frame.rendered, current, frame.K)
        return pairs

    def _due_for_refresh(self, world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int) -> bool:
        c = self.config
        return (
            self.anchor is None
            or _view_key(K, height, width) != self._anchor_key
            or c.refresh == "always"
            or (c.refresh == "every_k" and self._steps_since_refresh >= c.every_k)
            or self._beyond_reach(world_T_cam)
        )

    def anchor_distance(self, world_T_cam: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """How far views (B, 4, 4) lie from the anchor (:func:`~kadv.geometry.pose_distance`, read on
        the host): the rotation angle (B,) in radians and the centre distance (B,) in metres."""
        return pose_distance(*(pose.detach().double().cpu() for pose in (self.anchor.world_T_cam, world_T_cam)))

    def _beyond_reach(self, world_T_cam: torch.Tensor) -> bool:
        """Whether any of the views (B, 4, 4) lies farther from the anchor than
        ``anchor_reach_deg`` or ``anchor_reach_m``."""
        turned, moved = self.anchor_distance(world_T_cam)
        c = self.config
        return bool(((turned > math.radians(c.anchor_reach_deg)) | (moved > c.anchor_reach_m)).any())

    def _exact_frame(
        self, current: torch.Tensor, K: torch.Tensor, height: int, width: int, anchor: AnchorLayers | None
    ) -> _ExactFrame:
        """The exact render at the current poses and what the device needs of it, moved once."""
        border, K_render, render_height, render_width, inside = self._render_view(K, height, width)
        rendered = self._exact_render(current, K_render, render_height, render_width, border, anchor)
        exact = rendered.cropped(border) if border else rendered
        normals = camera_face_normals(self.renderer.surfaces, exact.triangle_ids[:, 0], current).permute(0, 3, 1, 2)
        rgb_rendered, depth_rendered = rendered.rgb.to(self.device), rendered.depth.to(self.device)
        return _ExactFrame(
            rendered,
            exact,
            K_render,
            inside,
            rgb_rendered,
            depth_rendered,
            rgb_rendered[inside],
            depth_rendered[inside],
            exact.mask.to(self.device),
            normals.to(self.device),
        )

    def _warped_frame(
        self, current: torch.Tensor, world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int
    ) -> tuple[_ExactFrame, WarpAgreement]:
        """The frame's values from the warp: the view (with its ring) cast without shading for
        the depth test, the anchor warped onto it (differentiable in the intrinsics ``K`` too), and
        the pixels no layer holds shaded exactly. Its agreement: the warp's coverage and depth
        error against the cast (no exact colour)."""
        border, K_warp, render_height, render_width, inside = self._render_view(K, height, width)
        K_render = K_warp.detach()
        cast = self.renderer.render(current, K_render, render_height, render_width, colour=False)
        cast_depth = cast.depth.to(self.device)
        A_T_P = torch.linalg.inv_ex(self.anchor.world_T_cam)[0] @ world_T_cam  # inv_ex: no wait for its check
        normals = camera_face_normals(self.renderer.surfaces, cast.triangle_ids[:, 0], current).permute(0, 3, 1, 2)
        warp = warp_boxed(
            self.anchor.boxed, cast_depth, normals.to(self.device), A_T_P, K_warp, self.config.depth_tolerance
        )
        holes = self._shade_holes(current, K_render, render_height, render_width, ~warp.valid)
        rgb = torch.where(warp.valid, warp.rgb, holes)
        depth = torch.where(warp.valid, warp.depth, cast_depth)
        exact = cast.cropped(border) if border else cast
        frame = _ExactFrame(
            cast, exact, K_render, inside, rgb.detach(), depth.detach(), rgb[inside], depth[inside],
            exact.mask.to(self.device), None,
        )  # fmt: skip
        inner = Reprojection(warp.rgb[inside], warp.depth[inside], warp.valid[inside], warp.layer[inside])
        return frame, WarpAgreement.of(inner, None, cast_depth[inside], frame.mask)

    def _render_view(self, K: torch.Tensor, height: int, width: int) -> tuple:
        """What a frame is rendered as: its border, intrinsics and size, and the index of the frame
        inside it. With silhouettes the frame is rendered with a ring around it (its interior)."""
        border = RING if self.config.silhouette else 0
        K_render, render_height, render_width = ring_view(K, height, width) if border else (K, height, width)
        inside = (..., slice(border, render_height - border), slice(border, render_width - border))
        return border, K_render, render_height, render_width, inside

    def _shade_holes(
        self, world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int, holes: torch.Tensor
    ) -> torch.Tensor:
        """(B, 3, H, W) exact colours of the pixels ``holes`` (B, 1, H, W) (0 elsewhere): each
        one's s x s rays cast and shaded, without the mirrored light of coats and metals (which
        the anchor's colours, and so the warp's, leave out too)."""
        s = self.config.supersample
        rgb = torch.zeros(holes.shape[0], 3, height, width, dtype=torch.float32, device=self.device)
        view, row, column = torch.nonzero(holes[:, 0].to(self.renderer.device), as_tuple=True)
        if not len(view):
            return rgb
        # the chosen pixels' sub-pixel centres, in pixels, each pixel's s x s together
        offsets = (torch.arange(s, dtype=torch.float64, device=view.device) + 0.5) / s
        u = (column[:, None, None] + offsets[None, None, :]).expand(-1, s, s)
        v = (row[:, None, None] + offsets[None, :, None]).expand(-1, s, s)
        pixels = torch.stack([u, v, torch.ones_like(u)], dim=-1).reshape(len(view), s * s, 3)
        K_inv = torch.linalg.inv(batched_intrinsics(K, holes.shape[0])).to(view.device)[view]
        pose = world_T_cam.detach().double().to(view.device)[view]
        directions = pixels @ K_inv.transpose(1, 2) @ pose[:, :3, :3].transpose(1, 2)  # camera z = 1
        origins = pose[:, None, :3, 3].expand_as(directions)
        colours = self._colours(origins.reshape(-1, 3), directions.reshape(-1, 3), K, view.repeat_interleave(s * s))
        colours = colours.reshape(-1, s * s, 3).mean(1).to(self.device, torch.float32)
        index = tuple(i.to(self.device) for i in (view, row, column))
        return rgb.permute(0, 2, 3, 1).index_put(index, colours).permute(0, 3, 1, 2)

    def _colours(
        self, origins: torch.Tensor, directions: torch.Tensor, K: torch.Tensor, ray_view: torch.Tensor
    ) -> torch.Tensor:
        """(N, 3) shaded colours of sub-pixel rays (N, 3) of the views ``ray_view`` (N,) with
        intrinsics ``K``, each view's at its own footprint when their intrinsics differ."""
        s = self.config.supersample
        if not views_apart(K):
            return self.renderer.cast_and_shade(origins, directions, pixel_angle(K) / s, True, False)[1]["rgb"]
        colours = torch.zeros(len(origins), 3, dtype=torch.float32, device=origins.device)
        for b in torch.unique(ray_view).tolist():
            rays = ray_view == b
            shaded = self.renderer.cast_and_shade(origins[rays], directions[rays], pixel_angle(K[b]) / s, True, False)
            colours[rays] = shaded[1]["rgb"].to(colours)
        return colours

    def _checked_warp(
        self, frame: _ExactFrame, world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int, refreshed: bool
    ) -> tuple[Reprojection, WarpAgreement, bool]:
        """The warp to the current poses and its agreement with the exact frame; with ``on_drift``,
        an anchor that drifted too far is rendered again first."""
        # an anchor rendered in this call is at the current poses: the warp need not compare them
        warp = self._warp(frame.depth, frame.normals, world_T_cam, K, True if refreshed else None)
        agreement = WarpAgreement.of(warp, frame.rgb, frame.depth, frame.mask)
        if self.config.refresh == "on_drift" and not refreshed and agreement.drifted(self.config):
            self._refresh(world_T_cam.detach(), K.detach(), height, width)
            refreshed = True
            warp = self._warp(frame.depth, frame.normals, world_T_cam, K, True)
            agreement = WarpAgreement.of(warp, frame.rgb, frame.depth, frame.mask)
        return warp, agreement, refreshed

    def _values(self, frame: _ExactFrame, warp: Reprojection) -> tuple[torch.Tensor, torch.Tensor]:
        """rgb and depth of an exact frame: the exact values, with the warp's gradient where it holds."""
        valid = warp.valid
        rgb = frame.rgb + torch.where(valid, straight_through(warp.rgb), torch.zeros_like(warp.rgb))
        depth = frame.depth + torch.where(valid, straight_through(warp.depth), torch.zeros_like(warp.depth))
        return rgb, depth

    def _exact_render(
        self,
        world_T_cam: torch.Tensor,
        K: torch.Tensor,
        height: int,
        width: int,
        border: int,
        anchor: AnchorLayers | None,
    ) -> RenderOutput:
        """The exact render of the frame plus ``border`` pixels; an anchor (CPU) just rendered at this
        pose holds the colours of the frame's sub-pixel rays, which are then not cast again."""
        sub = {}
        if anchor is not None and anchor.supersample > 1 and anchor.guard_band >= border:
            s, start = anchor.supersample, anchor.supersample * (anchor.guard_band - border)
            window = (slice(None), slice(None), slice(start, start + s * height), slice(start, start + s * width))
            sub = {"sub_rgb": anchor.rgb[:, 0][window], "sub_ids": anchor.triangle_ids[:, 0][window]}
            if anchor.reflecting is not None:
                sub["sub_terms"] = anchor.reflecting[window]
        return self.renderer.render(world_T_cam, K, height, width, supersample=self.config.supersample, **sub)

    def _warp(
        self,
        depth: torch.Tensor,
        normals: torch.Tensor,
        world_T_cam: torch.Tensor,
        K: torch.Tensor,
        at_anchor: bool | None,
    ) -> Reprojection:
        A_T_P = torch.linalg.inv_ex(self.anchor.world_T_cam)[0] @ world_T_cam  # inv_ex: no wait for its check
        if self.config.values == "warp":
            # the preset's steps read the boxed anchor, its refreshes too: at the anchor's own pose the
            # lean warp's slopes agree with the closed form's (tests/render/test_dibr.py) at half its cost
            return warp_boxed(self.anchor.boxed, depth, normals, A_T_P, K, self.config.depth_tolerance)
        return reproject(
            self.anchor,
            depth,
            normals,
            A_T_P,
            K,
            depth_tolerance=self.config.depth_tolerance,
            plane_tolerance=self.config.plane_tolerance,
            at_anchor=at_anchor,
        )


@dataclass(frozen=True)
class _ViewKey:
    """What an anchor was rendered for, besides the pose: image size and intrinsics (B, 3, 3),
    compared by value (the intrinsics live on the host, so comparing them waits for no device)."""

    height: int
    width: int
    K: torch.Tensor

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, _ViewKey)
            and (self.height, self.width) == (other.height, other.width)
            and self.K.shape == other.K.shape
            and torch.equal(self.K, other.K)
        )


def _view_key(K: torch.Tensor, height: int, width: int) -> _ViewKey:
    return _ViewKey(height, width, K.detach().clone())


@dataclass
class WarpAgreement:
    """How well the warp matches the exact render, per view (B,).

    Attributes:
        coverage: fraction of hit pixels with a valid warp.
        rgb_error: mean |rgb_warp - rgb_exact| over valid pixels.
        depth_error: mean |depth_warp - depth_exact| / depth_exact over valid pixels.
    """

    coverage: torch.Tensor
    rgb_error: torch.Tensor
    depth_error: torch.Tensor

    @classmethod
    def of(cls, warp, rgb: torch.Tensor | None, depth: torch.Tensor, mask: torch.Tensor) -> WarpAgreement:
        """Compare a :class:`~kadv.render.dibr.Reprojection` with the exact rgb (None: no exact
        colour was rendered, the colour error is NaN), depth and mask."""
        valid = warp.valid.detach()
        hit = mask.sum(dim=(1, 2, 3)).clamp_min(1)
        count = valid.sum(dim=(1, 2, 3)).clamp_min(1)
        coverage = valid.sum(dim=(1, 2, 3)) / hit
        if rgb is None:
            rgb_error = torch.full_like(coverage, torch.nan)
        else:
            rgb_error = ((warp.rgb.detach() - rgb).abs().mean(1, keepdim=True) * valid).sum(dim=(1, 2, 3)) / count
        relative = (warp.depth.detach() - depth).abs() / depth.clamp_min(_MIN_DEPTH)
        depth_error = (relative * valid).sum(dim=(1, 2, 3)) / count
        return cls(coverage.double(), rgb_error.double(), depth_error.double())

    def drifted(self, config: DiffRenderConfig) -> bool:
        """Whether any view passed the ``on_drift`` tolerances."""
        return bool(
            (self.coverage < config.min_coverage).any()
            or (self.rgb_error > config.max_rgb_error).any()
            or (self.depth_error > config.max_depth_error).any()
        )
