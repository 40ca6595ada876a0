"""Is a camera view legitimate? Inside an object, outside the scene, too close, or valid.

Open3D's signed distance decides its sign by ray parity, which is meaningless for open rooms
(windows, missing ceilings); the verdict here comes from a sphere of enclosure rays around the
optical centre instead:

- *outside the scene*: more than ``outside_threshold`` (0.3) of the enclosure rays escape. A
  room's windows and doors rarely let a fifth of all directions out, while anywhere under open
  sky, even over an endless ground plane, about half of them escape;
- *inside an object*: most enclosure rays first hit a hidden side of a surface
  (:meth:`~kadv.render.ExactRenderer.hidden_side`). With baked lighting that is a side the bake's
  flood fill from the scene's cameras did not reach, which holds whatever the file's windings (a
  room wound outwards, as some exporters leave two-sided walls). With direct lighting it is the
  back of a triangle: exporters mostly write closed objects with outward normals and rooms with
  inward normals, so from free space one sees front faces. One- and two-sided materials are
  treated alike in this vote: the back of a two-sided panel (a painting, a leaf) is legitimately
  visible, but only over the minority of directions the panel covers, so it cannot swing the
  majority; a one-sided surface seen from behind counts the same way.
- *too close*: the centre is nearer than ``min_distance`` to a surface or some of the view's
  pixels are nearer than the near plane.
- *uninformative*: a view that is otherwise valid but where one plane (a wall seen close, the
  floor) covers more than ``max_plane_share`` of the pixels that hit a surface.

A scan (``render.lighting=scanned``) may stop below eye height, with no ceiling, and miss whole
walls: operators sweep at chest height. In such a scan (:func:`scan_has_ceiling` is False) a ray
that leaves its bounds over its top or through a side is what the scan looks like, not a hole: the
enclosure test counts only rays that escape through its floor, and the hole test only pixels whose rays do
(the others stay out of the mask all the same). A centre above its top or beyond its bounds is
outside the scene. A lone plane's
  ground truth, min-max normalised, is a ramp that a model's nearly flat guess misses by a wide
  margin while its delta1 stays near 1, so the view's L_depth says nothing about the model.
"""

from __future__ import annotations

import functools
import math
import weakref
from dataclasses import dataclass, field

import numpy as np
import torch

from kadv._renamed import renamed_attribute
from kadv.checks import check_shape
from kadv.geometry.camera import pixel_rays
from kadv.geometry.pose import check_world_T_cam
from kadv.penalties.config import PenaltyConfig
from kadv.penalties.distance import distance_to_surface
from kadv.penalties.envelope import OUTSIDE_ENVELOPE, EnvelopeFigures
from kadv.render.exact import ExactRenderer, RenderOutput

__all__ = [
    "SCAN_PLANE_TOLERANCE",
    "SCAN_PROBE_ELEVATION",
    "SCAN_TOP_TOLERANCE",
    "ValidityLimits",
    "ViewValidity",
    "dominant_plane_shares",
    "enclosure_hits",
    "fibonacci_sphere",
    "plane_counts",
    "plane_labels",
    "plane_shares",
    "scan_exits",
    "scan_has_ceiling",
    "view_validity",
]

