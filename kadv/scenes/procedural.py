"""Procedural furnished rooms: rectangular or L-shaped rooms, halls and corridors, with furniture,
windows, doors, pictures, rugs and ceiling lamps; deterministic per seed.

The room's walls, floor and ceiling face into it and every piece of furniture is a set of closed,
outward-facing boxes, so a camera inside furniture or outside the room sees back faces, as in a
loaded scene. A door opens onto a closed corridor; a window has a glass pane (transparent, so
dropped at load like a file's glass) and shows a bright ground and backdrop outside, above which
rays escape to the sky. The lamps' bulbs are emitters (dropped, their centres become lights) and a
light stands inside each window.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
import torch
import trimesh

from kadv.geometry.camera import Camera
from kadv.geometry.pose import look_at
from kadv.scenes.emitters import MISSING_ENVMAP_RADIANCE, Emitters
from kadv.scenes.materials import textured_materials
from kadv.scenes.parts import box_parts, facing, hexahedron_parts, mesh_part, overlapped, planar_quad, quad_part
from kadv.scenes.scene import Material, MeshPart, Scene, assemble_scene

__all__ = ["CORRIDOR_SHARE", "HALL_SHARE", "ROOM_FEATURES", "check_shares", "procedural_room"]

_UP = np.array([0.0, 1.0, 0.0])
_EYE_CLEARANCE = 1.0  # metres kept free of furniture around the file camera
_GAP = 0.08  # metres between pieces of furniture
# Real buildings are not all rooms of a few metres: views down a corridor or across a hall span
# depths that a 3.5-8 m room never shows.
CORRIDOR_SHARE = 0.15
"""The default share of generated footprints that are corridors."""
HALL_SHARE = 0.15
"""The default share of generated footprints that are halls."""
ROOM_FEATURES = ("stairs_share", "sun_share", "glazing_share", "trim_share", "round_share")
"""``procedural_room``'s shares of what real rooms have and its first rooms lacked (each 0 by default)."""


def _rects_overlap(a: np.ndarray, b: np.ndarray, gap: float = 0.0) -> bool:
    """Whether the floor rectangles (x0, z0, x1, z1) ``a`` and ``b`` overlap, or come nearer than ``gap``."""
    return bool(a[0] < b[2] + gap and b[0] < a[2] + gap and a[1] < b[3] + gap and b[1] < a[3] + gap)


def _inside(rect: np.ndarray, container: np.ndarray, margin: float = 0.0) -> bool:
    return bool(np.all(rect[:2] >= container[:2] + margin) and np.all(rect[2:] <= container[2:] - margin))


@dataclass
class _Wall:
    """A wall from ``start`` to ``end`` (x, z) at floor level; its front looks along ``inward``."""

    start: np.ndarray
    end: np.ndarray
    openings: list[tuple[float, float, float, float, str]] = field(default_factory=list)

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))

    @property
    def along(self) -> np.ndarray:
        return (self.end - self.start) / self.length

    @property
    def inward(self) -> np.ndarray:
        along = self.along
        return np.array([along[1], -along[0]])

    def point(self, u: float, y: float, w: float = 0.0) -> np.ndarray:
        """World point ``u`` metres along the wall, ``y`` high, ``w`` metres into the room (negative: out)."""
        xz = self.start + u * self.along + w * self.inward
        return np.array([xz[0], y, xz[1]])

    def rect(self, u0: float, u1: float, w0: float, w1: float) -> np.ndarray:
        """The floor rectangle (x0, z0, x1, z1) between ``u0``-``u1`` along the wall and ``w0``-``w1`` into the room."""
        corners = np.array([self.point(u, 0.0, w)[[0, 2]] for u in (u0, u1) for w in (w0, w1)])
        return np.concatenate([corners.min(axis=0), corners.max(axis=0)])


class _Builder:
    """Collects parts and materials; every ``add_*`` returns nothing and appends."""

    def __init__(self, rng: np.random.Generator, tile: float) -> None:
        self.rng = rng
        self.tile = tile
        self.parts: list[MeshPart] = []
        self.materials: list[Material] = []
        self.lights: list[np.ndarray] = []

    def material(self, role: str) -> int:
        material = textured_materials(self.rng, role, 1)[0]
        material.name = f"{role}{len(self.materials)}"
        self.materials.append(material)
        return len(self.materials) - 1

    def special(self, material: Material) -> int:
        self.materials.append(material)
        return len(self.materials) - 1

    def quad(self, corners: np.ndarray, toward: np.ndarray, material: int, name: str) -> None:
        self.parts.append(planar_quad(facing(corners, toward), material, name, self.tile))

    def box(self, lo: np.ndarray, hi: np.ndarray, material: int, name: str) -> None:
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        self.parts += box_parts(lo, hi, material, name, self.tile)

    def framed_quad(self, corners: np.ndarray, toward: np.ndarray, material: int, name: str) -> None:
        """A quad with its texture mapped once over it (a picture, a backdrop)."""
        corners = overlapped(facing(corners, toward))
        self.parts.append(quad_part(corners, material, name))


def _footprint(
    rng: np.random.Generator, corridor_share: float, hall_share: float
) -> tuple[list[np.ndarray], list[_Wall]]:
    """Floor rectangles (x0, z0, x1, z1) and the walls around their union: a corridor, a hall or a
    room, as a rectangle, or for a room an L."""
    # no shape is drawn when only rooms may come, so that those rooms are the rooms of the
    # generator before halls and corridors, which the shipped weights' first stages trained on
    shape = rng.random() if corridor_share + hall_share > 0 else 1.0
    room = shape >= corridor_share + hall_share
    if room:
        width, depth = rng.uniform(3.5, 8.0, size=2)
    elif shape < corridor_share:
        width, depth = rng.permutation([rng.uniform(2.0, 3.2), rng.uniform(10.0, 30.0)])
    else:
        width, depth = rng.uniform(8.0, 16.0, size=2)
    if room and rng.random() < 0.4:
        w1, d1 = width * rng.uniform(0.45, 0.7), depth * rng.uniform(0.45, 0.7)
        rects = [np.array([0, 0, width, d1]), np.array([0, d1, w1, depth])]
        outline = [(0, 0), (0, depth), (w1, depth), (w1, d1), (width, d1), (width, 0)]
    else:
        rects = [np.array([0, 0, width, depth])]
        outline = [(0, 0), (0, depth), (width, depth), (width, 0)]
    points = [np.array(p, np.float64) for p in outline]
    walls = [_Wall(a, b) for a, b in zip(points, points[1:] + points[:1])]
    return rects, walls


