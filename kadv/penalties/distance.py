"""Distance from camera centres to the nearest surface, with its analytic gradient, and L_dist."""

from __future__ import annotations

import torch

from kadv.checks import check_shape, check_values
from kadv.render.exact import ExactRenderer

__all__ = ["distance_to_surface", "shortcut_penalty"]


class _SurfaceDistance(torch.autograd.Function):
    """d(c) = |c - q(c)| with q the closest surface point; dd/dc = (c - q) / |c - q|.

    The closest point moves with c, but only tangentially to the surface, so it drops out of
    the derivative (away from the medial axis, where d is not differentiable).
    """

    @staticmethod
    def forward(ctx, centres: torch.Tensor, renderer: ExactRenderer) -> torch.Tensor:
        caster = renderer.caster
        closest = caster.closest_points(centres.detach().to(caster.device, torch.float32))
        offset = centres.detach() - closest.to(centres)
        distance = offset.norm(dim=-1)
        ctx.save_for_backward(offset / distance.clamp_min(1e-12)[:, None])
        return distance

    @staticmethod
    def backward(ctx, grad_output: torch.Tensor) -> tuple[torch.Tensor, None]:
        (direction,) = ctx.saved_tensors
        return grad_output[:, None] * direction, None


def distance_to_surface(renderer: ExactRenderer, centres: torch.Tensor) -> torch.Tensor:
    """Distance (B,) in metres from each centre (B, 3) to the nearest triangle of the scene.

    Uses the renderer's ray caster (closest points); differentiable in ``centres``.

    Raises:
        ValueError: on a wrong shape or NaN/inf centres.

    Examples:
        >>> import kadv
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))  # x 0-4, y 0-3, z 0-5
        >>> centres = torch.tensor([[1.0, 1.5, 2.5], [2.0, 2.5, 2.5]], dtype=torch.float64)
        >>> distance_to_surface(room, centres).round(decimals=9).tolist()  # to the wall x = 0; the ceiling
        [1.0, 0.5]
    """
    check_shape(centres, "B 3", "centres")
    check_values(torch.isfinite(centres.detach()), "centres: contain NaN or inf")
    return _SurfaceDistance.apply(centres, renderer)


def shortcut_penalty(distance: torch.Tensor, d_th: float) -> torch.Tensor:
    """L_dist = 1/d - 1/d_th where d < d_th, else 0 (zero gradient there).

    Continuous at d = d_th and growing without bound as the camera reaches a surface.

    Examples:
        >>> shortcut_penalty(torch.tensor([0.1, 0.2, 0.5], dtype=torch.float64), d_th=0.2).tolist()  # 1/0.1 - 1/0.2
        [5.0, 0.0, 0.0]
    """
    if d_th <= 0:
        raise ValueError(f"d_th must be positive, got {d_th}")
    close = distance < d_th
    safe = torch.where(close, distance, torch.full_like(distance, d_th)).clamp_min(1e-9)
    return torch.where(close, 1.0 / safe - 1.0 / d_th, torch.zeros_like(distance))