VALID, INSIDE, OUTSIDE, TOO_CLOSE = "valid", "inside an object", "outside the scene", "too close"
UNINFORMATIVE = "uninformative"
# A scan's enclosure rays look no higher than this above the horizon, degrees: its ceiling may be missing
SCAN_PROBE_ELEVATION = 15.0
# metres from a scan's dominant plane within which a hit counts as on it (a scan's noise is millimetres)
SCAN_PLANE_TOLERANCE = 0.03
# metres below a scan's top within which a ray leaving its bounds counts as leaving over the top
SCAN_TOP_TOLERANCE = 0.05
# Triangles lie in one plane when their unit normals agree to ~1 degree and their offsets to 2 cm:
# coarse enough for a wall split into many triangles, fine enough to part a table top from the floor.
_PLANE_NORMAL_STEP, _PLANE_OFFSET_STEP = 0.02, 0.02
_PLANE_LABELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_SCAN_CEILINGS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_DEVICE_PLANE_LABELS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_SCAN_CEILINGS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@dataclass(frozen=True)
class ValidityLimits:
    """The limits a :class:`ViewValidity` judges its figures by (:func:`view_validity`'s arguments).

    Attributes:
        near: pixels nearer than this z-depth make the view "too close".
        min_distance: nor may the centre be nearer to a surface.
        outside_threshold: the enclosure rays' escape fraction above which the centre is outside the scene.
        inside_threshold: its hidden-side fraction above which the centre is inside an object.
        max_plane_share: a view whose most common plane covers more of its hit pixels is
            "uninformative" (None: never).
        max_miss_share: so is a scan's view (``render.lighting=scanned``) where more of the
            pixels see nothing below the scan's top (None, or any other scene: never).
    """

    near: float = PenaltyConfig.near
    min_distance: float = PenaltyConfig.min_distance
    outside_threshold: float = PenaltyConfig.outside_threshold
    inside_threshold: float = PenaltyConfig.inside_threshold
    max_plane_share: float | None = PenaltyConfig.max_plane_share
    max_miss_share: float | None = PenaltyConfig.max_miss_share