def _wall_pieces(b: _Builder, wall: _Wall, height: float, material: int, name: str) -> None:
    """The wall as quads around its openings, facing into the room."""
    inward = np.array([wall.inward[0], 0.0, wall.inward[1]])
    pieces, u = [], 0.0
    for u0, u1, v0, v1, _ in sorted(wall.openings):
        pieces += [(u, u0, 0.0, height), (u0, u1, 0.0, v0), (u0, u1, v1, height)]
        u = u1
    pieces.append((u, wall.length, 0.0, height))
    for index, (u0, u1, v0, v1) in enumerate(pieces):
        if u1 - u0 > 1e-6 and v1 - v0 > 1e-6:
            corners = np.array([wall.point(u0, v0), wall.point(u1, v0), wall.point(u1, v1), wall.point(u0, v1)])
            b.quad(corners, inward, material, f"{name}.piece{index}")


def _reveal(
    b: _Builder,
    wall: _Wall,
    opening: tuple[float, float, float, float, str],
    thickness: float,
    material: int,
    name: str,
) -> None:
    """The four faces of the opening's depth through the wall, facing into the opening."""
    u0, u1, v0, v1, _ = opening
    along = np.array([wall.along[0], 0.0, wall.along[1]])
    corners = lambda ua, ub, va, vb: np.array(
        [
            wall.point(ua, va, 0.0),
            wall.point(ub, vb, 0.0),
            wall.point(ub, vb, -thickness),
            wall.point(ua, va, -thickness),
        ]
    )
    b.quad(corners(u0, u1, v0, v0), _UP, material, f"{name}.sill")
    b.quad(corners(u0, u1, v1, v1), -_UP, material, f"{name}.head")
    b.quad(
        np.array(
            [wall.point(u0, v0), wall.point(u0, v1), wall.point(u0, v1, -thickness), wall.point(u0, v0, -thickness)]
        ),
        along,
        material,
        f"{name}.left",
    )
    b.quad(
        np.array(
            [wall.point(u1, v0), wall.point(u1, v1), wall.point(u1, v1, -thickness), wall.point(u1, v0, -thickness)]
        ),
        -along,
        material,
        f"{name}.right",
    )


def _corridor(
    b: _Builder,
    wall: _Wall,
    opening: tuple[float, float, float, float, str],
    thickness: float,
    extent: tuple[float, float, float, float],
    paint: int,
    floor: int,
    name: str,
) -> None:
    """A closed corridor behind a door: u from ``extent[0]`` to ``extent[1]``, ``extent[2]`` deep and
    ``extent[3]`` high, every face looking into it."""
    u0, u1, _, v1, _ = opening
    a, c, length, height = extent
    near, far = -thickness, -thickness - length
    outward = np.array([-wall.inward[0], 0.0, -wall.inward[1]])
    along = np.array([wall.along[0], 0.0, wall.along[1]])
    box = lambda ua, ub, va, vb, w: np.array(
        [wall.point(ua, va, w), wall.point(ub, va, w), wall.point(ub, vb, w), wall.point(ua, vb, w)]
    )
    b.quad(box(a, c, 0.0, height, far), -outward, paint, f"{name}.far")
    for index, (ua, ub, va, vb) in enumerate([(a, u0, 0.0, height), (u1, c, 0.0, height), (u0, u1, v1, height)]):
        b.quad(box(ua, ub, va, vb, near), outward, paint, f"{name}.near{index}")
    flat = lambda y: np.array(
        [wall.point(a, y, near), wall.point(c, y, near), wall.point(c, y, far), wall.point(a, y, far)]
    )
    b.quad(flat(0.0), _UP, floor, f"{name}.floor")
    b.quad(flat(height), -_UP, paint, f"{name}.ceiling")
    for u, toward in ((a, along), (c, -along)):
        b.quad(
            np.array(
                [
                    wall.point(u, 0.0, near),
                    wall.point(u, 0.0, far),
                    wall.point(u, height, far),
                    wall.point(u, height, near),
                ]
            ),
            toward,
            paint,
            f"{name}.end",
        )


def _outdoors(
    b: _Builder, wall: _Wall, thickness: float, extent: tuple[float, float, float, float, float], name: str
) -> None:
    """A bright courtyard beyond a window, open to the sky: u from ``extent[0]`` to ``extent[1]``,
    ``extent[2]`` metres out, its ground ``extent[3]`` below the floor, its walls ``extent[4]`` high."""
    a, c, distance, drop, top = extent
    near, far = -thickness, -thickness - distance
    along = np.array([wall.along[0], 0.0, wall.along[1]])
    toward_room = np.array([wall.inward[0], 0.0, wall.inward[1]])
    ground, backdrop = b.material("ground"), b.material("backdrop")
    b.quad(
        np.array(
            [
                wall.point(a, -drop, near),
                wall.point(c, -drop, near),
                wall.point(c, -drop, far),
                wall.point(a, -drop, far),
            ]
        ),
        _UP,
        ground,
        f"{name}.ground",
    )
    b.framed_quad(
        np.array(
            [wall.point(a, -drop, far), wall.point(c, -drop, far), wall.point(c, top, far), wall.point(a, top, far)]
        ),
        toward_room,
        backdrop,
        f"{name}.backdrop",
    )
    for u, toward in ((a, along), (c, -along)):
        b.framed_quad(
            np.array(
                [
                    wall.point(u, -drop, near),
                    wall.point(u, -drop, far),
                    wall.point(u, top, far),
                    wall.point(u, top, near),
                ]
            ),
            toward,
            b.material("backdrop"),
            f"{name}.side",
        )


def _glazing_bars(
    b: _Builder, wall: _Wall, opening: tuple[float, float, float, float, str], thickness: float, name: str
) -> None:
    """Mullions and transoms across a glazed opening, about every 0.6-1.5 m, at the pane's plane."""
    rng = b.rng
    u0, u1, v0, v1, _ = opening
    bar, material = rng.uniform(0.03, 0.08), b.material(("plain", "wood")[int(rng.integers(2))])
    w0, w1 = -thickness / 2 - 0.03, -thickness / 2 + 0.03
    spacing = rng.uniform(0.6, 1.5, size=2)
    columns, rows = max(1, round((u1 - u0) / spacing[0])), int(rng.integers(0, 3))
    for index, u in enumerate(np.linspace(u0, u1, columns + 1)[1:-1]):
        b.box(wall.point(u - bar / 2, v0, w0), wall.point(u + bar / 2, v1, w1), material, f"{name}.mullion{index}")
    for index, v in enumerate(np.sort(rng.uniform(v0 + 0.3, v1 - 0.3, size=rows)) if v1 - v0 > 0.6 else []):
        b.box(wall.point(u0, v - bar / 2, w0), wall.point(u1, v + bar / 2, w1), material, f"{name}.transom{index}")


