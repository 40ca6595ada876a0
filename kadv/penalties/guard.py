"""Step guard: a camera centre may not move through (or too close to) a surface."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from kadv.checks import check_shape
from kadv.penalties.config import PenaltyConfig
from kadv.penalties.distance import distance_to_surface
from kadv.render.raycast import ExactRenderer

__all__ = ["StepCheck", "step_guard"]

# Parallel rays around the segment: a ray through the exact shared edge of two triangles can
# slip between them in Embree's non-watertight mode; a few micro-offset copies cannot all do so.
_OFFSETS = 1e-4 * np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]], np.float64)


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


def _perpendicular_basis(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(direction[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    first = np.cross(direction, helper)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    return first, np.cross(direction, first)


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
    old = c_old.detach().double().cpu().numpy()
    new = c_new.detach().double().cpu().numpy()
    if not (np.isfinite(old).all() and np.isfinite(new).all()):
        raise ValueError("c_old / c_new: contain NaN or inf")
    step = new - old
    length = np.linalg.norm(step, axis=1)
    moving = length > 0
    direction = np.where(moving[:, None], step / np.maximum(length, 1e-300)[:, None], [[1.0, 0.0, 0.0]])
    first, second = _perpendicular_basis(direction)
    origins = old[:, None, :] + _OFFSETS[None, :, :1] * first[:, None] + _OFFSETS[None, :, 1:] * second[:, None]
    hits = renderer.cast(origins, np.repeat(direction[:, None], len(_OFFSETS), axis=1)).numpy()
    first_hit = hits.t.reshape(len(old), len(_OFFSETS)).min(axis=1)  # metres: directions are unit
    clear = np.clip(first_hit - margin, 0.0, None)
    fraction = np.where(moving, np.clip(clear / np.maximum(length, 1e-300), 0.0, 1.0), 1.0)
    distances = distance_to_surface(renderer, torch.from_numpy(np.concatenate([old, new]))).numpy()
    start_distance, end_distance = distances[: len(old)], distances[len(old) :]
    # A camera already within the margin may still back away from the surface.
    allowed = (first_hit > length + margin) & ((end_distance >= margin) | (end_distance > start_distance))
    return StepCheck(torch.from_numpy(allowed), torch.from_numpy(fraction), torch.from_numpy(end_distance))