@dataclass
class ViewValidity:
    """Per-camera validity statistics (B cameras), tensors (B,) on the renderer's device.

    The verdicts are words, so they are made on the host, from all figures in one copy, when first
    read: a search can hold a step's validity without waiting for the device.

    Attributes:
        miss_fraction: fraction of the view's pixels whose ray hits nothing.
        back_face_fraction: fraction of the view's pixels that see the back of a triangle.
        near_fraction: fraction of the view's pixels closer than the near plane.
        enclosure_miss_fraction: fraction of spherical enclosure rays that escape.
        enclosure_back_fraction: fraction of enclosure rays whose first hit is a hidden side
            (:meth:`~kadv.render.ExactRenderer.hidden_side`: with direct lighting a back face).
        distance: distance from the optical centre to the nearest surface, metres.
        plane_share: share of the pixels that hit a surface which lie on the most common plane.
        past_top_fraction, past_side_fraction: fractions of the view's pixels that see nothing and
            whose ray leaves a scan with no ceiling over its top, or through a side of its bounds
            (a missing wall; :func:`scan_exits`); None: 0 (any other scene).
        off_scan: whether the centre stands above such a scan's top or beyond its bounds (None:
            no scene of that kind).
        limits: what the figures are judged by.
        envelope: the views' pose figures when a search bounds them: a view that is otherwise
            valid but lies outside the envelope is "outside the envelope".
    """

    miss_fraction: torch.Tensor
    back_face_fraction: torch.Tensor
    near_fraction: torch.Tensor
    enclosure_miss_fraction: torch.Tensor
    enclosure_back_fraction: torch.Tensor
    distance: torch.Tensor
    plane_share: torch.Tensor
    past_top_fraction: torch.Tensor | None = None
    past_side_fraction: torch.Tensor | None = None
    off_scan: torch.Tensor | None = None
    limits: ValidityLimits = field(default_factory=ValidityLimits)
    envelope: EnvelopeFigures | None = None
    probe_miss_fraction = renamed_attribute("enclosure_miss_fraction")
    probe_back_fraction = renamed_attribute("enclosure_back_fraction")

    @property
    def verdicts(self) -> list[str]:
        """One of "valid", "inside an object", "outside the scene", "too close", "uninformative",
        "outside the envelope" per camera."""
        return self._judged[0]

    @property
    def reasons(self) -> list[str]:
        """A sentence per camera saying why."""
        return self._judged[1]

    @property
    def valid(self) -> torch.Tensor:
        """(B,) bool on the CPU, True where the verdict is "valid"."""
        return torch.tensor([v == VALID for v in self.verdicts], dtype=torch.bool)

    def _share(self, figure: torch.Tensor | None) -> torch.Tensor:
        return torch.zeros_like(self.miss_fraction) if figure is None else figure.to(self.miss_fraction.device)

    @property
    def hole_fraction(self) -> torch.Tensor:
        """(B,) the fraction of pixels that see nothing where a scan has a surface to see: the misses
        less those past a ceilingless scan's top and its sides."""
        return self.miss_fraction - self._share(self.past_top_fraction) - self._share(self.past_side_fraction)

    @property
    def surface_fraction(self) -> torch.Tensor:
        """(B,) the fraction of the pixels a surface could be seen at (those not past a ceilingless
        scan's top) that hit one."""
        return (1.0 - self.miss_fraction) / (1.0 - self._share(self.past_top_fraction)).clamp_min(1e-12)

    @functools.cached_property
    def _judged(self) -> tuple[list[str], list[str]]:
        above = self.off_scan if self.off_scan is not None else torch.zeros_like(self.distance, dtype=torch.bool)
        figures = [
            self.enclosure_miss_fraction,
            self.enclosure_back_fraction,
            self.distance,
            self.near_fraction,
            self.plane_share,
            self.hole_fraction,
            above.to(self.distance.device, self.distance.dtype),
        ]
        escaped, hidden, distance, near_fraction, share, missed, above = torch.stack(figures).cpu()  # one copy
        limits, verdicts, reasons = self.limits, [], []
        outside_envelope = self.envelope.reasons() if self.envelope is not None else [None] * len(distance)
        for b in range(len(distance)):
            miss_frac, back_frac = float(escaped[b]), float(hidden[b])
            if above[b]:
                verdicts.append(OUTSIDE)
                reasons.append("the centre stands above the scan's top or beyond its bounds")
            elif miss_frac > limits.outside_threshold:
                verdicts.append(OUTSIDE)
                reasons.append(f"{miss_frac:.0%} of enclosure rays escape the scene (> {limits.outside_threshold:.0%})")
            elif back_frac > limits.inside_threshold:
                verdicts.append(INSIDE)
                reasons.append(
                    f"{back_frac:.0%} of enclosure rays first hit a hidden side (> {limits.inside_threshold:.0%})"
                )
            elif distance[b] < limits.min_distance or near_fraction[b] > 0:
                verdicts.append(TOO_CLOSE)
                reasons.append(
                    f"centre {distance[b]:.3f} m from a surface, {near_fraction[b]:.1%} of pixels nearer "
                    f"than {limits.near} m (limits {limits.min_distance} m, 0 pixels)"
                )
            elif limits.max_plane_share is not None and share[b] > limits.max_plane_share:
                verdicts.append(UNINFORMATIVE)
                reasons.append(
                    f"one plane covers {share[b]:.0%} of the surface pixels (> {limits.max_plane_share:.0%})"
                )
            elif limits.max_miss_share is not None and missed[b] > limits.max_miss_share:
                verdicts.append(UNINFORMATIVE)
                reasons.append(f"{missed[b]:.0%} of the pixels see a hole in the scan (> {limits.max_miss_share:.0%})")
            elif outside_envelope[b] is not None:
                verdicts.append(OUTSIDE_ENVELOPE)
                reasons.append(f"{outside_envelope[b]} ({self.envelope.envelope.describe()})")
            else:
                verdicts.append(VALID)
                reasons.append(
                    f"enclosed ({miss_frac:.0%} escape, {back_frac:.0%} hidden sides), {distance[b]:.2f} m clear"
                )
        return verdicts, reasons


def fibonacci_sphere(count: int) -> np.ndarray:
    """(count, 3) nearly uniform unit directions (golden-angle spiral), deterministic.

    Examples:
        >>> directions = fibonacci_sphere(100)
        >>> directions.shape, bool(np.allclose(np.linalg.norm(directions, axis=1), 1.0))
        ((100, 3), True)
        >>> bool(abs(directions.mean(axis=0)).max() < 0.02)  # spread evenly: their mean is near 0
        True
    """
    index = np.arange(count) + 0.5
    z = 1.0 - 2.0 * index / count
    radius = np.sqrt(1.0 - z * z)
    angle = np.pi * (1.0 + 5**0.5) * index
    return np.stack([radius * np.cos(angle), radius * np.sin(angle), z], axis=1)


