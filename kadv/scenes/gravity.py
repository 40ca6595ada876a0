"""Which way is up in a mesh that does not say: a reconstruction left in its first camera's frame
(SLAM and TSDF outputs, phone-scanner exports) has no axis up.

Gravity leaves its mark on indoor geometry: floors, table tops and seats are horizontal, walls
vertical, and the floor is the lowest large plane, with the room standing on it. So the candidates
for up are the directions of the mesh's dominant planes (the axes of its Manhattan frame, where it
has one, and the largest clusters of its face normals), each either way round; a candidate scores
the area of the lowest plane across it (the floor, for the true up); candidates across which the
mesh's extent is a storey's height come first, since a wall's direction spans a room's length. Which
way round is decided by what stands between floor and ceiling: furniture, nearer the floor. The
winner is refined to the area-weighted normal of that floor plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["UpEstimate", "estimate_up", "rotation_onto_y"]

# a face is across a candidate direction (horizontal, for up) within this many degrees
_ACROSS_DEG = 10.0
# metres above the lowest point along a candidate within which a face belongs to the lowest plane
_PLANE_BAND = 0.05
# a storey's height, metres: a room's extent along up lies within it (a partial scan's too)
_STOREY = (1.0, 4.5)
# normal clusters: directions on a Fibonacci sphere, and how many of the largest become candidates
_BINS, _CLUSTERS = 2000, 6
# what stands between floor and ceiling must sit this share of their distance above the middle to
# turn the floor found the other way round (an empty room's walls sit at the middle)
_SIGN_MARGIN = 0.05


@dataclass(frozen=True)
class UpEstimate:
    """The up direction a mesh implies.

    Attributes:
        up: (3,) unit vector in the file's frame.
        floor_area: the area of the lowest plane across it, m² (file units² times ``scale`` squared).
        manhattan: whether it is an axis of the mesh's Manhattan frame.
    """

    up: np.ndarray
    floor_area: float
    manhattan: bool


def _fibonacci(count: int) -> np.ndarray:
    index = np.arange(count) + 0.5
    z = 1.0 - 2.0 * index / count
    radius = np.sqrt(1.0 - z * z)
    angle = np.pi * (1.0 + 5**0.5) * index
    return np.stack([radius * np.cos(angle), radius * np.sin(angle), z], axis=1)


def _candidates(normals: np.ndarray, area: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """Directions (and whether each is a Manhattan axis): the eigenvectors of the area-weighted
    scatter of the unit normals, then the centres of the largest clusters of normals (either sign)."""
    scatter = (normals * area[:, None]).T @ normals
    axes = [(v, True) for v in np.linalg.eigh(scatter)[1].T]
    bins = _fibonacci(_BINS)
    nearest = np.abs(normals @ bins.T).argmax(axis=1)
    weight = np.bincount(nearest, area, _BINS)
    for b in np.argsort(-weight)[:_CLUSTERS]:
        members = nearest == b
        signed = normals[members] * np.sign(normals[members] @ bins[b])[:, None]
        centre = (signed * area[members, None]).sum(axis=0)
        if np.linalg.norm(centre) > 0:
            axes.append((centre / np.linalg.norm(centre), False))
    return axes


def _lowest_plane(up: np.ndarray, corners: np.ndarray, normals: np.ndarray, area: np.ndarray, scale: float):
    """The faces of the lowest plane across ``up``: horizontal within :data:`_ACROSS_DEG`, within
    :data:`_PLANE_BAND` of the lowest point."""
    heights = (corners @ up) * scale  # (F, 3)
    across = np.abs(normals @ up) >= np.cos(np.radians(_ACROSS_DEG))
    low = heights.min()
    return across & (heights.max(axis=1) <= low + _PLANE_BAND), heights.max() - low


def estimate_up(vertices: np.ndarray, faces: np.ndarray, scale: float = 1.0) -> UpEstimate:
    """The up direction (3,) of a mesh (vertices (V, 3) in file units of ``scale`` metres, triangles
    (F, 3)), whatever its triangles' winding.

    Examples:
        >>> import trimesh
        >>> room = trimesh.creation.box(extents=(6.0, 2.8, 4.0))  # a room 2.8 m high, y up
        >>> estimate = estimate_up(room.vertices, room.faces)
        >>> np.round(np.abs(estimate.up), 3).tolist(), round(estimate.floor_area, 1)
        ([0.0, 1.0, 0.0], 24.0)
    """
    corners = np.asarray(vertices, np.float64)[np.asarray(faces, np.int64)]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(cross, axis=1)
    keep = length > 1e-12
    corners, cross, length = corners[keep], cross[keep], length[keep]
    normals, area = cross / length[:, None], length / 2 * scale**2
    scored = []
    for axis, manhattan in _candidates(normals, area):
        for up in (axis, -axis):
            plane, extent = _lowest_plane(up, corners, normals, area, scale)
            storey = _STOREY[0] <= extent <= _STOREY[1]
            scored.append((storey, float(area[plane].sum()), up, plane, manhattan))
    _, _, up, plane, manhattan = max(scored, key=lambda s: (s[0], s[1]))
    # which way round: furniture stands on the floor, so what lies between the lowest and the
    # highest plane sits nearer the floor (a scan misses the floor under it, not the ceiling)
    heights = corners.mean(axis=1) @ up * scale
    low, high = heights.min(), heights.max()
    between = (heights > low + 2 * _PLANE_BAND) & (heights < high - 2 * _PLANE_BAND)
    margin = _SIGN_MARGIN * (high - low)
    if area[between].sum() > 0 and np.average(heights[between], weights=area[between]) > (low + high) / 2 + margin:
        up = -up
        plane = _lowest_plane(up, corners, normals, area, scale)[0]
    floor_area = float(area[plane].sum())
    # refined: the floor's own normal, turned up
    signed = normals[plane] * np.sign(normals[plane] @ up)[:, None]
    refined = (signed * area[plane, None]).sum(axis=0)
    up = refined / np.linalg.norm(refined) if np.linalg.norm(refined) > 0 else up
    return UpEstimate(up, floor_area, manhattan)


def rotation_onto_y(up: np.ndarray) -> np.ndarray:
    """The least rotation (3, 3) taking the unit vector ``up`` to +y (Rodrigues' formula).

    Examples:
        >>> r = rotation_onto_y(np.array([0.0, 0.0, 1.0]))
        >>> np.round(r @ [0.0, 0.0, 1.0], 6).tolist(), round(float(np.linalg.det(r)), 6)
        ([0.0, 1.0, 0.0], 1.0)
    """
    up = np.asarray(up, np.float64) / np.linalg.norm(up)
    y = np.array([0.0, 1.0, 0.0])
    axis = np.cross(up, y)
    sine, cosine = np.linalg.norm(axis), float(up @ y)
    if sine < 1e-12:
        return np.eye(3) if cosine > 0 else np.diag([1.0, -1.0, -1.0])  # down: half a turn about x
    k = axis / sine
    skew = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + sine * skew + (1 - cosine) * skew @ skew
