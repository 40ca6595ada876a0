"""Differentiable reprojection of anchor RGB-D layers into the current pose.

For each current pixel p with exact (detached) depth: X_P = D(p) K^-1 p~ (kornia ``depth_to_3d_v2``),
X_A = A_T_P X_P (``transform_points``), q = pi(K_A X_A) (``project_points``). The anchor is sampled at
q with a box filter of one current pixel (s x s bilinear sub-samples of the s-times supersampled
anchor), so the gradient is that of the box-filtered image the finite-difference reference sees.

Sampling is depth-aware: a bilinear tap counts only if the expected point X_A lies on the tap's
own surface (within a tolerance of its triangle's plane). Taps across an occlusion edge would mix
two surfaces and give the gradient of the wrong one; silhouettes get their own term
(:mod:`kadv.render.silhouette`). Depth is the z of the sampled anchor point mapped back with P_T_A.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch
from kornia.geometry.camera.perspective import project_points
from kornia.geometry.depth import depth_to_3d_v2
from kornia.geometry.linalg import transform_points

from kadv.checks import check_shape
from kadv.geometry.camera import batched_intrinsics
from kadv.geometry.vector import dot
from kadv.render.layers import AnchorLayers, guard_band_intrinsics
from kadv.render.straight_through import straight_through

__all__ = ["Reprojection", "reproject"]

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


def _gather(maps: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """maps (B, C, N), index (B, M) -> (B, C, M)."""
    return torch.gather(maps, 2, index[:, None, :].expand(-1, maps.shape[1], -1))


def _hat(offset: torch.Tensor) -> torch.Tensor:
    """Bilinear weight of a tap ``offset`` pixels away along one axis: max(0, 1 - |offset|)."""
    return (1.0 - offset.abs()).clamp_min(0.0)


def _sample_layer(anchor: AnchorLayers, layer: int, q: torch.Tensor, expected: torch.Tensor, plane_tolerance: float):
    """Depth-aware samples of one layer at hi-res pixel coordinates q (B, M, 2).

    Values come from one bilinear lookup (exact when q falls on anchor pixel centres, as with
    A = P); gradients only from the mean of four lookups half a hi-res pixel away diagonally,
    because a single lookup's derivative at a pixel centre is a one-sided difference and theirs
    is central. All five lookups read the same 3 x 3 taps, so each tap is fetched and tested
    against the expected surface once. A tap counts only if the expected point X_A lies on the
    tap's own surface (within ``plane_tolerance`` of its triangle's plane, relative to depth).

    Returns colour (B, 3, M) and point (B, 3, M), normalised, and the valid tap weight (B, M) of
    the value lookup (0 where no tap is on the expected surface).
    """
    _, _, _, height, width = anchor.rgb.shape
    # one gather per tap fetches colour, point, normal and mask together
    maps = (
        torch.cat(
            [anchor.rgb[:, layer], anchor.points[:, layer], anchor.normals[:, layer], anchor.mask[:, layer]], dim=1
        )
        .to(_DTYPE)
        .flatten(2)
    )
    x, y = q[..., 0] - 0.5, q[..., 1] - 0.5  # continuous pixel index (centres at +0.5)
    x0, y0 = torch.floor(x.detach() - 0.5), torch.floor(y.detach() - 0.5)  # the taps: x0 + {0, 1, 2}
    tolerance = plane_tolerance * expected[:, 2].abs()
    # the four diagonal lookups' weights on tap column i add up to hat(x - 0.5 - x_i) + hat(x + 0.5 - x_i)
    value_x = [_hat(x.detach() - (x0 + i)) for i in range(3)]
    value_y = [_hat(y.detach() - (y0 + j)) for j in range(3)]
    smooth_x = [_hat(x - 0.5 - (x0 + i)) + _hat(x + 0.5 - (x0 + i)) for i in range(3)]
    smooth_y = [_hat(y - 0.5 - (y0 + j)) + _hat(y + 0.5 - (y0 + j)) for j in range(3)]
    colour = point = total = smooth_colour = smooth_point = smooth_total = 0.0
    for j in range(3):
        for i in range(3):
            xi, yi = x0 + i, y0 + j
            inside = (xi >= 0) & (xi < width) & (yi >= 0) & (yi < height)
            index = (yi.clamp(0, height - 1) * width + xi.clamp(0, width - 1)).long()
            tap = _gather(maps, index)
            tap_rgb, tap_points, tap_normals = tap[:, 0:3], tap[:, 3:6], tap[:, 6:9]
            off_plane = ((expected - tap_points) * tap_normals).sum(1).abs()
            same_surface = inside & (tap[:, 9] > 0) & (off_plane <= tolerance)
            weight = value_x[i] * value_y[j] * same_surface
            smooth = smooth_x[i] * smooth_y[j] * same_surface
            with torch.no_grad():
                colour = colour + weight[:, None] * tap_rgb
                point = point + weight[:, None] * tap_points
                total = total + weight
            smooth_colour = smooth_colour + smooth[:, None] * tap_rgb
            smooth_point = smooth_point + smooth[:, None] * tap_points
            smooth_total = smooth_total + smooth
    smooth_total = smooth_total.clamp_min(1e-12)[:, None]
    smooth_colour, smooth_point = smooth_colour / smooth_total, smooth_point / smooth_total
    value_weight = total.clamp_min(1e-12)[:, None]
    colour = straight_through(smooth_colour, onto=colour / value_weight)
    point = straight_through(smooth_point, onto=point / value_weight)
    return colour, point, total


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
        expected_image = expected.reshape(batch, 3, hs, ws)
        value, slope_x, slope_y = (maps.new_empty(batch, channels, hs, ws) for channels in (7, 4, 4))
        # in bands of rows of equal height
        band = _band_rows(batch, hs, ws, maps.device)
        for top in range(0, hs, band):
            bottom = min(top + band, hs)
            rows = slice(top, bottom)
            _centred_taps(
                maps[:, :, top : bottom + 2],
                expected_image[:, :, rows],
                plane_tolerance,
                value[:, :, rows],
                slope_x[:, :, rows],
                slope_y[:, :, rows],
            )
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

    Args:
        anchor: anchor layers.
        depth: (B, 1, H, W) exact z-depth of the current views (detached; 0 = invalid).
        normals: (B, 3, H, W) current-camera-frame geometric normals of the surfaces seen; the
            sub-pixel samples of a pixel lie on that triangle's plane.
        A_T_P: (B, 4, 4) current-to-anchor camera transform, differentiable in the pose.
            The work runs on ``depth``'s device, where the anchor's maps must be.
        K: (3, 3) or (B, 3, 3) intrinsics of the current views.
        depth_tolerance: relative disagreement between warped and exact depth above which a
            pixel is invalid.
        plane_tolerance: relative distance from a tap's surface plane above which the tap is
            taken to belong to another surface.
        at_anchor: True when the caller rendered the anchor at these very poses and intrinsics (the
            comparison, which reads the poses back from the device, is then skipped); None: compare.
    """
    sizes = check_shape(depth, "B 1 H W", "depth")
    check_shape(normals, "B 3 H W", "normals", sizes)
    check_shape(A_T_P, "B 4 4", "A_T_P", sizes)
    batch, _, height, width = depth.shape
    device = depth.device
    depth = depth.detach().to(_DTYPE)
    valid_pixel = (depth[:, 0] > 0).reshape(batch, height * width)
    # Pixels without a surface get a stand-in depth so that no NaN enters the graph; they stay invalid.
    depth = torch.where(depth > 0, depth, torch.ones_like(depth))
    K = batched_intrinsics(K, batch)
    sub_points_P = _sub_pixel_points(depth, normals, K.to(device, _DTYPE, non_blocking=True), anchor.supersample)
    P_T_A = torch.linalg.inv_ex(A_T_P.double())[0].to(device, _DTYPE)  # inv_ex: no wait for its check
    if _at_anchor(anchor, A_T_P, K, height, width, at_anchor):
        expected = sub_points_P.reshape(batch, -1, 3).transpose(1, 2)  # A = P, to within _SAME_POSE
        # pixel centres, shaped as one sub-sample per pixel
        centres = depth_to_3d_v2(
            depth[:, 0], _shift_half_pixel(K.to(device, _DTYPE, non_blocking=True)), normalize_points=False
        )
        _, q = _project_to_anchor(anchor, centres[:, :, None, :, None, :], A_T_P)
        shift = straight_through(q).transpose(1, 2).reshape(batch, 2, height, width)

        def layer_pixels(layer: int) -> tuple[torch.Tensor, ...]:
            return _anchor_layer_pixels(anchor, layer, expected, shift, P_T_A, plane_tolerance)
    else:
        expected, q = _project_to_anchor(anchor, sub_points_P, A_T_P)

        def layer_pixels(layer: int) -> tuple[torch.Tensor, ...]:
            return _sampled_layer_pixels(anchor, layer, q, expected, P_T_A, plane_tolerance, (height, width))

    return _composite_layers(
        layer_pixels, anchor.num_layers, depth.reshape(batch, -1), valid_pixel, (height, width), depth_tolerance
    )


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