def plane_labels(renderer: ExactRenderer) -> np.ndarray:
    """(F,) int64 label per triangle of the renderer's scene; coplanar triangles share a label
    (computed once per scene).

    Examples:
        >>> import kadv
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> len(np.unique(plane_labels(room)))  # floor, ceiling and four walls
        6
    """
    if renderer not in _PLANE_LABELS:
        scene = renderer.scene
        corners = scene.vertices[scene.faces]
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
        # n and -n are one plane: make each normal's largest component positive
        sign = np.sign(np.take_along_axis(normal, np.abs(normal).argmax(axis=1)[:, None], axis=1))
        normal *= np.where(sign == 0, 1.0, sign)
        offset = np.einsum("fi,fi->f", normal, corners[:, 0])
        keys = np.concatenate(
            [np.round(normal / _PLANE_NORMAL_STEP), np.round(offset / _PLANE_OFFSET_STEP)[:, None]], axis=1
        )
        _PLANE_LABELS[renderer] = np.unique(keys, axis=0, return_inverse=True)[1].reshape(-1)
    return _PLANE_LABELS[renderer]


def plane_shares(renderer: ExactRenderer, triangle_ids: torch.Tensor) -> torch.Tensor:
    """(B,) float64 share of each view's hit pixels that lie on its most common plane (0 for a view
    that hits nothing), from per-pixel triangle ids (B, N) with -1 for a miss, on their device.

    Examples:
        >>> import kadv
        >>> from kadv.geometry import intrinsics_from_fov, look_at
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> facing_wall = look_at(torch.tensor([2.0, 1.5, 4.0]), torch.tensor([2.0, 1.5, 5.0]))  # 1 m from it
        >>> corner = look_at(torch.tensor([1.0, 2.0, 1.0]), torch.tensor([4.0, 0.0, 5.0]))
        >>> out = room.render(torch.stack([facing_wall, corner]), intrinsics_from_fov(60.0, 24, 32), 24, 32)
        >>> shares = plane_shares(room, out.triangle_ids[:, 0].flatten(1))
        >>> shares[0].item(), shares[1].item() < 0.9
        (1.0, True)
    """
    counts = plane_counts(renderer, triangle_ids)
    hits = (triangle_ids >= 0).sum(dim=1)
    most = counts.amax(dim=1) if counts.shape[1] else torch.zeros_like(hits)
    return torch.where(hits > 0, most.double() / hits.clamp_min(1).double(), 0.0)