def _add_openings(
    b: _Builder,
    walls: list[_Wall],
    rects: list[np.ndarray],
    height: float,
    thickness: float,
    paint: int,
    floor: int,
    glass: int,
    glazing_share: float = 0.0,
) -> list[np.ndarray]:
    """Doors and windows cut into the walls, each with what lies behind it; returns the floor
    rectangles kept clear in front of the doors. A ``glazing_share`` of the windows are glazed
    walls: wide, from near the floor or sill to near the ceiling, divided by glazing bars."""
    rng = b.rng
    outside: list[np.ndarray] = list(rects)  # floor rectangles nothing outside may enter
    clear = []
    plans = ["door"] * int(rng.integers(0, 3)) + ["window"] * int(rng.integers(1, 4))
    for kind in plans:
        # nothing is drawn when the share is 0, so those rooms are the rooms drawn before it existed
        glazed = kind == "window" and glazing_share > 0 and rng.random() < glazing_share
        for _ in range(20):
            wall = walls[int(rng.integers(len(walls)))]
            if kind == "door":
                width, v0, v1 = rng.uniform(0.8, 1.6), 0.0, min(rng.uniform(2.0, 2.3), height - 0.15)
            elif glazed:
                v0 = rng.choice([rng.uniform(0.02, 0.1), rng.uniform(0.6, 1.0)])
                width, v1 = rng.uniform(0.3, 0.9) * wall.length, height - rng.uniform(0.15, 0.5)
            else:
                v0 = rng.uniform(0.5, 1.0)
                width, v1 = rng.uniform(0.7, 2.2), min(v0 + rng.uniform(0.9, 1.8), height - 0.2)
            if wall.length < width + 0.6:
                continue
            u0 = rng.uniform(0.3, wall.length - width - 0.3)
            u1 = u0 + width
            if any(u0 < o1 + 0.3 and o0 < u1 + 0.3 for o0, o1, *_ in wall.openings):
                continue
            if kind == "door":
                a, c = u0 - rng.uniform(0.2, 2.0), u1 + rng.uniform(0.2, 2.0)
                extent = (a, c, rng.uniform(1.2, 3.0), min(height, v1 + rng.uniform(0.3, 0.8)))
                beyond = wall.rect(a, c, -thickness - extent[2], -thickness)
            else:
                a, c = u0 - rng.uniform(0.5, 4.0), u1 + rng.uniform(0.5, 4.0)
                extent = (a, c, rng.uniform(5.0, 15.0), rng.uniform(0.0, 4.0), height + rng.uniform(1.0, 6.0))
                beyond = wall.rect(a, c, -thickness - extent[2], -thickness)
            if any(_rects_overlap(beyond, r, 0.05) for r in outside):
                continue
            outside.append(beyond)
            opening = (u0, u1, v0, v1, kind)
            wall.openings.append(opening)
            name = f"{kind}{len(outside) - len(rects)}"
            _reveal(b, wall, opening, thickness, paint, name)
            if kind == "door":
                _corridor(b, wall, opening, thickness, extent, paint, floor, name)
                clear.append(wall.rect(u0 - 0.1, u1 + 0.1, 0.0, 1.0))
            else:
                _window(b, wall, opening, thickness, extent, glass, glazed, name)
            break
    return clear


def _window(
    b: _Builder, wall: _Wall, opening: tuple, thickness: float, extent: tuple, glass: int, glazed: bool, name: str
) -> None:
    """A window in ``opening`` (u0, u1, v0, v1, kind): its pane, its glazing bars when ``glazed``,
    the outdoors it looks on, and a light just inside it."""
    u0, u1, v0, v1, _ = opening
    pane = np.array(
        [
            wall.point(u0, v0, -thickness / 2),
            wall.point(u1, v0, -thickness / 2),
            wall.point(u1, v1, -thickness / 2),
            wall.point(u0, v1, -thickness / 2),
        ]
    )
    b.quad(pane, np.array([wall.inward[0], 0.0, wall.inward[1]]), glass, f"{name}.glass")
    if glazed:
        _glazing_bars(b, wall, opening, thickness, name)
    _outdoors(b, wall, thickness, extent, name)
    b.lights.append(wall.point((u0 + u1) / 2, (v0 + v1) / 2, 0.4))


