"""Differentiable reprojection of anchor RGB-D layers into the current pose.

For each current pixel p with exact (detached) depth: X_P = D(p) K^-1 p~ (kornia ``depth_to_3d_v2``),
X_A = A_T_P X_P (``transform_points``), q = pi(K_A X_A) (``project_points``), and the anchor is read
at q. Depth is the z of the anchor point read there, mapped back with P_T_A.

- A moved view (:func:`warp_boxed`) reads the anchor box-filtered to its pixels (the mean of each
  pixel's s x s sub-samples, as the exact render's colour is) with one ``grid_sample`` per layer,
  and tests per pixel that the point read is the point expected (the same surface seen from both
  poses). Layers behind the first are read only where those before failed. (Not kornia's
  ``warp_frame_depth``: it takes one camera matrix for both frames, where the guard band moves the
  anchor's principal point and the box filter its scale, and holds the point fixed along the ray.)
- At the anchor's own pose (:func:`reproject` with ``at_anchor``), the samples sit on the anchor's
  pixel centres: each sub-sample's taps are tested against its own triangle's plane and the values
  and slopes come in closed form (:func:`_anchor_layer_pixels`), exact to the last bit. This is
  what the default step (``refresh=always``) runs.

Either way the gradient is that of the box-filtered image the finite-difference reference sees;
lookups across an occlusion edge would mix two surfaces and give the gradient of the wrong one, so
silhouettes get their own term (:mod:`kadv.render.silhouette`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from kornia.geometry.camera.perspective import project_points
from kornia.geometry.depth import depth_to_3d_v2
from kornia.geometry.linalg import transform_points
from kornia.geometry.line import ParametrizedLine
from kornia.geometry.plane import Hyperplane
from kornia.geometry.vector import Scalar, Vector3
from torch.nn import functional as F

from kadv.checks import check_shape
from kadv.geometry.camera import batched_intrinsics
from kadv.geometry.vector import dot
from kadv.render.layers import AnchorLayers, BoxedLayers, guard_band_intrinsics
from kadv.render.straight_through import straight_through

__all__ = ["Reprojection", "reproject", "warp_boxed"]

# Per-sample arithmetic (a few hundred thousand sub-pixel samples) runs in float32, which halves its
# memory traffic; the pose algebra stays in float64. benchmarks/gradcheck.py holds either way.
_DTYPE = torch.float32
# relative pose and intrinsics entries within this of the anchor's are the anchor's view (A = P)
_SAME_POSE = 1e-9


@dataclass
class Reprojection:
    """The anchor warped into the current views.

    Attributes:
        rgb: (B, 3, H, W) warped colour (0 where invalid).
        depth: (B, 1, H, W) warped z-depth in the current frame (0 where invalid).
        valid: (B, 1, H, W) bool: sampled from the right surface, inside the anchor, depth agrees.
        layer: (B, 1, H, W) int64 index of the anchor layer used (-1 where invalid).
    """

    rgb: torch.Tensor
    depth: torch.Tensor
    valid: torch.Tensor
    layer: torch.Tensor


# hi-res samples whose closed-form taps are computed at once, at most. On the CPU, per view: bands
# this large spread each of their hundred-odd torch calls' fixed cost (dispatch, waking the threads)
# over enough samples, and keep the temporaries to a few MB (bands of 64 rows at 640 samples took
# half as long again). On a GPU, whose cost is the launches, the batch's views at once, within a
# few hundred MB of temporaries.
_BAND_SAMPLES = 160_000
_DEVICE_BAND_SAMPLES = 4_000_000


def _centred_taps(
    maps: torch.Tensor,
    expected: torch.Tensor,
    plane_tolerance: float,
    value: torch.Tensor,
    slope_x: torch.Tensor,
    slope_y: torch.Tensor,
) -> None:
    """Value (B, 7, h, w) = (r, g, b, z, on the surface, x, y) and the blurred lookups' slopes
    (B, 4, h, w) in x and y of (r, g, b, z) at samples on anchor pixel centres, from the maps
    (B, 11, h + 2, w + 2) of :func:`_anchor_layer_pixels` around them and the samples' expected
    points (B, 3, h, w); written into the given tensors.

    The blurred lookups of :func:`_sample_layer` weigh the taps of a sample on a tap's centre by
    0.5, 1, 0.5 along each axis, with derivatives -1, 0, 1 in the sample's position: both are
    separable, so each row of taps is combined along x first.
    """
    h, w = expected.shape[-2:]
    tolerance = plane_tolerance * expected[:, 2].abs()
    weighted_rows, sloped_rows = [], []
    for j in range(3):
        row = []
        for i in range(3):
            tap = maps[:, :, j : j + h, i : i + w]
            # n . expected - n . point, unrolled (a sum over 3 channels is slow)
            off_plane = torch.addcmul(
                torch.addcmul(torch.addcmul(-tap[:, 10], expected[:, 0], tap[:, 7]), expected[:, 1], tap[:, 8]),
                expected[:, 2],
                tap[:, 9],
            )
            # (r, g, b, z, 1) on the expected surface, 0 elsewhere
            row.append(tap[:, 0:5] * ((tap[:, 4] > 0) & (off_plane.abs() <= tolerance))[:, None])
        weighted_rows.append(torch.add(row[0], row[2]).mul_(0.5).add_(row[1]))
        sloped_rows.append(row[2] - row[0])
        if j == 1:
            centre = row[1]
    blurred = torch.add(weighted_rows[0], weighted_rows[2]).mul_(0.5).add_(weighted_rows[1])
    blurred_x = torch.add(sloped_rows[0], sloped_rows[2]).mul_(0.5).add_(sloped_rows[1])
    blurred_y = weighted_rows[2].sub_(weighted_rows[0])
    total = blurred[:, 4:5].clamp_min_(1e-12)
    # derivative of blurred / total along each axis (quotient rule)
    torch.div(blurred_x[:, 0:4].sub_(blurred[:, 0:4] * (blurred_x[:, 4:5] / total)), total, out=slope_x)
    torch.div(blurred_y[:, 0:4].sub_(blurred[:, 0:4] * (blurred_y[:, 4:5] / total)), total, out=slope_y)
    value[:, 0:5] = centre
    torch.mul(maps[:, 5:7, 1 : 1 + h, 1 : 1 + w], centre[:, 4:5], out=value[:, 5:7])


def _band_rows(batch: int, height: int, width: int, device: torch.device) -> int:
    """Rows of a (batch, ..., height, width) hi-res image whose taps :func:`_centred_taps` computes
    at once: bands of equal height, within :data:`_BAND_SAMPLES` samples per view on the CPU and
    :data:`_DEVICE_BAND_SAMPLES` for the batch elsewhere."""
    if device.type == "cpu":
        return math.ceil(height / math.ceil(height * width / _BAND_SAMPLES))
    return math.ceil(height / math.ceil(batch * height * width / _DEVICE_BAND_SAMPLES))


def _anchor_layer_pixels(
    anchor: AnchorLayers,
    layer: int,
    expected: torch.Tensor,
    shift: torch.Tensor,
    P_T_A: torch.Tensor,
    plane_tolerance: float,
) -> tuple[torch.Tensor, ...]:
    """One layer's warp per pixel for views at the anchor's own pose (A = P).

    The sub-pixel samples (B, 3, M) ``expected`` (anchor frame) then sit on the anchor's hi-res
    pixel centres: they form a hi-res image of the frame, and sample (row, column) is anchor pixel
    (row + s g, column + s g). The 3 x 3 taps are shifted slices of the anchor maps and the lookups'
    values and slopes in q come in closed form (:func:`_centred_taps`). Values are exact; the
    gradient is the pixel's mean slope times the motion of its centre's projection, ``shift``
    (B, 2, H, W) = q - q.detach(): the same as :func:`_sample_layer` gives, to first order in
    the sub-pixel offsets (each sub-sample's projection moves as its pixel centre's).

    Returns colour (B, 3, H * W), z-depth (B, H * W) (the harmonic mean of the sub-samples', which
    is the pixel-centre depth on a plane) and whether every sub-sample found its surface (B, H * W).
    """
    s, g = anchor.supersample, anchor.guard_band
    batch, _, height, width = shift.shape
    hs, ws, start = s * height, s * width, s * g - 1
    window = (..., slice(start, start + hs + 2), slice(start, start + ws + 2))
    points, normals = anchor.points[:, layer][window].to(_DTYPE), anchor.normals[:, layer][window].to(_DTYPE)
    # channels: the derivative's (r, g, b, z, mask), then x, y and the plane (normal, n . point)
    maps = torch.cat(
        [
            anchor.rgb[:, layer][window].to(_DTYPE),
            points[:, 2:3],
            anchor.mask[:, layer][window].to(_DTYPE),
            points[:, 0:2],
            normals,
            (points * normals).sum(1, keepdim=True),
        ],
        dim=1,
    )
    with torch.no_grad():
        value, slope_x, slope_y = _taps_in_bands(maps, expected.reshape(batch, 3, hs, ws), plane_tolerance)
        on_surface = value[:, 4:5]
        ok = _block_min(on_surface, s) > _MIN_TAP_WEIGHT  # (B, 1, H, W): every sub-sample
        colour = _block_mean(value[:, 0:3], s)
        # 1/z is affine across a plane's image, so the harmonic mean is the pixel-centre depth; its
        # derivative weighs sub-sample k by z^2 / (S z_k^2)
        sub_z = torch.where(on_surface > 0, value[:, 3:4], 1.0).clamp_min(1e-9)
        z = 1.0 / _block_mean(1.0 / sub_z, s)
        weight = 1.0 / (sub_z * sub_z)
        mean_x, mean_y = _block_mean(slope_x[:, 0:3], s), _block_mean(slope_y[:, 0:3], s)
        z_squared = z * z
        depth_x, depth_y = (z_squared * _block_mean(slope[:, 3:4] * weight, s) for slope in (slope_x, slope_y))
        point = z_squared * _block_mean(torch.cat([value[:, 5:7], value[:, 3:4]], dim=1) * weight, s)
    colour = colour + shift[:, 0:1] * mean_x + shift[:, 1:2] * mean_y
    # the depth also moves with P_T_A at fixed anchor points
    moved = transform_points(P_T_A[:, None], point.flatten(2).transpose(1, 2))[..., 2].reshape(batch, 1, height, width)
    z = z + shift[:, 0:1] * depth_x + shift[:, 1:2] * depth_y + straight_through(moved)
    return colour.flatten(2), z.flatten(1), ok.flatten(1)


def _taps_in_bands(
    maps: torch.Tensor, expected: torch.Tensor, plane_tolerance: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """:func:`_centred_taps` of the anchor ``maps`` (B, 10, hs + 2, ws + 2) at the sub-samples
    ``expected`` (B, 3, hs, ws), in bands of rows of equal height: the values (B, 7, hs, ws) and
    the slopes in x and y (B, 4, hs, ws)."""
    batch, _, hs, ws = expected.shape
    value, slope_x, slope_y = (maps.new_empty(batch, channels, hs, ws) for channels in (7, 4, 4))
    band = _band_rows(batch, hs, ws, maps.device)
    for top in range(0, hs, band):
        bottom = min(top + band, hs)
        rows = slice(top, bottom)
        _centred_taps(
            maps[:, :, top : bottom + 2],
            expected[:, :, rows],
            plane_tolerance,
            value[:, :, rows],
            slope_x[:, :, rows],
            slope_y[:, :, rows],
        )
    return value, slope_x, slope_y


# below this cosine between a sub-pixel ray and its pixel's plane, the ray grazes the plane and
# keeps the pixel-centre depth instead of meeting the plane far away
# Pixel coordinates of points that do not project (behind the anchor, at infinity): far outside
# every image, so each lookup there finds nothing, yet finite, so no NaN reaches the gradient.
_OFF_IMAGE = -1e6
_GRAZING_COSINE = 1e-3
_MIN_TAP_WEIGHT = 1e-9  # a sub-sample whose taps all lie on other surfaces found nothing


def _sub_pixel_points(depth: torch.Tensor, normals: torch.Tensor, K: torch.Tensor, s: int) -> torch.Tensor:
    """Current-frame points (B, H, s, W, s, 3) of the s x s sub-pixel samples of each pixel, in the
    order of a hi-res image (row, sub-row, column, sub-column).

    Sub-pixel rays meet the plane of the pixel's triangle (``normals`` (B, 3, H, W), current
    camera frame) at the pixel's exact depth (B, 1, H, W), positive everywhere.
    """
    # kornia's meshgrid puts pixel (i, j) at (j, i); kadv's centres are at +0.5: shift the principal point.
    points = depth_to_3d_v2(depth[:, 0], _shift_half_pixel(K), normalize_points=False)[:, :, None, :, None, :]
    per_pixel = depth[:, 0, :, None, :, None, None]  # (B, H, 1, W, 1, 1)
    rays = points / per_pixel.clamp_min(1e-12)  # through the pixel centres, z = 1
    offsets = (torch.arange(s, dtype=depth.dtype, device=depth.device) + 0.5) / s - 0.5
    dy, dx = torch.meshgrid(offsets, offsets, indexing="ij")
    focal = torch.stack([K[:, 0, 0], K[:, 1, 1]], dim=-1)[:, None, None, :]
    shift = torch.stack([dx, dy], dim=-1) / focal  # (B, s, s, 2) in normalised image coordinates
    shift = torch.cat([shift, torch.zeros_like(shift[..., :1])], dim=-1)[:, None, :, None, :, :]  # (B, 1, s, 1, s, 3)
    n = normals.detach().to(depth.dtype).permute(0, 2, 3, 1)[:, :, None, :, None, :]
    # the plane n . X = n . point along each sub-pixel ray rays + shift; shift has no z
    numerator = dot(n, points)[..., None]
    denominator = dot(n, rays)[..., None] + (n[..., 0:1] * shift[..., 0:1] + n[..., 1:2] * shift[..., 1:2])
    # a sub-pixel ray is as long as its pixel's, to well within the cosine's precision
    grazing = denominator.abs() < _GRAZING_COSINE * rays.norm(dim=-1, keepdim=True)
    t = torch.where(grazing, per_pixel, numerator / torch.where(grazing, 1.0, denominator))
    return (rays + shift) * t


def _project_to_anchor(
    anchor: AnchorLayers, sub_points_P: torch.Tensor, A_T_P: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Anchor-frame points (B, 3, M) and hi-res anchor pixel coordinates q (B, M, 2) of the
    sub-pixel points (B, H, s, W, s, 3), M = H * s * W * s; points behind the anchor land far outside."""
    batch, height = sub_points_P.shape[:2]
    device = sub_points_P.device
    sub_points_A = transform_points(A_T_P[:, None, None].to(device, _DTYPE), sub_points_P.reshape(batch, height, -1, 3))
    sub_points_A = sub_points_A.reshape(batch, -1, 3)
    q = project_points(sub_points_A, anchor.K[:, None].to(device, _DTYPE, non_blocking=True))
    q = torch.where(torch.isfinite(q), q, torch.full_like(q, _OFF_IMAGE))
    return sub_points_A.transpose(1, 2), q