def dominant_plane_shares(
    points: torch.Tensor, hit: torch.Tensor, hypotheses: int = 64, samples: int = 1024, rounds: int = 2
) -> torch.Tensor:
    """(B,) share of each view's hit pixels within :data:`SCAN_PLANE_TOLERANCE` of its dominant
    plane, from world points (B, N, 3) and hits (B, N). A scan's noisy triangles share no plane
    exactly, so :func:`plane_shares`' labels would split its walls; and a least-squares fit to all
    points is pulled off every plane by the others. So RANSAC: ``hypotheses`` planes through three
    hit points each, scored on ``samples`` hit points, the best refitted by least squares to its
    inliers ``rounds`` times. The draws come from a generator of their own (seed 0): the same
    views give the same shares, and the global random state is left alone. 0 for a view that hits
    nothing.

    Examples:
        >>> _ = torch.manual_seed(0)
        >>> wall = torch.cat([torch.rand(1, 90, 2), torch.zeros(1, 90, 1)], dim=2)  # the plane z = 0
        >>> floor = torch.cat([torch.rand(1, 10, 1), torch.full((1, 10, 1), -0.5), torch.rand(1, 10, 1)], dim=2)
        >>> hit = torch.ones(1, 100, dtype=torch.bool)
        >>> round(dominant_plane_shares(torch.cat([wall, floor], dim=1), hit).item(), 2)
        0.9
    """
    check_shape(points, "B N 3", "points")
    check_shape(hit, "B N", "hit", {"B": points.shape[0], "N": points.shape[1]})
    batch = len(points)
    generator = torch.Generator(device=points.device).manual_seed(0)
    # a view with no hit draws from all its points; its share is 0 anyway
    odds = hit.to(points.dtype) + (~hit.any(dim=1, keepdim=True)).to(points.dtype)
    picks = torch.multinomial(odds, 3 * hypotheses + samples, replacement=True, generator=generator)
    drawn = torch.gather(points, 1, picks[..., None].expand(-1, -1, 3))
    corners = drawn[:, : 3 * hypotheses].reshape(batch, hypotheses, 3, 3)
    normal = torch.linalg.cross(corners[:, :, 1] - corners[:, :, 0], corners[:, :, 2] - corners[:, :, 0])
    length = normal.norm(dim=-1, keepdim=True)
    normal = normal / length.clamp_min(1e-12)
    offset = (normal * corners[:, :, 0]).sum(dim=-1)  # (B, H)
    distance = (drawn[:, 3 * hypotheses :] @ normal.transpose(1, 2) - offset[:, None]).abs()  # (B, S, H)
    score = (distance <= SCAN_PLANE_TOLERANCE).sum(dim=1) * (length[..., 0] > 1e-9)  # degenerate triples: 0
    best = score.argmax(dim=1)
    normal, offset = normal[torch.arange(batch), best], offset[torch.arange(batch), best]
    for _ in range(rounds + 1):
        near = hit & ((points @ normal[..., None])[..., 0] - offset[:, None]).abs().le(SCAN_PLANE_TOLERANCE)
        weight = near.to(points.dtype)
        count = weight.sum(dim=1, keepdim=True).clamp_min(1.0)
        centre = (points * weight[..., None]).sum(dim=1, keepdim=True) / count[..., None]
        spread = (points - centre) * weight[..., None]
        refit = torch.linalg.svd(spread.transpose(1, 2) @ spread).U[..., -1]  # the least-spread axis
        enough = weight.sum(dim=1, keepdim=True) >= 3
        normal = torch.where(enough, refit, normal)
        offset = torch.where(enough[:, 0], (normal * centre[:, 0]).sum(dim=-1), offset)
    hits = hit.sum(dim=1)
    return torch.where(hits > 0, weight.sum(dim=1) / hits.clamp_min(1), 0.0)


def plane_counts(renderer: ExactRenderer, triangle_ids: torch.Tensor) -> torch.Tensor:
    """(B, P) int64 pixels of each view on each of the scene's P planes (:func:`plane_labels`), from
    per-pixel triangle ids (B, N) with -1 for a miss, on their device, without a loop over views."""
    labels, planes = _device_plane_labels(renderer, triangle_ids.device)
    hit = triangle_ids >= 0
    # misses go to a last column, dropped
    label = torch.where(hit, labels[triangle_ids.clamp_min(0)], planes)
    counts = torch.zeros(len(triangle_ids), planes + 1, dtype=torch.int64, device=triangle_ids.device)
    return counts.scatter_add_(1, label, torch.ones_like(label))[:, :planes]


def _device_plane_labels(renderer: ExactRenderer, device: torch.device) -> tuple[torch.Tensor, int]:
    """:func:`plane_labels` as a tensor on ``device`` (made once per renderer and device), and the
    number of planes."""
    tables = _DEVICE_PLANE_LABELS.setdefault(renderer, {})
    if device not in tables:
        labels = plane_labels(renderer)
        tables[device] = torch.from_numpy(labels).to(device), int(labels.max()) + 1 if len(labels) else 0
    return tables[device]