def _add_stairs(
    b: _Builder, walls: list[_Wall], rects: list[np.ndarray], height: float, occupied: list[np.ndarray]
) -> np.ndarray | None:
    """A straight flight along a wall up to an opening in the ceiling, with a stairwell above it:
    solid, floating (slabs from the wall) or open (slabs on a stringer) steps, often a railing.
    Returns the ceiling's opening (x0, z0, x1, z1), or None when no wall has room for the flight."""
    rng = b.rng
    steps = int(np.ceil(height / rng.uniform(0.16, 0.2)))
    rise, going, width = height / steps, rng.uniform(0.24, 0.32), rng.uniform(0.8, 1.4)
    run, style = steps * going, str(rng.choice(["solid", "floating", "open"]))
    tread, rail = (
        b.material(("wood", "floor", "plain")[int(rng.integers(3))]),
        b.material(("plain", "wood")[int(rng.integers(2))]),
    )
    slab = rng.uniform(0.04, 0.1)
    placed = _flight_place(rng, walls, rects, occupied, run, width)
    if placed is None:
        return None
    wall, start = placed
    up = bool(rng.random() < 0.5)  # climbing along the wall's direction, or against it
    span = lambda i: (
        (start + i * going, start + (i + 1) * going) if up else (start + run - (i + 1) * going, start + run - i * going)
    )
    for i in range(steps):
        u0, u1 = span(i)
        bottom = 0.0 if style == "solid" else (i + 1) * rise - slab
        lo, hi = wall.point(u0, bottom, 0.005), wall.point(u1, (i + 1) * rise, width)
        b.box(np.minimum(lo, hi), np.maximum(lo, hi), tread, f"stairs.step{i}")
    foot, head = (start, start + run) if up else (start + run, start)
    if style == "open":  # a stringer under the steps' open ends, from the floor to the ceiling
        beam = lambda u, y: [wall.point(u, y, width - 0.06), wall.point(u, y, width)]
        bottom = [*beam(foot, 0.0), *beam(head, height - 0.3)[::-1]]
        b.parts += hexahedron_parts(
            np.array(bottom + [p + [0, 0.3, 0] for p in bottom]), rail, "stairs.stringer", b.tile
        )
    if style != "solid" or rng.random() < 0.6:  # balusters on the open side and a sloped handrail
        post = rng.uniform(0.02, 0.05)
        for i in range(steps):
            u = sum(span(i)) / 2
            lo, hi = (
                wall.point(u - post / 2, (i + 1) * rise, width - 0.05 - post),
                wall.point(u + post / 2, (i + 1) * rise + 0.9, width - 0.05),
            )
            b.box(np.minimum(lo, hi), np.maximum(lo, hi), rail, f"stairs.baluster{i}")
        along = [wall.point(foot, rise + 0.9, width - 0.08), wall.point(foot, rise + 0.9, width - 0.02)]
        top = [wall.point(head, height + 0.9, width - 0.02), wall.point(head, height + 0.9, width - 0.08)]
        bottom = along + top
        b.parts += hexahedron_parts(
            np.array(bottom + [p + [0, 0.05, 0] for p in bottom]), rail, "stairs.handrail", b.tile
        )
    # headroom of 2 m over every step: the ceiling opens above the flight's upper part
    first = int(np.floor((height - 2.0) / rise))
    hole = wall.rect(*sorted((span(first)[0 if up else 1], head)), 0.0, width + 0.1)
    occupied.append(wall.rect(*sorted((foot - (1.0 if up else -1.0), head)), 0.0, width + 0.1))
    _stairwell(b, hole, height, rng.uniform(2.4, 3.0), b.material("wall"))
    return hole


def _flight_place(
    rng: np.random.Generator, walls: list[_Wall], rects: list[np.ndarray], occupied: list[np.ndarray], run: float,
    width: float,
) -> tuple[_Wall, float] | None:  # fmt: skip
    """A wall and a start along it for a flight ``run`` long and ``width`` wide: clear of the
    wall's openings, inside the room's floor ``rects`` and clear of what is ``occupied``; None
    after 20 draws that fit nowhere."""
    for _ in range(20):
        wall = walls[int(rng.integers(len(walls)))]
        if wall.length < run + 0.4:
            continue
        start = rng.uniform(0.2, wall.length - run - 0.2)
        if any(start < o1 + 0.1 and o0 < start + run + 0.1 for o0, o1, *_ in wall.openings):
            continue
        rect = wall.rect(start, start + run, 0.02, width + 0.05)
        if not any(_inside(rect, r, 0.01) for r in rects) or any(_rects_overlap(rect, o, _GAP) for o in occupied):
            continue
        return wall, start
    return None


def _stairwell(b: _Builder, hole: np.ndarray, height: float, rise: float, paint: int) -> None:
    """The closed shaft above the ceiling's opening ``hole`` (x0, z0, x1, z1): four walls and a
    ceiling ``rise`` metres up, facing into it."""
    x0, z0, x1, z1 = hole
    top = height + rise
    centre = np.array([(x0 + x1) / 2, height + rise / 2, (z0 + z1) / 2])
    for index, ((ax, az), (bx, bz)) in enumerate(pairwise([(x0, z0), (x1, z0), (x1, z1), (x0, z1), (x0, z0)])):
        corners = np.array([[ax, height, az], [bx, height, bz], [bx, top, bz], [ax, top, az]])
        b.quad(corners, centre - corners.mean(axis=0), paint, f"stairwell.wall{index}")
    b.quad(np.array([[x0, top, z0], [x1, top, z0], [x1, top, z1], [x0, top, z1]]), -_UP, paint, "stairwell.ceiling")


def _without(rect: np.ndarray, hole: np.ndarray | None) -> list[np.ndarray]:
    """The floor rectangle ``rect`` less the rectangle ``hole``, as up to four rectangles."""
    if hole is None or not _rects_overlap(rect, hole):
        return [rect]
    x0, z0, x1, z1 = rect
    h0, g0, h1, g1 = max(hole[0], x0), max(hole[1], z0), min(hole[2], x1), min(hole[3], z1)
    pieces = [(x0, z0, h0, z1), (h1, z0, x1, z1), (h0, z0, h1, g0), (h0, g1, h1, z1)]
    return [np.array(p) for p in pieces if p[2] - p[0] > 1e-6 and p[3] - p[1] > 1e-6]


# Furniture in a local frame: u along the wall it backs onto (or its own front), y up, w away from
# its back. Each returns boxes (lo, hi, role) in that frame and its footprint (width, depth).
def _table(rng: np.random.Generator) -> tuple[list, tuple[float, float]]:
    width, depth, top = rng.uniform(0.8, 1.8), rng.uniform(0.6, 1.0), rng.uniform(0.72, 0.78)
    slab, leg, inset = rng.uniform(0.03, 0.06), rng.uniform(0.04, 0.08), rng.uniform(0.03, 0.1)
    boxes = [((0, top - slab, 0), (width, top, depth), "wood")]
    for u in (inset, width - inset - leg):
        for w in (inset, depth - inset - leg):
            boxes.append(((u, 0, w), (u + leg, top - slab, w + leg), "wood"))
    for _ in range(int(rng.integers(0, 4))):  # books, a laptop, a box on the table
        size = rng.uniform([0.1, 0.02, 0.1], [0.4, 0.2, 0.35])
        u, w = rng.uniform(0, width - size[0]), rng.uniform(0, depth - size[2])
        boxes.append(((u, top, w), (u + size[0], top + size[1], w + size[2]), "plain"))
    return boxes, (width, depth)


def _chair(rng: np.random.Generator) -> tuple[list, tuple[float, float]]:
    size, seat, leg = rng.uniform(0.4, 0.5), rng.uniform(0.42, 0.47), rng.uniform(0.03, 0.045)
    back, role = rng.uniform(0.8, 1.0), ("wood", "fabric")[int(rng.integers(2))]
    boxes = [((0, seat - 0.04, 0), (size, seat, size), role), ((0, seat, 0), (size, back, 0.03), role)]
    for u in (0, size - leg):
        for w in (0, size - leg):
            boxes.append(((u, 0, w), (u + leg, seat - 0.04, w + leg), "wood"))
    return boxes, (size, size)


