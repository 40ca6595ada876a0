"""Step guard: a camera centre may not move through (or too close to) a surface."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from kadv.checks import check_shape, check_values
from kadv.penalties.config import PenaltyConfig
from kadv.penalties.distance import distance_to_surface
from kadv.render.exact import ExactRenderer

__all__ = ["StepCheck", "step_guard"]

# Parallel rays around the segment: a ray through the exact shared edge of two triangles can
# slip between them in Embree's non-watertight mode; a few micro-offset copies cannot all do so.
_OFFSETS = 1e-4 * torch.tensor([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]], dtype=torch.float64)


@dataclass
class StepCheck:
    """Verdict of :func:`step_guard` per camera.

    Attributes:
        allowed: (B,) bool, True where the whole step is clear.
        max_fraction: (B,) float in [0, 1]: the largest fraction of the step that stays clear
            (ending at least ``margin`` before the first surface on the segment).
        end_distance: (B,) distance of the proposed centre to the nearest surface.
    """

    allowed: torch.Tensor
    max_fraction: torch.Tensor
    end_distance: torch.Tensor


def _perpendicular_basis(direction: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Two unit vectors (B, 3) perpendicular to unit ``direction`` (B, 3) and to each other."""
    axes = torch.eye(3, dtype=direction.dtype, device=direction.device)
    helper = torch.where(direction[:, :1].abs() < 0.9, axes[0], axes[1])
    first = torch.linalg.cross(direction, helper)
    first = first / torch.linalg.vector_norm(first, dim=1, keepdim=True)
    return first, torch.linalg.cross(direction, first)


def step_guard(
    renderer: ExactRenderer, c_old: torch.Tensor, c_new: torch.Tensor, margin: float = PenaltyConfig.margin
) -> StepCheck:
    """Check the straight moves c_old -> c_new (B, 3) against the scene's surfaces.

    A step is refused when its segment crosses a surface, passes within ``margin`` of the first
    surface along its line, or ends closer than ``margin`` to any surface (unless it ends farther
    from the surfaces than it started, so a camera that got too close can back away).

    Raises:
        ValueError: on mismatched shapes or NaN/inf centres.

    Examples:
        >>> import kadv
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> start = torch.tensor([[1.0, 1.5, 2.5], [1.0, 1.5, 2.5]], dtype=torch.float64)
        >>> end = torch.tensor([[2.0, 1.5, 2.5], [-1.0, 1.5, 2.5]], dtype=torch.float64)
        >>> check = step_guard(room, start, end, margin=0.1)
        >>> check.allowed.tolist()  # the second move would leave through the wall x = 0
        [True, False]
        >>> round(check.max_fraction[1].item(), 3)  # it may go 0.9 m of its 2 m, to 0.1 m from the wall
        0.45
    """
    check_shape(c_new, "B 3", "c_new", check_shape(c_old, "B 3", "c_old"))
    device = renderer.device
    old = c_old.detach().to(device, torch.float64, non_blocking=True)
    new = c_new.detach().to(device, torch.float64, non_blocking=True)
    check_values(torch.isfinite(old).all() & torch.isfinite(new).all(), "c_old / c_new: contain NaN or inf")
    step = new - old
    length = torch.linalg.vector_norm(step, dim=1)
    moving = length > 0
    unit_x = torch.eye(3, dtype=torch.float64, device=device)[0]
    direction = torch.where(moving[:, None], step / length.clamp_min(1e-300)[:, None], unit_x)
    first, second = _perpendicular_basis(direction)
    offsets = _OFFSETS.to(device, non_blocking=True)
    origins = old[:, None, :] + offsets[None, :, :1] * first[:, None] + offsets[None, :, 1:] * second[:, None]
    hits = renderer.cast(origins, direction[:, None].expand(-1, len(offsets), 3))
    first_hit = hits.t.double().reshape(len(old), len(offsets)).amin(dim=1)  # metres: directions are unit
    clear = (first_hit - margin).clamp_min(0.0)
    fraction = torch.where(moving, (clear / length.clamp_min(1e-300)).clamp(0.0, 1.0), 1.0)
    distances = distance_to_surface(renderer, torch.cat([old, new]))
    start_distance, end_distance = distances[: len(old)], distances[len(old) :]
    # A camera already within the margin may still back away from the surface.
    allowed = (first_hit > length + margin) & ((end_distance >= margin) | (end_distance > start_distance))
    where = c_new.device
    return StepCheck(allowed.to(where), fraction.to(where), end_distance.to(where))
