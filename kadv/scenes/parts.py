"""Building blocks of generated scenes: textured quads and boxes as :class:`MeshPart` s."""

from __future__ import annotations

import numpy as np

from kadv.scenes.scene import MeshPart

__all__ = [
    "box_parts",
    "facing",
    "hexahedron_parts",
    "mesh_part",
    "overlapped",
    "planar_quad",
    "quad_part",
    "room_shell_parts",
]

_QUAD_FACES = np.array([[0, 2, 1], [0, 3, 2]])


def quad_part(corners: np.ndarray, material: int, name: str, uv_extent: tuple[float, float] = (1.0, 1.0)) -> MeshPart:
    """Two triangles of the quad ``corners`` (4, 3), UVs spanning ``uv_extent``.

    The front face's normal is (c3 - c0) x (c1 - c0); corner 0 has uv (0, 0), corner 1 (u, 0).
    """
    u, v = uv_extent
    uv = np.array([[0, 0], [u, 0], [u, v], [0, v]], np.float64)
    return MeshPart(np.asarray(corners, np.float64), _QUAD_FACES, uv[_QUAD_FACES], None, material, name)


def overlapped(corners: np.ndarray, margin: float = 1e-3) -> np.ndarray:
    """Grow a quad by ``margin`` past its edges: faces that merely touch leave float cracks rays slip through."""
    u = corners[1] - corners[0]
    v = corners[3] - corners[0]
    u_hat, v_hat = u / np.linalg.norm(u), v / np.linalg.norm(v)
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    return corners + margin * (signs[:, :1] * u_hat + signs[:, 1:] * v_hat)


def facing(corners: np.ndarray, toward: np.ndarray) -> np.ndarray:
    """The quad ``corners`` (4, 3), mirrored if needed (corners 0 and 1 swap, 2 and 3) so its front
    face looks along ``toward`` (3,); the edge from corner 0 to 3 keeps its direction."""
    corners = np.asarray(corners, np.float64)
    normal = np.cross(corners[3] - corners[0], corners[1] - corners[0])
    return corners if normal @ np.asarray(toward, np.float64) > 0 else corners[[1, 0, 3, 2]]


def planar_quad(corners: np.ndarray, material: int, name: str, tile: float) -> MeshPart:
    """A quad whose UVs are its world position along its edges over ``tile`` metres.

    Pieces of one plane (a wall around its window) so share one continuous texture placement.
    """
    corners = overlapped(np.asarray(corners, np.float64))
    u_hat = corners[1] - corners[0]
    v_hat = corners[3] - corners[0]
    axes = np.stack([u_hat / np.linalg.norm(u_hat), v_hat / np.linalg.norm(v_hat)], axis=1)
    uv = corners @ axes / tile
    return MeshPart(corners, _QUAD_FACES, uv[_QUAD_FACES], None, material, name)


def box_parts(lo: np.ndarray, hi: np.ndarray, material: int, name: str, tile: float) -> list[MeshPart]:
    """The six outward-facing faces of the axis-aligned box ``lo`` (3,) - ``hi`` (3,), one texture
    repeat per ``tile`` metres from each face's corner."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    faces = np.array(
        [
            [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0]],
            [[x1, y0, z1], [x0, y0, z1], [x0, y1, z1], [x1, y1, z1]],
            [[x0, y0, z1], [x0, y0, z0], [x0, y1, z0], [x0, y1, z1]],
            [[x1, y0, z0], [x1, y0, z1], [x1, y1, z1], [x1, y1, z0]],
            [[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]],
            [[x0, y0, z1], [x1, y0, z1], [x1, y0, z0], [x0, y0, z0]],
        ],
        np.float64,
    )
    parts = []
    for index, corners in enumerate(faces):
        corners = overlapped(corners)
        extent = (np.linalg.norm(corners[1] - corners[0]) / tile, np.linalg.norm(corners[3] - corners[0]) / tile)
        parts.append(quad_part(corners, material, f"{name}.face{index}", extent))
    return parts


_HEXAHEDRON_FACES = np.array([[0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])


def hexahedron_parts(corners: np.ndarray, material: int, name: str, tile: float) -> list[MeshPart]:
    """The six outward-facing faces of a convex hexahedron (a sloped beam, a stair stringer):
    ``corners`` (8, 3) are the bottom face's corners in order around it, then the top face's, each
    above its bottom corner; one texture repeat per ``tile`` metres from each face's corner."""
    corners = np.asarray(corners, np.float64)
    centre = corners.mean(axis=0)
    parts = []
    for index, face in enumerate(_HEXAHEDRON_FACES):
        quad = overlapped(facing(corners[face], corners[face].mean(axis=0) - centre))
        extent = (np.linalg.norm(quad[1] - quad[0]) / tile, np.linalg.norm(quad[3] - quad[0]) / tile)
        parts.append(quad_part(quad, material, f"{name}.face{index}", extent))
    return parts


def mesh_part(vertices: np.ndarray, faces: np.ndarray, material: int, name: str, tile: float) -> MeshPart:
    """A triangle mesh (a trimesh primitive: a cylinder, a sphere) with UVs projected along each
    face's dominant axis, one texture repeat per ``tile`` metres; ``faces`` (F, 3) wound outwards."""
    vertices, faces = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    corners = vertices[faces]
    normal = np.abs(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    dominant = normal.argmax(axis=1)
    # the two axes other than the dominant one, per face: (F, 2)
    others = np.array([[1, 2], [0, 2], [0, 1]])[dominant]
    uv = np.take_along_axis(corners, np.repeat(others[:, None, :], 3, axis=1), axis=2) / tile
    return MeshPart(vertices, faces, uv, None, material, name)


def room_shell_parts(size: tuple[float, float, float], materials: list[int], tile: float) -> list[MeshPart]:
    """The floor, ceiling and four walls of the room x in [0, W], y in [0, H], z in [0, D], facing
    into it, one texture repeat per ``tile`` metres; ``materials`` (6,) in the order floor, ceiling,
    walls at z = 0, z = D, x = 0 and x = W."""
    W, H, D = size
    walls = {
        "floor": [[0, 0, 0], [W, 0, 0], [W, 0, D], [0, 0, D]],
        "ceiling": [[0, H, D], [W, H, D], [W, H, 0], [0, H, 0]],
        "wall_z0": [[W, 0, 0], [0, 0, 0], [0, H, 0], [W, H, 0]],
        "wall_z1": [[0, 0, D], [W, 0, D], [W, H, D], [0, H, D]],
        "wall_x0": [[0, 0, 0], [0, 0, D], [0, H, D], [0, H, 0]],
        "wall_x1": [[W, 0, D], [W, 0, 0], [W, H, 0], [W, H, D]],
    }
    parts = []
    for material, (name, corners) in zip(materials, walls.items()):
        corners = overlapped(np.array(corners, np.float64))
        extent = (np.linalg.norm(corners[1] - corners[0]) / tile, np.linalg.norm(corners[3] - corners[0]) / tile)
        parts.append(quad_part(corners, material, name, extent))
    return parts