def _sofa(rng: np.random.Generator) -> tuple[list, tuple[float, float]]:
    width, depth = rng.uniform(1.5, 2.4), rng.uniform(0.8, 1.0)
    seat, back, arm, arm_w = (
        rng.uniform(0.38, 0.45),
        rng.uniform(0.75, 0.9),
        rng.uniform(0.55, 0.65),
        rng.uniform(0.12, 0.25),
    )
    boxes = [
        ((0, 0.06, 0), (width, seat, depth), "fabric"),
        ((0, seat, 0), (width, back, 0.2), "fabric"),
        ((0, seat, 0.2), (arm_w, arm, depth), "fabric"),
        ((width - arm_w, seat, 0.2), (width, arm, depth), "fabric"),
    ]
    cushions = int(rng.integers(2, 4))
    span = (width - 2 * arm_w) / cushions
    for index in range(cushions):  # a seam between cushions
        u = arm_w + index * span
        boxes.append(((u + 0.01, seat, 0.2), (u + span - 0.01, seat + 0.1, depth - 0.02), "fabric"))
    for u in (0.05, width - 0.1):
        boxes.append(((u, 0, 0.05), (u + 0.05, 0.06, 0.1), "wood"))
    return boxes, (width, depth)


def _shelf(rng: np.random.Generator) -> tuple[list, tuple[float, float]]:
    width, depth, height = rng.uniform(0.6, 1.6), rng.uniform(0.28, 0.45), rng.uniform(1.0, 2.2)
    board = rng.uniform(0.02, 0.035)
    boxes = [
        ((0, 0, 0), (board, height, depth), "wood"),
        ((width - board, 0, 0), (width, height, depth), "wood"),
        ((0, 0, 0), (width, height, 0.015), "wood"),
    ]
    levels = np.linspace(0, height - board, int(rng.integers(3, 7)))
    for y in levels:
        boxes.append(((board, y, 0.015), (width - board, y + board, depth), "wood"))
    for y, next_y in pairwise(levels):
        u, gap = board + rng.uniform(0, 0.1), next_y - y - board
        while u < width - board - 0.05:  # a run of books and the odd box, with spaces between
            if rng.random() < 0.2:
                u += rng.uniform(0.05, 0.25)
                continue
            thick = rng.uniform(0.02, 0.06) if rng.random() < 0.8 else rng.uniform(0.1, 0.25)
            tall = gap * rng.uniform(0.55, 0.9)
            end = min(u + thick, width - board - 0.005)
            boxes.append(((u, y + board, 0.03), (end, y + board + tall, depth * rng.uniform(0.6, 0.95)), "plain"))
            u = end + 0.002
    return boxes, (width, depth)


def _cabinet(rng: np.random.Generator) -> tuple[list, tuple[float, float]]:
    width, depth = rng.uniform(0.5, 1.6), rng.uniform(0.4, 0.6)
    height = rng.uniform(0.7, 1.0) if rng.random() < 0.6 else rng.uniform(1.7, 2.1)
    role = ("wood", "plain")[int(rng.integers(2))]
    boxes = [
        ((0, 0.05, 0), (width, height, depth), role),
        ((0.03, 0, 0.03), (width - 0.03, 0.05, depth - 0.03), "plain"),
    ]
    doors = max(1, round(width / 0.5))
    span = width / doors
    for index in range(doors):  # door fronts a little proud, with seams, and a handle each
        u = index * span
        boxes.append(((u + 0.005, 0.06, depth), (u + span - 0.005, height - 0.01, depth + 0.015), role))
        handle_u = u + (span - 0.05 if index % 2 == 0 else 0.03)
        boxes.append(
            ((handle_u, height * 0.5, depth + 0.015), (handle_u + 0.02, height * 0.5 + 0.12, depth + 0.035), "plain")
        )
    return boxes, (width, depth)


_AGAINST_WALL = {"sofa": _sofa, "shelf": _shelf, "cabinet": _cabinet}
_FREE = {"table": _table, "chair": _chair}


def _place(b: _Builder, boxes: list, wall: _Wall, u: float, w: float, materials: dict[str, int], name: str) -> None:
    for index, (lo, hi, role) in enumerate(boxes):
        corners = np.array([wall.point(u + lo[0], lo[1], w + lo[2]), wall.point(u + hi[0], hi[1], w + hi[2])])
        material = b.material("plain") if role == "plain" else materials[role]
        b.box(corners.min(axis=0), corners.max(axis=0), material, f"{name}.part{index}")


def _add_furniture(
    b: _Builder, walls: list[_Wall], rects: list[np.ndarray], height: float, occupied: list[np.ndarray]
) -> None:
    rng = b.rng
    materials = {"wood": b.material("wood"), "fabric": b.material("fabric")}
    area = sum((r[2] - r[0]) * (r[3] - r[1]) for r in rects)
    for index in range(int(rng.integers(3, 5 + int(area / 6)))):
        kind = str(rng.choice(list(_AGAINST_WALL) + list(_FREE), p=[0.15, 0.25, 0.2, 0.2, 0.2]))
        if rng.random() < 0.3:  # pieces vary in material within a room, most share
            materials = {"wood": b.material("wood"), "fabric": b.material("fabric")}
        for _ in range(30):
            boxes, (width, depth) = (_AGAINST_WALL | _FREE)[kind](rng)
            wall = walls[int(rng.integers(len(walls)))]
            if wall.length < width + 0.2:
                continue
            u = rng.uniform(0.05, wall.length - width - 0.05)
            if kind in _AGAINST_WALL:
                w = 0.02
                top = max(hi[1] for _, hi, _ in boxes)
                if any(
                    u < o1 and o0 < u + width and (what == "door" or v0 < top) for o0, o1, v0, _, what in wall.openings
                ):
                    continue
            else:
                w = rng.uniform(0.3, 3.0)
            rect = wall.rect(u, u + width, w, w + depth)
            if not any(_inside(rect, r, 0.01) for r in rects) or any(_rects_overlap(rect, o, _GAP) for o in occupied):
                continue
            occupied.append(rect)
            _place(b, boxes, wall, u, w, materials, f"{kind}{index}")
            break


def _add_decor(b: _Builder, walls: list[_Wall], rects: list[np.ndarray], height: float, eye: np.ndarray) -> None:
    """Pictures on the walls, rugs on the floor, lamps hanging from the ceiling."""
    _add_pictures(b, walls, height)
    _add_rugs(b, rects)
    _add_lamps(b, rects, height, eye)