def reproject(
    anchor: AnchorLayers,
    depth: torch.Tensor,
    normals: torch.Tensor,
    A_T_P: torch.Tensor,
    K: torch.Tensor,
    depth_tolerance: float = 0.01,
    plane_tolerance: float = 0.02,
    at_anchor: bool | None = None,
) -> Reprojection:
    """Warp the anchor into current views.

    At the anchor's own pose the warp is exact, sub-pixel by sub-pixel (:func:`_anchor_layer_pixels`);
    elsewhere it reads one sample per pixel of the box-filtered anchor (:func:`warp_boxed`).

    Args:
        anchor: anchor layers.
        depth: (B, 1, H, W) exact z-depth of the current views (detached; 0 = invalid).
        normals: (B, 3, H, W) current-camera-frame geometric normals of the surfaces seen (the
            sub-pixel samples at the anchor's pose, and the points a move slides along, lie on
            that triangle's plane).
        A_T_P: (B, 4, 4) current-to-anchor camera transform, differentiable in the pose.
            The work runs on ``depth``'s device, where the anchor's maps must be.
        K: (3, 3) or (B, 3, 3) intrinsics of the current views.
        depth_tolerance: relative disagreement between warped and exact points above which a
            pixel is invalid.
        plane_tolerance: at the anchor's pose, relative distance from a tap's surface plane above
            which the tap is taken to belong to another surface.
        at_anchor: True when the caller rendered the anchor at these very poses and intrinsics (the
            comparison, which reads the poses back from the device, is then skipped); None: compare.
    """
    sizes = check_shape(depth, "B 1 H W", "depth")
    check_shape(A_T_P, "B 4 4", "A_T_P", sizes)
    batch, _, height, width = depth.shape
    K = batched_intrinsics(K, batch)
    check_shape(normals, "B 3 H W", "normals", sizes)
    if not _at_anchor(anchor, A_T_P, K, height, width, at_anchor):
        return warp_boxed(anchor.boxed, depth, normals, A_T_P, K, depth_tolerance)
    device = depth.device
    depth = depth.detach().to(_DTYPE)
    valid_pixel = (depth[:, 0] > 0).reshape(batch, height * width)
    # Pixels without a surface get a stand-in depth so that no NaN enters the graph; they stay invalid.
    depth = torch.where(depth > 0, depth, torch.ones_like(depth))
    sub_points_P = _sub_pixel_points(depth, normals, K.to(device, _DTYPE, non_blocking=True), anchor.supersample)
    P_T_A = torch.linalg.inv_ex(A_T_P.double())[0].to(device, _DTYPE)  # inv_ex: no wait for its check
    expected = sub_points_P.reshape(batch, -1, 3).transpose(1, 2)  # A = P, to within _SAME_POSE
    # pixel centres, shaped as one sub-sample per pixel
    centres = depth_to_3d_v2(
        depth[:, 0], _shift_half_pixel(K.to(device, _DTYPE, non_blocking=True)), normalize_points=False
    )
    _, q = _project_to_anchor(anchor, centres[:, :, None, :, None, :], A_T_P)
    shift = straight_through(q).transpose(1, 2).reshape(batch, 2, height, width)

    def layer_pixels(layer: int) -> tuple[torch.Tensor, ...]:
        return _anchor_layer_pixels(anchor, layer, expected, shift, P_T_A, plane_tolerance)

    return _composite_layers(
        layer_pixels, anchor.num_layers, depth.reshape(batch, -1), valid_pixel, (height, width), depth_tolerance
    )


