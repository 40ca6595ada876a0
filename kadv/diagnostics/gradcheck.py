"""Gradient check of the differentiable renderer against finite differences of exact renders.

Reference: central differences of supersampled exact renders (RGB and depth box-averaged over
s x s samples per pixel), with the step confirmed by halving it. Functionals are
f = sum(W * rgb) and f = sum(W * depth) with fixed smooth random weight maps, in an *interior*
version (weights zeroed within 2 pixels of occlusion edges) and a *full* one. The pose's gradient
is a 6-vector (compared per block, rotation and translation); the focal length's derivative, a
scalar, is compared as the vector of its values over :data:`FOCAL_WEIGHTS` weight maps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from kornia.geometry.transform import resize
from torch.nn import functional as F

from kadv.geometry.camera import intrinsics_from_fov, pixel_rays
from kadv.geometry.pose import perturb_world_T_cam
from kadv.penalties import random_valid_poses
from kadv.render.differentiable import DifferentiableRenderer, DiffRenderConfig
from kadv.render.exact import ExactRenderer, RenderOutput, pixel_angle
from kadv.render.layers import RING, ring_view

__all__ = [
    "FUNCTIONALS",
    "GradientCheck",
    "check_pose",
    "gradient_check_poses",
    "occlusion_edge_mask",
    "smooth_weights",
    "supersampled_maps",
]

FUNCTIONALS = ("rgb_interior", "depth_interior", "rgb_full", "depth_full")
FOCAL_WEIGHTS = 8  # weight maps per functional whose focal-length derivatives are compared as one vector
# a kept anchor is placed this share of its reach away: at the reach itself rounding may put the view
# beyond it, and the call would render a new anchor instead of warping
_INSIDE = 0.999


def smooth_weights(seed: int, channels: int, height: int, width: int) -> torch.Tensor:
    """(1, C, H, W) smooth random weights: 4 x 5 Gaussian noise upsampled bicubically."""
    generator = torch.Generator().manual_seed(seed)
    coarse = torch.randn(1, channels, 4, 5, generator=generator, dtype=torch.float64)
    return resize(coarse, (height, width), interpolation="bicubic", align_corners=True)


def occlusion_edge_mask(exact: RenderOutput, radius: int = 2, jump: float = 0.005) -> torch.Tensor:
    """(B, 1, H, W) True within ``radius`` pixels of an occlusion edge: neighbours on different
    triangles where one's hit point lies off the other's tangent plane by more than ``jump`` times
    its depth, or where one ray misses. Neighbouring triangles of one surface are not an edge,
    however steeply the depth changes between them (a grazing floor, a scan's small irregular
    triangles); a crease or a step is."""
    points, normals = exact.points.double(), exact.normals.double()
    depth, ids, hit = exact.depth.double(), exact.triangle_ids, exact.mask
    edge = torch.zeros_like(hit)
    for a, b in (
        ((..., slice(None, -1)), (..., slice(1, None))),
        ((..., slice(None, -1), slice(None)), (..., slice(1, None), slice(None))),
    ):
        gap = points[b] - points[a]
        off = torch.maximum(
            (normals[a] * gap).sum(dim=1, keepdim=True).abs() / depth[a].clamp_min(1e-9),
            (normals[b] * gap).sum(dim=1, keepdim=True).abs() / depth[b].clamp_min(1e-9),
        )
        jumpy = (ids[a] != ids[b]) & (((hit[a] & hit[b]) & (off > jump)) | (hit[a] ^ hit[b]))
        edge[a] |= jumpy
        edge[b] |= jumpy
    return F.max_pool2d(edge.float(), 2 * radius + 1, stride=1, padding=radius) > 0


def supersampled_maps(
    renderer: ExactRenderer, world_T_cam: torch.Tensor, K: torch.Tensor, height: int, width: int, supersample: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Box-averaged RGB (B, 3, H, W) and z-depth (B, 1, H, W) (misses count as depth 0) of s x s samples."""
    origins, directions = pixel_rays(world_T_cam, K, height, width, supersample, device=renderer.device)
    batch, s = origins.shape[0], supersample
    angle = pixel_angle(K) / supersample
    hits, shaded = renderer.cast_and_shade(origins.reshape(-1, 3), directions.reshape(-1, 3), angle, True, False)
    rgb = shaded["rgb"].double().reshape(batch, height, s, width, s, 3).mean(dim=(2, 4))
    depth = torch.where(hits.hit, hits.t.double(), 0.0).reshape(batch, height, s, width, s).mean(dim=(2, 4))
    return rgb.permute(0, 3, 1, 2).cpu(), depth[:, None].cpu()