def _add_pictures(b: _Builder, walls: list[_Wall], height: float) -> None:
    """One to four framed pictures on the walls, clear of their openings."""
    rng = b.rng
    for index in range(int(rng.integers(1, 5))):
        wall = walls[int(rng.integers(len(walls)))]
        size = rng.uniform([0.3, 0.3], [1.2, 0.9])
        if wall.length < size[0] + 0.4:
            continue
        u, bottom = rng.uniform(0.2, wall.length - size[0] - 0.2), rng.uniform(1.1, 1.9) - size[1] / 2
        if bottom + size[1] > height - 0.1 or any(
            u < o1 + 0.1 and o0 < u + size[0] + 0.1 for o0, o1, *_ in wall.openings
        ):
            continue
        frame = b.material(("wood", "plain")[int(rng.integers(2))])
        lo, hi = wall.point(u, bottom, 0.0), wall.point(u + size[0], bottom + size[1], 0.03)
        b.box(lo, hi, frame, f"picture{index}.frame")
        border = min(0.06, size.min() / 6)
        inward = np.array([wall.inward[0], 0.0, wall.inward[1]])
        canvas = np.array(
            [
                wall.point(u + border, bottom + border, 0.031),
                wall.point(u + size[0] - border, bottom + border, 0.031),
                wall.point(u + size[0] - border, bottom + size[1] - border, 0.031),
                wall.point(u + border, bottom + size[1] - border, 0.031),
            ]
        )
        b.framed_quad(canvas, inward, b.material("picture"), f"picture{index}.canvas")


def _add_rugs(b: _Builder, rects: list[np.ndarray]) -> None:
    """Up to two rugs on the floor's rectangles."""
    rng = b.rng
    for index in range(int(rng.integers(0, 3))):
        rect = rects[int(rng.integers(len(rects)))]
        size = rng.uniform(1.0, 3.0, size=2)
        if np.any(size > rect[2:] - rect[:2] - 0.4):
            continue
        x0, z0 = rng.uniform(rect[:2] + 0.2, rect[2:] - size - 0.2)
        b.box(
            np.array([x0, 0.0, z0]), np.array([x0 + size[0], 0.012, z0 + size[1]]), b.material("fabric"), f"rug{index}"
        )


def _add_lamps(b: _Builder, rects: list[np.ndarray], height: float, eye: np.ndarray) -> None:
    """One to three lamps hanging from the ceiling (cord, shade, an emissive bulb), none within
    1.5 m of the ``eye``."""
    rng = b.rng
    bulb = b.special(Material("bulb", base_color=np.ones(3), emissive=True))
    for index in range(int(rng.integers(1, 4))):
        rect = rects[int(rng.integers(len(rects)))]
        x, z = rng.uniform(rect[:2] + 0.5, rect[2:] - 0.5)
        drop = rng.uniform(0.2, min(0.8, height - 2.1))
        if np.hypot(x - eye[0], z - eye[2]) < 1.5:
            continue
        shade, tall = rng.uniform(0.2, 0.5), rng.uniform(0.1, 0.3)
        b.box(
            np.array([x - 0.006, height - drop, z - 0.006]),
            np.array([x + 0.006, height, z + 0.006]),
            b.material("plain"),
            f"lamp{index}.cord",
        )
        b.box(
            np.array([x - shade / 2, height - drop - tall, z - shade / 2]),
            np.array([x + shade / 2, height - drop, z + shade / 2]),
            b.material("wall"),
            f"lamp{index}.shade",
        )
        y = height - drop - tall - 0.01
        corners = np.array(
            [
                [x - shade / 4, y, z - shade / 4],
                [x + shade / 4, y, z - shade / 4],
                [x + shade / 4, y, z + shade / 4],
                [x - shade / 4, y, z + shade / 4],
            ]
        )
        b.quad(corners, -_UP, bulb, f"lamp{index}.bulb")


def _free_spans(wall: _Wall, y0: float, y1: float) -> list[tuple[float, float]]:
    """The stretches (u0, u1) of ``wall`` that no opening interrupts between heights ``y0`` and ``y1``."""
    spans, u = [], 0.0
    for o0, o1, v0, v1, _ in sorted(wall.openings):
        if v0 < y1 and v1 > y0:
            spans.append((u, o0))
            u = o1
    spans.append((u, wall.length))
    return [(a, c) for a, c in spans if c - a > 0.05]


def _add_trims(b: _Builder, walls: list[_Wall], height: float, thickness: float) -> None:
    """Skirting boards, a cornice, often a dado rail, frames round the doors and windows and sills
    under the windows: the mouldings that edge most real rooms."""
    rng = b.rng
    trim = b.material("wood" if rng.random() < 0.3 else "wall")  # painted like the walls, or wood
    depth, frame = rng.uniform(0.012, 0.03), rng.uniform(0.05, 0.12)
    bands = [(0.0, rng.uniform(0.06, 0.2), "skirting"), (height - rng.uniform(0.04, 0.15), height, "cornice")]
    if rng.random() < 0.3:
        rail = rng.uniform(0.8, 1.1)
        bands.append((rail, rail + rng.uniform(0.03, 0.07), "dado"))
    for index, wall in enumerate(walls):
        for y0, y1, what in bands:
            for piece, (u0, u1) in enumerate(_free_spans(wall, y0, y1)):
                b.box(wall.point(u0, y0, 0.0), wall.point(u1, y1, depth), trim, f"wall{index}.{what}{piece}")
        for number, (u0, u1, v0, v1, kind) in enumerate(wall.openings):
            top = min(v1 + frame, height - 0.01)
            name = f"wall{index}.{kind}{number}"
            for u in (max(0.0, u0 - frame), min(wall.length, u1 + frame) - frame):
                b.box(wall.point(u, v0, 0.0), wall.point(u + frame, top, depth), trim, f"{name}.jamb")
            b.box(wall.point(u0, v1, 0.0), wall.point(u1, top, depth), trim, f"{name}.head")
            if kind == "window" and v0 > 0.2:
                b.box(
                    wall.point(u0 - 0.05, v0 - 0.04, -thickness), wall.point(u1 + 0.05, v0, 0.06), trim, f"{name}.sill"
                )