# a lookup whose taps all hit surfaces reads a hit fraction of 1 (bilinear weights sum to 1 up to rounding)
_FULL = 1.0 - 1e-4


def warp_boxed(
    boxed: BoxedLayers,
    depth: torch.Tensor,
    normals: torch.Tensor,
    A_T_P: torch.Tensor,
    K: torch.Tensor,
    tolerance: float = 0.01,
) -> Reprojection:
    """Warp box-filtered anchor layers into current views: one bilinear lookup per pixel.

    Each current pixel's point X_P (its exact depth along the pixel-centre ray) goes to the anchor,
    X_A = A_T_P X_P, and is looked up at its projection q with ``grid_sample``. As the pose moves,
    X_A moves where the pixel's ray meets the plane of the surface it hit (fixed in the anchor's
    frame): away from the anchor's own pose, the point sliding along the surface moves q too.

    A lookup holds if its taps all hit a surface and the point it reads lies within ``tolerance``
    (relative to depth) of X_A: the same surface, seen from both poses (one depth test per pixel).
    The first layer that holds gives the pixel's colour and the depth's gradient (its value is the
    exact depth it was tested against); the next layer is read only at the pixels where the layers
    before it failed. Values come from the lookup at q; gradients, where it is differentiable in the
    pose, from the mean of four lookups half a fine pixel away diagonally (a central difference; one
    lookup of :attr:`BoxedLayers.diagonal_means`).

    Args:
        boxed: the anchor's box-filtered layers (:attr:`AnchorLayers.boxed`), on ``depth``'s device.
        depth: (B, 1, H, W) exact z-depth of the current views (detached; 0 = no surface).
        normals: (B, 3, H, W) current-camera-frame normals of the surfaces the pixels hit.
        A_T_P: (B, 4, 4) current-to-anchor camera transform, differentiable in the pose.
        K: (3, 3) or (B, 3, 3) intrinsics of the current views.
        tolerance: the depth test's relative tolerance.
    """
    sizes = check_shape(depth, "B 1 H W", "depth")
    check_shape(A_T_P, "B 4 4", "A_T_P", check_shape(normals, "B 3 H W", "normals", sizes))
    batch, _, height, width = depth.shape
    device = depth.device
    K = batched_intrinsics(K, batch).to(device, _DTYPE, non_blocking=True)
    depth = depth.detach().to(_DTYPE)
    hit = (depth[:, 0] > 0).reshape(batch, -1)
    # pixels without a surface get a stand-in depth so that no NaN enters the graph; they stay invalid
    depth = torch.where(depth > 0, depth, torch.ones_like(depth))
    points_P = depth_to_3d_v2(depth[:, 0], _shift_half_pixel(K), normalize_points=False).reshape(batch, -1, 3)
    points_A = _on_surface(points_P, normals.detach().to(device, _DTYPE).flatten(2).transpose(1, 2), A_T_P)
    q = project_points(points_A, boxed.K[:, None].to(device, _DTYPE, non_blocking=True))
    q = torch.where(torch.isfinite(q) & (points_A[..., 2:] > 0), q, torch.full_like(q, _OFF_IMAGE))
    P_T_A = torch.linalg.inv_ex(A_T_P.double())[0].to(device, _DTYPE)  # inv_ex: no wait for its check
    smooth = torch.is_grad_enabled() and A_T_P.requires_grad
    colour, warped, layer_used = _read_layers(boxed, q, points_A, hit, P_T_A, tolerance, smooth)
    valid = layer_used >= 0
    shape = (batch, 1, height, width)
    # the depth's value is the exact one the test passed against; the warp gives its gradient
    warped = torch.where(valid, depth.reshape(batch, -1) + (warped - warped.detach()), 0.0)
    return Reprojection(
        rgb=colour.reshape(batch, 3, height, width).float(),
        depth=warped.reshape(shape).float(),
        valid=valid.reshape(shape),
        layer=layer_used.reshape(shape),
    )