def _sampled_layer_pixels(
    anchor: AnchorLayers,
    layer: int,
    q: torch.Tensor,
    expected: torch.Tensor,
    P_T_A: torch.Tensor,
    plane_tolerance: float,
    size: tuple[int, int],
) -> tuple[torch.Tensor, ...]:
    """One layer's warp per pixel from its sub-pixel samples read by :func:`_sample_layer`:
    colour (B, 3, H * W), z-depth (B, H * W) and whether every sub-sample found its surface (B, H * W)."""
    batch = q.shape[0]
    height, width = size
    s = anchor.supersample

    def image(samples: torch.Tensor) -> torch.Tensor:  # (B, C, M) -> (B, C, sH, sW): the samples' order
        return samples.reshape(batch, samples.shape[1], s * height, s * width)

    c, p, total = _sample_layer(anchor, layer, q, expected, plane_tolerance)
    ok = _block_min(image(total[:, None]), s) > _MIN_TAP_WEIGHT  # (B, 1, H, W): the least weight
    sub_z = image(transform_points(P_T_A[:, None], p.transpose(1, 2))[..., 2][:, None])
    # 1/z is affine across a plane's image, so the harmonic mean is the pixel-centre depth
    inverse = 1.0 / torch.where(ok.repeat_interleave(s, 2).repeat_interleave(s, 3), sub_z, 1.0).clamp_min(1e-9)
    z = 1.0 / _block_mean(inverse, s)
    return _block_mean(image(c), s).flatten(2), z.flatten(1), ok.flatten(1)


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