def _cylinder(b: _Builder, bottom: np.ndarray, top: float, radius: float, material: int, name: str) -> None:
    """A closed upright cylinder from ``bottom`` (3,) up to the height ``top``."""
    mesh = trimesh.creation.cylinder(radius=radius, segment=[bottom, [bottom[0], top, bottom[2]]], sections=20)
    b.parts.append(mesh_part(mesh.vertices, mesh.faces, material, name, b.tile))


def _sphere(b: _Builder, centre: np.ndarray, radius: float, material: int, name: str) -> None:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    b.parts.append(mesh_part(mesh.vertices + centre, mesh.faces, material, name, b.tile))


def _add_round_things(
    b: _Builder, rects: list[np.ndarray], height: float, occupied: list[np.ndarray], eye: np.ndarray
) -> None:
    """Round tables, floor lamps, potted plants and pendant globes: furniture that is not a box."""
    rng = b.rng
    area = sum((r[2] - r[0]) * (r[3] - r[1]) for r in rects)
    for index in range(int(rng.integers(1, 3 + int(area / 10)))):
        kind = str(rng.choice(["table", "lamp", "plant", "globe"]))
        reach = {"table": rng.uniform(0.35, 0.7), "lamp": 0.2, "plant": rng.uniform(0.25, 0.45), "globe": 0.3}[kind]
        for _ in range(20):
            rect = rects[int(rng.integers(len(rects)))]
            if np.any(rect[2:] - rect[:2] < 2 * reach + 0.2):
                continue
            x, z = rng.uniform(rect[:2] + reach + 0.05, rect[2:] - reach - 0.05)
            spot = np.array([x - reach, z - reach, x + reach, z + reach])
            # a globe hangs from the ceiling, clear of the file camera; the rest stand on free floor
            if (
                (np.hypot(x - eye[0], z - eye[2]) < 1.5)
                if kind == "globe"
                else any(_rects_overlap(spot, o, _GAP) for o in occupied)
            ):
                continue
            break
        else:
            continue
        name = f"{kind}{index}"
        if kind == "globe":
            radius, drop = rng.uniform(0.12, 0.3), rng.uniform(0.3, max(0.35, height - 2.3))
            _cylinder(b, np.array([x, height - drop, z]), height, 0.005, b.material("plain"), f"{name}.cord")
            _sphere(b, np.array([x, height - drop - radius, z]), radius, b.material("wall"), f"{name}.shade")
            continue
        occupied.append(spot)
        if kind == "table":
            top, slab = rng.uniform(0.72, 0.76), rng.uniform(0.03, 0.05)
            wood = b.material("wood")
            _cylinder(b, np.array([x, top - slab, z]), top, reach, wood, f"{name}.top")
            _cylinder(b, np.array([x, 0.03, z]), top - slab, rng.uniform(0.03, 0.07), wood, f"{name}.pedestal")
            _cylinder(b, np.array([x, 0.0, z]), 0.03, rng.uniform(0.2, 0.3), wood, f"{name}.base")
        elif kind == "lamp":
            pole, shade = rng.uniform(1.3, 1.7), rng.uniform(0.2, 0.35)
            metal = b.material("plain")
            _cylinder(b, np.array([x, 0.0, z]), 0.03, rng.uniform(0.12, 0.18), metal, f"{name}.base")
            _cylinder(b, np.array([x, 0.03, z]), pole, rng.uniform(0.01, 0.02), metal, f"{name}.pole")
            _cylinder(
                b, np.array([x, pole, z]), pole + shade, rng.uniform(0.13, 0.2), b.material("wall"), f"{name}.shade"
            )
        else:
            pot = rng.uniform(0.2, 0.5)
            _cylinder(b, np.array([x, 0.0, z]), pot, reach * rng.uniform(0.4, 0.6), b.material("plain"), f"{name}.pot")
            leaves = b.material("foliage")
            for leaf in range(int(rng.integers(1, 4))):
                radius = reach * rng.uniform(0.5, 0.9)
                offset = rng.uniform(-0.3, 0.3, size=2) * reach
                centre = np.array([x + offset[0], pot + radius * rng.uniform(0.6, 1.2), z + offset[1]])
                _sphere(b, centre, radius, leaves, f"{name}.leaves{leaf}")


def _floors_and_ceilings(
    b: _Builder, rects: list[np.ndarray], height: float, floor: int, ceiling: int, hole: np.ndarray | None
) -> list[MeshPart]:
    """The floor and ceiling quads of each floor rectangle, the ceiling open over ``hole``."""
    parts = []
    for index, rect in enumerate(rects):
        x0, z0, x1, z1 = rect
        parts.append(
            planar_quad(
                facing(np.array([[x0, 0, z0], [x1, 0, z0], [x1, 0, z1], [x0, 0, z1]]), _UP),
                floor,
                f"floor{index}",
                b.tile,
            )
        )
        for piece, (x0, z0, x1, z1) in enumerate(_without(rect, hole)):
            corners = np.array([[x0, height, z0], [x1, height, z0], [x1, height, z1], [x0, height, z1]])
            name = f"ceiling{index}" if hole is None else f"ceiling{index}.piece{piece}"
            parts.append(planar_quad(facing(corners, -_UP), ceiling, name, b.tile))
    return parts


def _daylight(rng: np.random.Generator, walls: list[_Wall], sun_share: float) -> Emitters:
    """The sky the windows show (the lamps' bulbs are area emitters of the default radiance) and,
    for a ``sun_share`` of the rooms with windows, a sun shining in through one of them; with the
    share > 0 the sky's radiance varies too (0.5-3 times the default)."""
    sky = np.full(3, MISSING_ENVMAP_RADIANCE)
    if sun_share == 0:  # nothing is drawn, so those rooms are the rooms drawn before suns existed
        return Emitters(sky_radiance=sky)
    sky = sky * np.exp(rng.uniform(np.log(0.5), np.log(3.0)))
    windows = [wall for wall in walls for *_, kind in wall.openings if kind == "window"]
    if not windows or rng.random() >= sun_share:
        return Emitters(sky_radiance=sky)
    wall = windows[int(rng.integers(len(windows)))]
    elevation, azimuth = np.radians(rng.uniform(20, 60)), np.radians(rng.uniform(-50, 50))
    out = -wall.inward  # towards the sun, seen from the room: out through the window and up
    out = np.array(
        [out[0] * np.cos(azimuth) - out[1] * np.sin(azimuth), out[0] * np.sin(azimuth) + out[1] * np.cos(azimuth)]
    )
    direction = np.array([out[0] * np.cos(elevation), np.sin(elevation), out[1] * np.cos(elevation)])
    # a clear day's sun gives a few to ten times the irradiance of the sky (pi x its radiance)
    tint = np.array([1.0, rng.uniform(0.9, 1.0), rng.uniform(0.75, 0.95)])
    irradiance = np.pi * sky * rng.uniform(3.0, 10.0) * tint
    return Emitters(sky_radiance=sky, sun_directions=direction[None], sun_irradiance=irradiance[None])