def _read_layers(
    boxed: BoxedLayers,
    q: torch.Tensor,
    points_A: torch.Tensor,
    hit: torch.Tensor,
    P_T_A: torch.Tensor,
    tolerance: float,
    smooth: bool,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Each pixel's colour (B, 3, N), current-frame depth (B, N) and layer (B, N; -1: none) from the
    first boxed layer that holds at it, the pixels (``hit`` (B, N)) at boxed coordinates q (B, N, 2)
    expecting points ``points_A`` (B, N, 3); a layer is read only at the pixels still to do."""
    batch, pixels = hit.shape
    device = q.device
    colour = torch.zeros(batch, 3, pixels, dtype=_DTYPE, device=device)
    warped = torch.zeros(batch, pixels, dtype=_DTYPE, device=device)
    layer_used = torch.full((batch, pixels), -1, dtype=torch.int64, device=device)
    todo = hit
    for layer in range(boxed.maps.shape[1]):
        if layer == 0:  # every pixel: no compaction
            c, z, ok = _lookup(boxed, 0, q, points_A, P_T_A, tolerance, smooth)
            ok = ok & hit
            colour, warped = torch.where(ok[:, None], c, colour), torch.where(ok, z, warped)
            layer_used, todo = torch.where(ok, 0, layer_used), todo & ~ok
            continue
        count = todo.sum(1)
        most = int(count.max())
        if most == 0:
            break
        # the pixels still to do first, in order (a permutation's head: no index twice)
        index = torch.argsort((~todo).to(torch.uint8), dim=1, stable=True)[:, :most]
        live = torch.arange(most, device=device)[None] < count[:, None]
        q_todo = q.gather(1, index[..., None].expand(-1, -1, 2))
        expected = points_A.gather(1, index[..., None].expand(-1, -1, 3))
        c, z, ok = _lookup(boxed, layer, q_todo, expected, P_T_A, tolerance, smooth)
        ok = ok & live
        spread = index[:, None].expand(-1, 3, -1)
        colour = colour.scatter(2, spread, torch.where(ok[:, None], c, colour.gather(2, spread)))
        warped = warped.scatter(1, index, torch.where(ok, z, warped.gather(1, index)))
        layer_used = layer_used.scatter(1, index, torch.where(ok, layer, layer_used.gather(1, index)))
        todo = todo.scatter(1, index, todo.gather(1, index) & ~ok)
    return colour, warped, layer_used


def _on_surface(points_P: torch.Tensor, normals_P: torch.Tensor, A_T_P: torch.Tensor) -> torch.Tensor:
    """Anchor-frame points (B, N, 3) of current-frame points (B, N, 3), equal in value
    to A_T_P X_P and differentiable as the point where each pixel's ray meets its surface's plane
    (normals (B, N, 3), current frame), which stays put in the anchor's frame as the pose moves.
    Where no gradient is wanted, A_T_P X_P itself: the plane only shapes the gradient."""
    A_T_P = A_T_P.to(points_P.device, _DTYPE)
    # row vectors times R^T: one matrix product a view, whose backward is one more (a broadcast
    # product of N 3 x 3 matrices would sum N of them)
    rotation_T, origin = A_T_P[:, :3, :3].transpose(1, 2), A_T_P[:, None, :3, 3].expand_as(points_P)
    ray = points_P @ rotation_T  # the pixel's ray in the anchor frame, to the hit
    if not ray.requires_grad:  # no gradient enabled, or none in the pose and the intrinsics
        return ray + origin
    normal = normals_P @ rotation_T.detach()
    hit = (ray + origin).detach()
    plane = Hyperplane(Vector3(normal), Scalar(-dot(normal, hit)))
    # kornia's intersection needs |n . direction| above an absolute eps: the unit ray's
    length = ray.detach().norm(dim=-1, keepdim=True).clamp_min(1e-12)
    grazing = dot(normal, ray.detach() / length).abs() < _GRAZING_COSINE
    _, point = ParametrizedLine(origin, ray / length).intersect(plane, eps=_GRAZING_COSINE)
    # a ray grazing its plane keeps the point it hit, moving with the camera
    return torch.where(grazing[..., None], ray + origin, point)


def _lookup(
    boxed: BoxedLayers,
    layer: int,
    q: torch.Tensor,
    expected: torch.Tensor,
    P_T_A: torch.Tensor,
    tolerance: float,
    smooth: bool,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Boxed layer ``layer`` read at boxed-pixel coordinates q (B, M, 2), whose points should be
    ``expected`` (B, M, 3, anchor frame): colour (B, 3, M), current-frame z-depth (B, M) and whether
    the lookup holds (B, M). With ``smooth``, the gradients of the diagonal lookups' mean."""

    def read_at(channels: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
        """Maps (B, C, h, w) read at pixel coordinates (B, 1, M, 2): (B, C, M)."""
        # grid_sample's coordinates with align_corners=False: pixel i's centre, i + 0.5, at (2i + 1) / n - 1
        scale = grid.new_tensor([2.0 / channels.shape[-1], 2.0 / channels.shape[-2]])
        return F.grid_sample(channels, (grid * scale - 1.0).to(channels.dtype), align_corners=False)[:, :, 0]

    with torch.no_grad():
        centre = read_at(boxed.maps[:, layer], q.detach()[:, None])
    tolerance = tolerance * expected[..., 2].detach()
    expected = expected.detach().transpose(1, 2)
    # the lookup must read the point expected
    off = (centre[:, 3:6] - expected).mT
    holds = (centre[:, 6] >= _FULL) & (dot(off, off) <= tolerance * tolerance)  # (B, M)
    colour, point = centre[:, 0:3], centre[:, 3:6]
    if not smooth:
        return colour, _z_in(P_T_A, point), holds
    mean = read_at(boxed.diagonal_means[:, layer], q[:, None] + 0.5)
    # the four lookups' mean point is the centre's on one plane (bilinear reads of a plane's points
    # are linear); across an occlusion edge, or where a tap missed, it is pulled off: those pixels'
    # values carry no gradient (the silhouette term's)
    off = (mean[:, 3:6].detach() - centre[:, 3:6]).mT
    planar = (dot(off, off) <= tolerance * tolerance)[:, None]
    colour = torch.where(planar, straight_through(mean[:, 0:3], onto=colour), colour)
    point = torch.where(planar, straight_through(mean[:, 3:6], onto=point), point)
    z = _z_in(P_T_A, point)
    return colour, torch.where(planar[:, 0], z, z.detach()), holds  # a point that moves with nothing


def _z_in(P_T_A: torch.Tensor, points_A: torch.Tensor) -> torch.Tensor:
    """Current-frame z (B, M) of anchor-frame points (B, 3, M)."""
    return transform_points(P_T_A[:, None], points_A.transpose(1, 2))[..., 2]


def _at_anchor(
    anchor: AnchorLayers, A_T_P: torch.Tensor, K: torch.Tensor, height: int, width: int, known: bool | None
) -> bool:
    """Whether the views (B, 4, 4 relative poses, (B, 3, 3) intrinsics) are the anchor's own, up to
    rounding (``known``: as the caller says, None: compared), and its band holds every sample's 3 x 3 taps."""
    s, g = anchor.supersample, anchor.guard_band
    if s * g < 1 or tuple(anchor.rgb.shape[-2:]) != (s * (height + 2 * g), s * (width + 2 * g)):
        return False
    if known is not None:
        return known
    identity = torch.eye(4, dtype=torch.float64).expand(A_T_P.shape[0], 4, 4)
    return torch.allclose(A_T_P.detach().double().cpu(), identity, rtol=0.0, atol=_SAME_POSE) and torch.allclose(
        anchor.K.double().cpu(), guard_band_intrinsics(K, g, s).cpu(), rtol=0.0, atol=_SAME_POSE
    )


def _block_mean(image: torch.Tensor, s: int) -> torch.Tensor:
    """Mean (B, C, H, W) of each s x s block of a hi-res image (B, C, sH, sW), differentiable.

    A sum of s * s strided slices: avg_pool2d's CPU kernel takes three times as long here."""
    total = sum(image[..., i::s, j::s] for i in range(s) for j in range(s))
    return total / (s * s)


def _block_min(image: torch.Tensor, s: int) -> torch.Tensor:
    """Least value (B, C, H, W) of each s x s block of a hi-res image (B, C, sH, sW)."""
    least = image[..., 0::s, 0::s]
    for k in range(1, s * s):
        least = torch.minimum(least, image[..., k // s :: s, k % s :: s])
    return least


def _composite_layers(
    layer_pixels: Callable[[int], tuple[torch.Tensor, ...]],
    layers: int,
    depth: torch.Tensor,
    valid_pixel: torch.Tensor,
    size: tuple[int, int],
    depth_tolerance: float,
) -> Reprojection:
    """Each pixel takes the first of ``layers`` anchor layers (read per pixel by ``layer_pixels``)
    whose samples all find the expected surface and whose depth agrees with the exact depth (B, H*W).
    A pixel straddling an occlusion edge is left to the silhouette term rather than represented by
    one side's average."""
    batch, pixels = depth.shape
    height, width = size
    device = depth.device
    colour = torch.zeros(batch, 3, pixels, dtype=_DTYPE, device=device)
    found = torch.zeros(batch, pixels, dtype=torch.bool, device=device)
    layer_used = torch.full((batch, pixels), -1, dtype=torch.int64, device=device)
    warped_depth = torch.zeros(batch, pixels, dtype=_DTYPE, device=device)
    for layer in range(layers):
        c, z, ok = layer_pixels(layer)
        agree = ok & valid_pixel & ((z - depth).abs() <= depth_tolerance * depth)
        take = agree & ~found
        colour = torch.where(take[:, None], c, colour)
        warped_depth = torch.where(take, z, warped_depth)
        layer_used = torch.where(take, torch.full_like(layer_used, layer), layer_used)
        found = found | take
    shape = (batch, 1, height, width)
    return Reprojection(
        rgb=torch.where(found[:, None], colour, torch.zeros_like(colour)).reshape(batch, 3, height, width).float(),
        depth=warped_depth.reshape(shape).float(),
        valid=found.reshape(shape),
        layer=layer_used.reshape(shape),
    )


def _shift_half_pixel(K: torch.Tensor) -> torch.Tensor:
    shifted = K.clone()
    shifted[:, 0, 2] -= 0.5
    shifted[:, 1, 2] -= 0.5
    return shifted