@dataclass
class GradientCheck:
    """Cosines between analytic and reference derivatives at one pose, per functional: of the
    pose's 6-vector per block and, when checked, of the focal length's (over :data:`FOCAL_WEIGHTS`
    weight maps)."""

    cosines: dict[str, tuple[float, ...]]  # functional -> (rotation block, translation block[, focal length])
    agreements: dict[str, float]  # functional -> min block cosine of the reference at step h vs h / 2

    @property
    def step_agreement(self) -> float:
        return min(self.agreements.values())

    def agreement(self, functionals: tuple[str, ...]) -> float:
        """The least step agreement among ``functionals``."""
        return min(self.agreements[f] for f in functionals)

    def score(self, functional: str) -> float:
        """The pose's: the lower of its blocks' cosines."""
        return min(self.cosines[functional][:2])

    def focal_score(self, functional: str) -> float:
        """The focal length's cosine (NaN: not checked)."""
        cosines = self.cosines[functional]
        return cosines[2] if len(cosines) > 2 else float("nan")


def _cos(a: np.ndarray, b: np.ndarray) -> float:
    return float(a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-300))


def _blocks(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    return _cos(a[:3], b[:3]), _cos(a[3:], b[3:])


def check_pose(
    renderer: ExactRenderer,
    world_T_cam: torch.Tensor,
    K: torch.Tensor,
    height: int,
    width: int,
    configs: dict[str, DiffRenderConfig],
    *,
    weight_seed: int = 0,
    reference_supersample: int = 4,
    steps: tuple[float, ...] = (2e-3, 4e-3),
    edge_jump: float = 0.005,
    anchor_offset: tuple[float, float] | None = None,
    device: str | torch.device = "cpu",
) -> dict[str, GradientCheck]:
    """Compare analytic and finite-difference gradients of the four functionals at one pose.

    The analytic gradients come from a DifferentiableRenderer on ``device``, the reference from
    exact renders on the CPU. A configuration that keeps its anchor between calls (``refresh``
    every_k or on_drift) is checked between refreshes: its anchor is rendered first ``anchor_offset``
    (degrees, metres, directions seeded by ``weight_seed``) away; None: just inside the
    configuration's reach (``anchor_reach_deg``, ``anchor_reach_m``), the farthest it warps a view.
    ``steps``: the reference's steps in rotation (radians) and translation (metres) and, to check
    the focal length's derivative too (square pixels, the principal point kept), its step as a
    share of the focal length.

    Returns one :class:`GradientCheck` per configuration (the reference is shared); its
    ``step_agreement`` < 0.99 says the reference is not trustworthy there (resample the pose). The
    interior functionals leave out pixels near occlusion edges (:func:`occlusion_edge_mask`,
    ``jump=edge_jump``; a scan's surface noise asks for a larger one).
    """
    base = world_T_cam.double().reshape(1, 4, 4)
    K = torch.as_tensor(K, dtype=torch.float64)
    focal = len(steps) > 2
    # edges just outside the frame enter it when the camera moves: detect them on the ring too
    edges = occlusion_edge_mask(renderer.render(base, *ring_view(K, height, width)), jump=edge_jump)[
        ..., RING:-RING, RING:-RING
    ]
    functionals = _Functionals(weight_seed, FOCAL_WEIGHTS if focal else 1, (~edges).double())
    maps = lambda pose, K_view: supersampled_maps(renderer, pose, K_view, height, width, reference_supersample)
    half, focal_half, agreements = _references(maps, base, K, functionals, steps)
    results = {}
    for name, config in configs.items():
        differentiable = DifferentiableRenderer(renderer, config, device)
        if config.refresh != "always":
            offset = anchor_offset or (_INSIDE * config.anchor_reach_deg, _INSIDE * config.anchor_reach_m)
            differentiable(_offset_params(weight_seed, *offset), base, K, height, width)
        pose, focal_length, refreshed = _analytic(differentiable, base, K, height, width, functionals)
        if refreshed and config.refresh != "always":
            raise ValueError(f"gradient check: anchor_offset {offset} lies beyond {name}'s reach; it checks no warp")
        cosines = {f_name: _blocks(pose[f], half[f]) for f, f_name in enumerate(FUNCTIONALS)}
        if focal:
            cosines = {
                f_name: c + (_cos(focal_length[f], focal_half[f]),) for f, (f_name, c) in enumerate(cosines.items())
            }
        results[name] = GradientCheck(cosines, agreements)
    return results


def _references(maps, base, K, functionals: _Functionals, steps) -> tuple:
    """The finite-difference reference at half the ``steps`` (pose, and focal length where a third
    step is given, else None), and how well it agrees with the reference at the full steps (per
    functional, the lowest cosine over the blocks)."""
    full, half = (_pose_reference(maps, base, K, functionals, steps, scale) for scale in (1.0, 0.5))
    agreements = {name: min(_blocks(full[f], half[f])) for f, name in enumerate(FUNCTIONALS)}
    if len(steps) <= 2:
        return half, None, agreements
    focal_full, focal_half = (_focal_reference(maps, base, K, functionals, steps[2] * scale) for scale in (1.0, 0.5))
    for f, name in enumerate(FUNCTIONALS):
        agreements[name] = min(agreements[name], _cos(focal_full[f], focal_half[f]))
    return half, focal_half, agreements


class _Functionals:
    """The check's functionals (:data:`FUNCTIONALS`), each on ``maps`` sets of smooth weight maps
    seeded from ``seed`` (the pose's on the first; the focal length's on all), the interior ones
    zero where ``interior`` (1, 1, H, W) is."""

    def __init__(self, seed: int, maps: int, interior: torch.Tensor) -> None:
        height, width = interior.shape[-2:]
        self.sets = [
            _weights(smooth_weights(seed + 2 * k, 3, height, width), smooth_weights(seed + 2 * k + 1, 1, height, width),
                     interior)
            for k in range(maps)
        ]  # fmt: skip

    def __call__(self, rgb: torch.Tensor, depth: torch.Tensor, every: bool = False) -> torch.Tensor:
        """(F,) the functionals on the first set of maps; ``every``: (F, maps) on each."""
        values = torch.stack([_apply(w, rgb, depth) for w in self.sets if every or w is self.sets[0]], dim=-1)
        return values if every else values[:, 0]


def _pose_reference(maps, base, K, functionals: _Functionals, steps, scale: float) -> np.ndarray:
    """(F, 6) central differences of the functionals in the pose, steps ``steps`` x ``scale``."""
    columns = []
    for i in range(6):
        step = torch.zeros(1, 6, dtype=torch.float64)
        step[0, i] = steps[i >= 3] * scale
        values = [functionals(*maps(perturb_world_T_cam(base, sign * step[:, :3], sign * step[:, 3:]), K))
                  for sign in (1.0, -1.0)]  # fmt: skip
        columns.append(((values[0] - values[1]) / (2 * step[0, i])).numpy())
    return np.stack(columns, axis=1)


def _focal_reference(maps, base, K, functionals: _Functionals, share: float) -> np.ndarray:
    """(F, maps) central differences of the functionals in the focal length, step ``share`` of it."""
    step = share * float(K[0, 0])
    values = [functionals(*maps(base, _with_focal(K, sign * step)), every=True) for sign in (1.0, -1.0)]
    return ((values[0] - values[1]) / (2 * step)).numpy()


def _analytic(
    differentiable: DifferentiableRenderer, base, K, height: int, width: int, functionals: _Functionals
) -> tuple[np.ndarray, np.ndarray, bool]:
    """The functionals' analytic derivatives: in the pose (F, 6), and in the focal length (F, maps)
    when their weight maps are more than one set; and whether the call rendered a new anchor."""
    params = torch.zeros(1, 6, dtype=torch.float64, requires_grad=True)
    change = torch.zeros((), dtype=torch.float64, requires_grad=True)  # of the focal length, pixels
    focal = len(functionals.sets) > 1
    output = differentiable(params, base, _with_focal(K, change) if focal else K, height, width)
    values = functionals(output.rgb.double().cpu(), output.depth.double().cpu(), every=True)
    pose = np.stack([torch.autograd.grad(v, params, retain_graph=True)[0][0].numpy() for v in values[:, 0]])
    if not focal:
        return pose, np.zeros((len(values), 0)), output.refreshed
    grads = [[float(torch.autograd.grad(v, change, retain_graph=True)[0]) for v in row] for row in values]
    return pose, np.array(grads), output.refreshed


def _weights(w_rgb: torch.Tensor, w_depth: torch.Tensor, interior: torch.Tensor) -> list[tuple]:
    """The four functionals' (rgb weights, depth weights), one of them None, in :data:`FUNCTIONALS`' order."""
    return [(w_rgb * interior, None), (None, w_depth * interior), (w_rgb, None), (None, w_depth)]


def _apply(weights: list[tuple], rgb: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
    """(F,) the functionals of ``weights`` (:func:`_weights`) on rgb (1, 3, H, W) and depth (1, 1, H, W)."""
    return torch.stack([(w * rgb).sum() if w is not None else (v * depth).sum() for w, v in weights])


def _with_focal(K: torch.Tensor, change: torch.Tensor | float) -> torch.Tensor:
    """``K`` (3, 3) with ``change`` added to both focal lengths (differentiable in it)."""
    diagonal = torch.diag(torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64))
    return K + torch.as_tensor(change, dtype=torch.float64) * diagonal


def _offset_params(seed: int, degrees: float, metres: float) -> torch.Tensor:
    """Pose parameters (1, 6) of a move by ``degrees`` and ``metres`` in directions seeded by ``seed``."""
    generator = torch.Generator().manual_seed(seed)
    directions = F.normalize(torch.randn(2, 3, generator=generator, dtype=torch.float64), dim=1)
    return torch.cat([directions[0] * np.radians(degrees), directions[1] * metres])[None]


def gradient_check_poses(
    renderer: ExactRenderer,
    count: int,
    seed: int,
    fov_x_deg: float,
    height: int,
    width: int,
    configs: dict[str, DiffRenderConfig],
    *,
    min_agreement: float = 0.99,
    trusted: tuple[str, ...] = FUNCTIONALS,
    max_attempts: int = 60,
    **options,
) -> dict[str, list[GradientCheck]]:
    """Gradient checks at ``count`` seeded poses: >= 0.3 m from every surface, >= 90% of pixels hit,
    and a reference whose halved-step estimate agrees to ``min_agreement`` on the ``trusted``
    functionals (else the pose is resampled). On a scan, whose floaters, holes and noise put small
    occlusions everywhere, only the interior functionals' reference is stable.
    """
    K = intrinsics_from_fov(fov_x_deg, height, width)
    rng = np.random.default_rng(seed)
    results: dict[str, list[GradientCheck]] = {name: [] for name in configs}
    for _ in range(max_attempts):
        pose = random_valid_poses(renderer, 1, rng, fov_x_deg, min_clearance=0.3)[0]
        if float(renderer.render(pose, K, height, width).mask.float().mean()) < 0.9:
            continue
        checks = check_pose(renderer, pose, K, height, width, configs, **options)
        if next(iter(checks.values())).agreement(trusted) < min_agreement:
            continue
        for name, check in checks.items():
            results[name].append(check)
        if len(results[next(iter(configs))]) == count:
            return results
    raise RuntimeError(f"found only {len(results[next(iter(configs))])} of {count} poses with a trustworthy reference")