def check_shares(corridor_share: float, hall_share: float, prefix: str = "", **shares: float) -> None:
    """Raise ValueError, naming ``prefix`` + the key, unless both shares lie in [0, 1] and sum to at
    most 1, and each of the other ``shares`` (by name) lies in [0, 1]."""
    if not (0.0 <= corridor_share <= 1.0 and 0.0 <= hall_share <= 1.0 and corridor_share + hall_share <= 1.0):
        raise ValueError(
            f"{prefix}corridor_share ({corridor_share}) and {prefix}hall_share ({hall_share}) "
            "must lie in [0, 1] and sum to at most 1"
        )
    for name, share in shares.items():
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"{prefix}{name} must be in [0, 1], got {share}")


def procedural_room(
    seed: int = 0,
    tile: float = 1.0,
    fov_x_deg: float = 70.0,
    drop_transparent: bool = True,
    corridor_share: float = CORRIDOR_SHARE,
    hall_share: float = HALL_SHARE,
    stairs_share: float = 0.0,
    sun_share: float = 0.0,
    glazing_share: float = 0.0,
    trim_share: float = 0.0,
    round_share: float = 0.0,
) -> Scene:
    """A furnished room, the same for the same seed, bit for bit.

    The floor is at y = 0 and the room spans x >= 0, z >= 0: a corridor 2-3.2 m wide and 10-30 m
    long (``corridor_share`` of the seeds), a hall of 8-16 m sides (``hall_share``), else a
    rectangle of 3.5-8 m sides or an L cut from one; 2.4-3.4 m high; the room's box is the scene's
    ``interior``, where camera samplers look (the courtyards outside the windows are not for
    cameras). The file camera stands near the corner (0, 0), 1.3-1.7 m high, looking across the
    room, with at least 1 m of free space around it.

    Args:
        seed: the random seed.
        tile: metres per texture repeat on walls, floors and furniture.
        fov_x_deg: the file camera's horizontal field of view.
        drop_transparent: leave out the windows' glass (as loaded scenes do by default).
        corridor_share, hall_share: the chances of a corridor and of a hall; with both 0 the rooms
            are those of kadv's generator before it drew halls and corridors.
        stairs_share: the chance of a straight flight of stairs along a wall, up to an opening in
            the ceiling (solid, floating or open steps, often a railing).
        sun_share: the chance of a sun shining in through a window (seen by ``render.lighting=baked``;
            with the share > 0 the sky's radiance also varies from room to room).
        glazing_share: the chance of each window being a glazed wall (wide, near floor or sill to
            near the ceiling, divided by glazing bars).
        trim_share: the chance of mouldings: skirting boards, a cornice, often a dado rail, frames
            round the doors and windows, window sills.
        round_share: the chance of round things: round tables, floor lamps, potted plants and
            pendant globes.
        With the last five 0 (the default) the rooms are those drawn before they existed, bit for bit.

    Raises:
        ValueError: a share outside [0, 1], or corridor and hall shares summing over 1.
    """
    features = {
        "stairs_share": stairs_share,
        "sun_share": sun_share,
        "glazing_share": glazing_share,
        "trim_share": trim_share,
        "round_share": round_share,
    }
    check_shares(corridor_share, hall_share, **features)
    rng = np.random.default_rng(seed)
    b = _Builder(rng, tile)
    rects, walls = _footprint(rng, corridor_share, hall_share)
    height, thickness = rng.uniform(2.4, 3.4), rng.uniform(0.1, 0.3)
    floor = b.material(("wood", "floor", "fabric")[int(rng.choice(3, p=[0.5, 0.3, 0.2]))])
    ceiling, paints = b.material("wall"), [b.material("wall"), b.material("wall")]
    glass = b.special(Material("glass", transparent=True))
    clear = _add_openings(b, walls, rects, height, thickness, paints[0], floor, glass, glazing_share)
    for index, wall in enumerate(walls):  # most walls share one paint, an accent wall may differ
        _wall_pieces(b, wall, height, paints[int(rng.random() < 0.2)], f"wall{index}")
    floors_at = len(b.parts)  # floors and ceilings go here, so rooms without stairs keep their parts' order
    first = rects[0]
    eye = np.array([min(1.0, (first[2] - first[0]) / 4), rng.uniform(1.3, 1.7), min(1.0, (first[3] - first[1]) / 4)])
    occupied = [*clear, np.array([eye[0], eye[2], eye[0], eye[2]]) + _EYE_CLEARANCE * np.array([-1, -1, 1, 1])]
    # nothing is drawn when a share is 0, so those rooms are the rooms drawn before it existed
    hole = _add_stairs(b, walls, rects, height, occupied) if stairs_share > 0 and rng.random() < stairs_share else None
    b.parts[floors_at:floors_at] = _floors_and_ceilings(b, rects, height, floor, ceiling, hole)
    _add_furniture(b, walls, rects, height, occupied)
    _add_decor(b, walls, rects, height, eye)
    if trim_share > 0 and rng.random() < trim_share:
        _add_trims(b, walls, height, thickness)
    if round_share > 0 and rng.random() < round_share:
        _add_round_things(b, rects, height, occupied, eye)
    emitters = _daylight(rng, walls, sun_share)
    centre = np.mean([(r[:2] + r[2:]) / 2 for r in rects], axis=0)
    target = np.array([centre[0], 1.0, centre[1]])
    camera = Camera(
        look_at(torch.tensor(eye), torch.tensor(target)).double(), fov_x_deg, 640, 480, name="procedural_room_camera"
    )
    corners = np.array(rects)
    interior = np.array(
        [[corners[:, 0].min(), 0.0, corners[:, 1].min()], [corners[:, 2].max(), height, corners[:, 3].max()]]
    )
    return assemble_scene(
        b.parts,
        b.materials,
        [camera],
        np.array(b.lights).reshape(-1, 3),
        name=f"procedural_room_{seed}",
        drop_transparent=drop_transparent,
        interior=interior,
        emitters=emitters,
    )
