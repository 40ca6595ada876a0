"""Baked irradiance as shading reads it per hit: stored at a lattice of barycentric points per
triangle and side (:mod:`kadv.render.bake` computes it), interpolated between the three lattice
points around a hit."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch.nn import functional as F

__all__ = ["BakedLighting", "lattice_counts", "lattice_ij", "lattice_taps", "nearest_tap"]


@dataclass
class BakedLighting:
    """Irradiance on each triangle's lattice, both sides.

    Attributes:
        resolution: (F,) int64 lattice steps per edge (0: one point, at the centroid or, in scenes
            of very many triangles, shared by the small triangles of a texel cell that face one way).
        offsets: (2, F) int64 index of each triangle's first lattice point, front side then back.
        irradiance: (N, 3) float32 linear irradiance at the lattice points.
        exposure: the scene's one scale from radiance to display values.
        buried: (N,) bool, the lattice points whose own estimate was discarded and filled from their
            neighbours' (inside closed meshes, beyond a wall, in crevices).
        enclosed: (N,) bool, the lattice points on a side of a surface that the free space the
            scene's cameras stand in does not reach (inside closed meshes, beyond a wall), whatever
            the triangles' windings: the bake's flood fill.
        seconds: how long the bake took (0 when read from the cache).
    """

    resolution: np.ndarray
    offsets: np.ndarray
    irradiance: np.ndarray
    exposure: float
    buried: np.ndarray
    enclosed: np.ndarray
    seconds: float = 0.0

    def irradiance_at(self, triangle_ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor) -> torch.Tensor:
        """(N, 3) irradiance at hits: triangle ids (N,), Open3D barycentrics (N, 2) and side (N,) bool,
        on the hits' device (the tables are copied there once)."""
        tables = self._tables(triangle_ids.device)
        taps, weights = lattice_taps(tables["resolution"], tables["offsets"], triangle_ids, bary, back)
        # the three gathers, weighted and summed in one call
        return F.embedding_bag(taps, tables["irradiance"], per_sample_weights=weights.float(), mode="sum")

    def buried_at(self, triangle_ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor) -> torch.Tensor:
        """(N,) bool: whether the lattice point nearest each hit (as :meth:`irradiance_at` takes them)
        had its own estimate discarded (:attr:`buried`)."""
        return self._nearest_flag("buried", triangle_ids, bary, back)

    def enclosed_at(self, triangle_ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor) -> torch.Tensor:
        """(N,) bool: whether each hit lies on a side of its surface that the cameras' free space
        does not reach (:attr:`enclosed`): the lattice point nearest it and most of its triangle's
        points on that side are enclosed. The fill leaves points on a room's edges out (the walls
        overlap there), so the nearest point alone would hide hits beside them; most of the side
        alone would hide a floor's open part when most of its triangle lies under a cabinet."""
        sides = self._tables(triangle_ids.device)["enclosed_sides"][back.long(), triangle_ids]
        return sides & self._nearest_flag("enclosed", triangle_ids, bary, back)

    def _nearest_flag(
        self, name: str, triangle_ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor
    ) -> torch.Tensor:
        """(N,) the per-point flags ``name`` ("buried" or "enclosed") at the lattice point nearest each hit."""
        tables = self._tables(triangle_ids.device)
        return tables[name][nearest_tap(tables["resolution"], tables["offsets"], triangle_ids, bary, back)]

    def _tables(self, device: torch.device) -> dict[str, torch.Tensor]:
        """The lattice's arrays as tensors on ``device``, made on first use, and "enclosed_sides"
        (2, F): whether most lattice points of each triangle's front and back side are enclosed."""
        tables = self.__dict__.setdefault("_device_tables", {})
        if device not in tables:
            counts = lattice_counts(self.resolution)
            total = np.concatenate([[0], np.cumsum(self.enclosed, dtype=np.int64)])
            arrays = {
                "resolution": self.resolution,
                "offsets": self.offsets,
                "irradiance": self.irradiance,
                "buried": self.buried,
                "enclosed": self.enclosed,
                "enclosed_sides": 2 * (total[self.offsets + counts] - total[self.offsets]) > counts,
            }
            tables[device] = {k: torch.from_numpy(np.ascontiguousarray(a)).to(device) for k, a in arrays.items()}
        return tables[device]


def lattice_counts(resolution: np.ndarray) -> np.ndarray:
    """(F,) lattice points on one side of each triangle, of resolutions (F,): (r + 1)(r + 2) / 2."""
    return (resolution + 1) * (resolution + 2) // 2


def lattice_ij(r: int) -> tuple[np.ndarray, np.ndarray]:
    """Lattice steps (i, j), i + j <= r, row by row: point k of a triangle of resolution r."""
    i, j = np.triu_indices(r + 1)
    j = j - i
    return i, j


def lattice_taps(
    resolution: torch.Tensor, offsets: torch.Tensor, triangle_ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The three lattice points (N, 3) around each hit and their weights (N, 3), which sum to 1.

    Args:
        resolution: (F,) lattice steps per triangle.
        offsets: (2, F) first lattice point of each triangle's front and back side.
        triangle_ids: (N,) hit triangles.
        bary: (N, 2) Open3D barycentrics (u, v): the point is (1 - u - v) p0 + u p1 + v p2.
        back: (N,) True on the back side.
    """
    r = resolution.index_select(0, triangle_ids)
    start = offsets.reshape(-1).index_select(0, back.long() * offsets.shape[1] + triangle_ids)
    # column by column: on (N, 3) a where or a sum costs several times its three columns' work
    u, v = bary.clamp_min(0.0).unbind(dim=1)
    total = (u + v).clamp_min(1.0)
    scale = r.to(bary.dtype)  # r = 0 (one point): a = b = 0, and no step leaves the point
    a, b = u / total * scale, v / total * scale
    i0 = torch.minimum(a.long(), (r - 1).clamp_min(0))  # a, b >= 0: truncation floors
    j0 = torch.minimum(b.long(), r - 1 - i0).clamp_min(0)
    # in [0, 1] (b may pass r - a by a rounding): every weight below is >= 0
    fa, fb = a - i0, (b - j0).clamp_max(1.0)
    upper = fa + fb > 1.0
    # point (i, j) is row i's start, i (r + 1) - i (i - 1) / 2, plus j; the next row starts r + 1 - i on.
    # Below the diagonal: (i, j), (i + 1, j), (i, j + 1); above it: (i + 1, j + 1), (i, j + 1), (i + 1, j)
    corner = start + i0 * (r + 1) - i0 * (i0 - 1) // 2 + j0
    step = (r > 0).long()
    down = (r + 1 - i0) * step
    taps = torch.stack(
        [
            corner + upper * (down + step),
            corner + torch.where(upper, step, down),
            corner + torch.where(upper, down, step),
        ],
        dim=1,
    )
    weights = torch.stack(
        [(1.0 - fa - fb).abs(), torch.where(upper, 1.0 - fa, fa), torch.where(upper, 1.0 - fb, fb)], 1
    )
    return taps, weights / (weights[:, 0] + weights[:, 1] + weights[:, 2])[:, None]


def nearest_tap(
    resolution: torch.Tensor, offsets: torch.Tensor, triangle_ids: torch.Tensor, bary: torch.Tensor, back: torch.Tensor
) -> torch.Tensor:
    """(N,) the lattice point nearest each hit: the heaviest of its :func:`lattice_taps`."""
    taps, weights = lattice_taps(resolution, offsets, triangle_ids, bary, back)
    return taps.gather(1, weights.argmax(dim=1, keepdim=True))[:, 0]