def enclosure_hits(
    renderer: ExactRenderer, centres: torch.Tensor, directions: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """(miss, hidden) booleans (B, N) on the renderer's device for rays from each centre (B, 3) along
    each direction (N, 3): whether each escapes, and whether it meets a hidden side
    (:meth:`~kadv.render.ExactRenderer.hidden_side`).

    Examples:
        >>> import kadv
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> centres = torch.tensor([[2.0, 1.5, 2.5], [2.0, 1.5, -1.0]])  # inside; outside, behind the wall z = 0
        >>> miss, back = enclosure_hits(room, centres, fibonacci_sphere(64))
        >>> miss.any(dim=1).tolist(), back.any(dim=1).tolist()  # from outside: escaping rays, hidden sides
        ([False, True], [False, True])
    """
    centres = torch.as_tensor(centres).to(renderer.device, torch.float64, non_blocking=True)
    directions = torch.as_tensor(directions).to(renderer.device, torch.float64, non_blocking=True)
    if renderer.shading.lighting == "scanned":
        return _scan_enclosure(renderer, centres, directions)
    origins = centres[:, None, :].expand(len(centres), len(directions), 3)
    rays = directions[None].expand(origins.shape)
    hits = renderer.cast(origins, rays)
    shape = (len(centres), len(directions))
    return ~hits.hit.reshape(shape), renderer.hidden_side(hits, rays).reshape(shape)


def scan_has_ceiling(renderer: ExactRenderer) -> bool:
    """Whether a scan's top is a ceiling: horizontal surfaces within :data:`SCAN_TOP_TOLERANCE` of its
    top cover a fifth of its footprint (a room with a few patches of ceiling missing), rather than
    the top of walls that stop below it (a sweep at chest height). Computed once per scene."""
    if renderer not in _SCAN_CEILINGS:
        scene = renderer.scene
        corners = scene.vertices[scene.faces]
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        area = np.linalg.norm(normal, axis=1) / 2
        flat = np.abs(normal[:, 1]) > 0.9 * np.maximum(2 * area, 1e-300)
        lo, hi = scene.bounds
        high = corners[:, :, 1].min(axis=1) >= hi[1] - SCAN_TOP_TOLERANCE
        footprint = (hi[0] - lo[0]) * (hi[2] - lo[2])
        _SCAN_CEILINGS[renderer] = bool(area[flat & high].sum() >= 0.2 * footprint)
    return _SCAN_CEILINGS[renderer]


def scan_exits(
    renderer: ExactRenderer, origins: torch.Tensor, directions: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """(over the top, through a side) booleans (N,): where each ray (origins and directions (N, 3))
    would leave the scene's bounds, the top taken within :data:`SCAN_TOP_TOLERANCE` of it; neither:
    through the bottom.

    Examples:
        >>> import kadv
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> origin = torch.tensor([[2.0, 1.5, 2.5]] * 3, dtype=torch.float64)
        >>> up, level, down = [0.3, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.2]
        >>> top, side = scan_exits(room, origin, torch.tensor([up, level, down], dtype=torch.float64))
        >>> top.tolist(), side.tolist()
        ([True, False, False], [False, True, False])
    """
    lo, hi = (torch.as_tensor(b, dtype=torch.float64, device=origins.device) for b in renderer.scene.bounds)
    origins, directions = origins.double(), directions.double()
    with torch.no_grad():
        step = torch.where(directions.abs() > 1e-12, directions, torch.full_like(directions, 1e-12))
        far = torch.maximum((lo - origins) / step, (hi - origins) / step)
        leave = far.amin(dim=-1).clamp_min(0.0)
        height = origins[..., 1] + leave * directions[..., 1]
    top = height >= hi[1] - SCAN_TOP_TOLERANCE
    return top, ~top & (height > lo[1] + SCAN_TOP_TOLERANCE)


def _scan_enclosure(renderer: ExactRenderer, centres: torch.Tensor, directions: torch.Tensor) -> tuple:
    """The enclosure test of a scan, whose winding and closedness nothing keeps: only the directions at most
    :data:`SCAN_PROBE_ELEVATION` above the horizon (a scan's ceiling may be missing), and instead of
    the side a ray meets, the parity of the surfaces it crosses: from the free space of a room a ray
    crosses its shell once (or once more through each closed object on its way), from inside an
    object twice (the object's surface, then the shell). (miss, even) booleans (B, N') on the
    renderer's device: the ray escapes; it crosses an even, non-zero number of surfaces.

    A scan with no ceiling (:func:`scan_has_ceiling`) may stop below eye height and lack walls: a
    ray that leaves its bounds over the top passed over a wall, crossing no shell, so one crossing
    is counted for it; neither it nor one that leaves through a side (where a wall may be missing)
    counts as escaping: only a ray that leaves through the floor does."""
    low = directions[directions[:, 1] <= math.sin(math.radians(SCAN_PROBE_ELEVATION))]
    origins = centres[:, None, :].expand(len(centres), len(low), 3).reshape(-1, 3)
    rays = low[None].expand(len(centres), len(low), 3).reshape(-1, 3)
    ray_ids, t, _, _ = renderer.intersections(origins, rays)
    # a surface met twice within a millimetre (coplanar duplicates, a seam) is crossed once
    t64 = t.double()
    repeated = torch.zeros_like(ray_ids, dtype=torch.bool)
    repeated[1:] = (ray_ids[1:] == ray_ids[:-1]) & ((t64[1:] - t64[:-1]).abs() <= 1e-3)
    crossings = torch.bincount(ray_ids[~repeated], minlength=len(origins))
    escaped = crossings == 0
    if not scan_has_ceiling(renderer):
        top, side = scan_exits(renderer, origins, rays)
        crossings = crossings + top.to(crossings.dtype)
        escaped &= ~(top | side)
    shape = (len(centres), len(low))
    return escaped.reshape(shape), ((crossings > 0) & (crossings % 2 == 0)).reshape(shape)


def view_validity(
    renderer: ExactRenderer,
    world_T_cam: torch.Tensor,
    K: torch.Tensor,
    height: int,
    width: int,
    *,
    enclosure_rays: int = PenaltyConfig.enclosure_rays,
    render: RenderOutput | None = None,
    **limits: float | None,
) -> ViewValidity:
    """Classify B camera views.

    Args:
        renderer: the scene's exact renderer (its ray caster is reused).
        world_T_cam: (B, 4, 4) or (4, 4) poses.
        K: (3, 3) or (B, 3, 3) intrinsics.
        height, width: the views' image size.
        enclosure_rays: directions of the sphere of enclosure rays.
        render: the views' exact render at these poses, K and size, when the caller has one: its
            pixel-centre hits are used instead of casting them again.
        limits: :class:`ValidityLimits`' fields (``near``, ``min_distance``, ...), their defaults
            :class:`PenaltyConfig`'s.

    Examples:
        >>> import kadv
        >>> from kadv.geometry import intrinsics_from_fov, look_at
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> eyes = torch.tensor([[1.0, 1.5, 1.0], [1.0, 1.5, -1.0]])  # inside the room; behind its wall z = 0
        >>> poses = look_at(eyes, torch.tensor([[3.0, 1.0, 4.0], [3.0, 1.0, 4.0]]))
        >>> verdicts = view_validity(room, poses, intrinsics_from_fov(70.0, 24, 32), 24, 32)
        >>> verdicts.valid.tolist(), verdicts.verdicts
        ([True, False], ['valid', 'outside the scene'])
    """
    pose, scanned = check_world_T_cam(world_T_cam), renderer.shading.lighting == "scanned"
    batch, device = len(pose), renderer.device
    limits = ValidityLimits(**(limits if scanned else {**limits, "max_miss_share": None}))
    centres = pose[:, :3, 3].detach().double().to(device, non_blocking=True)
    partial = scanned and not scan_has_ceiling(renderer)
    rays = pixel_rays(pose, K, height, width, device=device) if render is None or partial else None
    hits = _view_hits(renderer, rays, render, (batch, height, width), limits.near, scanned)
    triangle_ids, view_back, near_hit, points = hits
    past_top, past_side, off_scan = None, None, None
    if scanned:  # a scan's noisy triangles share no plane exactly
        plane_share = dominant_plane_shares(points.double(), triangle_ids >= 0)
    if partial:  # no ceiling: past its walls' tops and its missing walls is no hole
        past_top, past_side, off_scan, plane_share = _open_scan(renderer, rays, triangle_ids, centres, plane_share)
    if not scanned:
        plane_share = plane_shares(renderer, triangle_ids)
    escaped, hidden = enclosure_hits(renderer, centres, _enclosure_directions(enclosure_rays, device))
    shares = (triangle_ids < 0, view_back, near_hit, escaped, hidden)
    return ViewValidity(
        *(share.double().mean(dim=1) for share in shares),
        distance=distance_to_surface(renderer, centres).detach(),
        plane_share=plane_share,
        past_top_fraction=past_top,
        past_side_fraction=past_side,
        off_scan=off_scan,
        limits=limits,
    )


def _view_hits(renderer: ExactRenderer, rays, render: RenderOutput | None, size: tuple, near: float, scanned: bool):
    """Each view's pixel-centre hits (B, H * W): triangles (-1: none), back faces, hits nearer than
    ``near`` and, for a scan, the points hit (B, H * W, 3); cast along ``rays`` (origins,
    directions) or read from the views' exact ``render``."""
    batch, height, width = size
    device = renderer.device
    points = None
    if render is None:
        origins, directions = rays
        hits = renderer.cast(origins, directions)
        view_back = renderer.back_facing(hits, directions).reshape(batch, height * width)
        triangle_ids = hits.triangle_ids.reshape(batch, height * width)
        near_hit = (triangle_ids >= 0) & (hits.t.double().reshape(batch, height * width) < near)
        if scanned:
            reach = torch.where(hits.hit, hits.t, 0.0).double()[:, None]
            points = (origins.reshape(-1, 3) + directions.reshape(-1, 3) * reach).reshape(batch, height * width, 3)
        return triangle_ids, view_back, near_hit, points
    check_shape(render.depth, f"B 1 {height} {width}", "render.depth", {"B": batch})
    triangle_ids = render.triangle_ids.reshape(batch, height * width).to(device)
    view_back = render.back_face.reshape(batch, height * width).to(device)
    near_hit = (triangle_ids >= 0) & (render.depth.reshape(batch, height * width).double().to(device) < near)
    if scanned:
        points = render.points.to(device).flatten(2).transpose(1, 2)
    return triangle_ids, view_back, near_hit, points


def _open_scan(renderer: ExactRenderer, rays, triangle_ids: torch.Tensor, centres: torch.Tensor, plane_share):
    """For a scan without a ceiling: each view's share of pixels that miss past its walls' tops and
    past its missing walls (B,), whether its centre is off the scan (B,), and its plane share with
    an opening where a wall is missing counted as that wall would be: one plane more."""
    origins, directions = rays
    batch, pixels = triangle_ids.shape
    top, side = scan_exits(renderer, origins.reshape(-1, 3), directions.reshape(-1, 3))
    missed = triangle_ids < 0
    past_top = (missed & top.reshape(batch, pixels)).double().mean(dim=1)
    past_side = (missed & side.reshape(batch, pixels)).double().mean(dim=1)
    lo, hi = (torch.as_tensor(b, dtype=torch.float64, device=renderer.device) for b in renderer.scene.bounds)
    off_scan = (centres[:, 1] >= hi[1] - SCAN_TOP_TOLERANCE) | (centres < lo).any(dim=1) | (centres > hi).any(dim=1)
    hits = 1.0 - missed.double().mean(dim=1)
    plane_share = torch.maximum(plane_share * hits, past_side) / (hits + past_side).clamp_min(1e-12)
    return past_top, past_side, off_scan, plane_share


@functools.lru_cache(maxsize=8)
def _enclosure_directions(count: int, device: torch.device) -> torch.Tensor:
    """:func:`fibonacci_sphere` as a float64 tensor on ``device``, made once."""
    return torch.from_numpy(fibonacci_sphere(count)).to(device)
