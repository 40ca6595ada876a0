"""Probe scenes: small generated rooms, each aimed at one known failure of monocular depth models.

Every probe is a seeded :class:`Scene` whose cameras are its init views: views the model should get
right, from which an attack searches nearby for the failure the probe provokes. The seed varies
textures, sizes and placements within the probe's design, never the design itself.

Rooms span x in [0, W], y in [0, H] (y up, floor at 0) and z in [0, D], walls facing in, as
:func:`kadv.scenes.box_room`'s do. All are closed, bar the window probe, which opens on a courtyard
under the sky.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import numpy as np
import torch

from kadv.geometry.camera import Camera, intrinsics_from_fov
from kadv.geometry.pose import look_at
from kadv.render.exact import ExactRenderer
from kadv.scenes.emitters import Emitters
from kadv.scenes.materials import textured_materials
from kadv.scenes.parts import box_parts, facing, planar_quad, quad_part, room_shell_parts
from kadv.scenes.procedural import procedural_room
from kadv.scenes.scene import Material, MeshPart, Scene, assemble_scene

__all__ = [
    "PROBES",
    "dim_lamp",
    "grazing_floor",
    "mirror",
    "photo_wall",
    "probe_names",
    "probe_scene",
    "stairs",
    "textureless_close",
    "thin_structures",
    "window",
]

_TILE = 1.0  # metres per texture repeat
_FOV = 70.0
_SUNK = 0.05  # metres below the floor that furniture starts


class _Room:
    """A room under construction: its shell, then parts and materials added by the probe."""

    def __init__(self, rng: np.random.Generator, size: tuple[float, float, float]) -> None:
        self.rng, self.size = rng, size
        floor, ceiling = textured_materials(rng, "floor", 1) + textured_materials(rng, "paint", 1)
        walls = textured_materials(rng, "wall", 1)
        self.materials: list[Material] = [floor, ceiling, *walls]
        self.parts: list[MeshPart] = room_shell_parts(size, [0, 1, 2, 2, 2, 2], _TILE)
        self.cameras: list[Camera] = []

    def material(self, material: Material) -> int:
        self.materials.append(material)
        return len(self.materials) - 1

    def role(self, role: str) -> int:
        return self.material(textured_materials(self.rng, role, 1)[0])

    def box(self, lo, hi, material: int, name: str) -> None:
        """An axis-aligned box; one standing on the floor is sunk into it: a face that merely
        touches the floor leaves a seam whose baked light leaks from under it."""
        lo = np.asarray(lo, np.float64).copy()
        if lo[1] <= 0.0:
            lo[1] = -_SUNK
        self.parts += box_parts(lo, np.asarray(hi, np.float64), material, name, _TILE)

    def camera(self, eye, target) -> None:
        pose = look_at(torch.tensor(eye, dtype=torch.float64), torch.tensor(target, dtype=torch.float64)).double()
        self.cameras.append(Camera(pose, _FOV, 640, 480, name=f"init{len(self.cameras)}"))

    def scene(self, name: str, seed: int, lights=None, emitters: Emitters | None = None) -> Scene:
        return assemble_scene(
            self.parts, self.materials, self.cameras, lights, name=f"probe_{name}_{seed}", emitters=emitters
        )


@cache
def _room_photograph(seed: int) -> np.ndarray:
    """(H, W, 3) an image of a furnished room: a generated room rendered from its own camera."""
    room = procedural_room(seed=seed)
    camera = room.cameras[0]

    out = ExactRenderer(room).render(camera.world_T_cam, intrinsics_from_fov(camera.fov_x_deg, 192, 256), 192, 256, 2)
    return out.rgb[0].permute(1, 2, 0).numpy()


def photo_wall(seed: int = 0) -> Scene:
    """A flat wall carrying a large photograph of a furnished room.

    Failure: texture read as depth. The photograph's perspective (its floor, walls and furniture
    receding) is painted on one plane; a model that reads depth from pictorial cues puts a room
    behind the wall. Close to the wall, where the photograph fills most of the frame, that is all
    the image shows.
    """
    rng = np.random.default_rng([seed, 1])
    W, H, D = rng.uniform(4.5, 5.5), rng.uniform(2.6, 3.0), rng.uniform(5.5, 6.5)
    room = _Room(rng, (W, H, D))
    # a quad's u runs from corner 0 to corner 1, to the viewer's left on a wall facing -z: the
    # photograph is mirrored to read the right way round
    image = np.ascontiguousarray(_room_photograph(seed)[:, ::-1])
    photo = room.material(Material("photograph", base_color=np.ones(3), texture=image))
    x0, x1, y0, y1, z = 0.35, W - 0.35, 0.25, H - 0.2, D - 0.01
    room.parts.append(quad_part(np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]), photo, "photograph"))
    room.camera([W / 2, 1.5, 1.0], [W / 2, 1.2, D])
    room.camera([0.9, 1.4, 1.6], [W * 0.7, 1.2, D])
    return room.scene("photo_wall", seed)


def grazing_floor(seed: int = 0) -> Scene:
    """A long, narrow room whose textured floor and walls are seen at grazing angles.

    Failure: depth along a plane seen edge-on. The texture's gradient of scale is the only cue to
    how far the floor runs, and it compresses towards the far end; tilting down or turning towards
    a side wall leaves one long receding plane across the frame.
    """
    rng = np.random.default_rng([seed, 2])
    W, H, D = rng.uniform(2.6, 3.2), rng.uniform(2.5, 2.8), rng.uniform(12.0, 15.0)
    room = _Room(rng, (W, H, D))
    end = room.role("furniture")
    room.box([W / 2 - 0.5, 0.0, D - 0.6], [W / 2 + 0.5, 0.9, D - 0.1], end, "end_cabinet")
    room.camera([W / 2, 1.5, 1.0], [W / 2, 1.0, D])
    room.camera([W * 0.7, 1.4, 1.5], [W * 0.3, 1.1, D * 0.6])
    return room.scene("grazing_floor", seed)


def _table(room: _Room, x: float, z: float, material: int, name: str) -> None:
    """A table top on four legs of 4 cm. Parts that meet overlap by a centimetre: faces that merely
    touch are coplanar, and a ray may meet either."""
    width, depth, height, leg = 1.2, 0.7, 0.74, 0.04
    room.box([x, height - 0.03, z], [x + width, height, z + depth], material, f"{name}.top")
    for i, (lx, lz) in enumerate(
        [(x, z), (x + width - leg, z), (x, z + depth - leg), (x + width - leg, z + depth - leg)]
    ):
        room.box([lx, 0.0, lz], [lx + leg, height - 0.01, lz + leg], material, f"{name}.leg{i}")


def _chair(room: _Room, x: float, z: float, back_z: float, material: int, name: str) -> None:
    """A seat on four legs of 3 cm, and a back of two posts and a rail on the ``back_z`` side."""
    size, seat, leg = 0.42, 0.45, 0.03
    room.box([x, seat - 0.03, z], [x + size, seat, z + size], material, f"{name}.seat")
    for i, (lx, lz) in enumerate([(x, z), (x + size - leg, z), (x, z + size - leg), (x + size - leg, z + size - leg)]):
        room.box([lx, 0.0, lz], [lx + leg, seat - 0.01, lz + leg], material, f"{name}.leg{i}")
    bz = z if back_z < z + size / 2 else z + size - leg
    for i, lx in enumerate([x, x + size - leg]):
        room.box([lx, seat - 0.01, bz], [lx + leg, seat + 0.45, bz + leg], material, f"{name}.post{i}")
    room.box([x, seat + 0.35, bz], [x + size, seat + 0.45, bz + leg], material, f"{name}.rail")


def thin_structures(seed: int = 0) -> Scene:
    """A banister of thin balusters, and a table and chairs on thin legs, in front of a wall.

    Failure: thin structures. Balusters and legs a few centimetres wide cover a few pixels each;
    a model that smooths its prediction paints them with the wall behind, or the wall with them.
    """
    rng = np.random.default_rng([seed, 3])
    W, H, D = rng.uniform(5.5, 6.5), rng.uniform(2.6, 3.0), rng.uniform(5.5, 6.5)
    room = _Room(rng, (W, H, D))
    wood, furniture = room.role("wood"), room.role("wood")
    z = D - rng.uniform(1.2, 1.6)  # the banister runs along x, in front of the far wall
    x0, x1, rail = 0.8, W - 0.8, 0.9
    room.box([x0, rail, z - 0.03], [x1, rail + 0.05, z + 0.03], wood, "banister.rail")
    room.box([x0, 0.0, z - 0.05], [x0 + 0.1, rail + 0.15, z + 0.05], wood, "banister.newel0")
    room.box([x1 - 0.1, 0.0, z - 0.05], [x1, rail + 0.15, z + 0.05], wood, "banister.newel1")
    spacing = rng.uniform(0.11, 0.15)
    for i, x in enumerate(np.arange(x0 + 0.1 + spacing, x1 - 0.1, spacing)):
        room.box([x - 0.015, 0.0, z - 0.015], [x + 0.015, rail + 0.02, z + 0.015], wood, f"banister.baluster{i}")
    table_x, table_z = rng.uniform(1.0, W - 2.4), z - 1.9
    _table(room, table_x, table_z, furniture, "table")
    _chair(room, table_x + 0.1, table_z - 0.55, table_z - 0.55, furniture, "chair0")
    _chair(room, table_x + 0.68, table_z + 0.85, table_z + 1.27, furniture, "chair1")
    room.camera([W / 2, 1.5, 0.9], [W / 2, 0.7, z])
    room.camera([W - 1.0, 1.3, 1.2], [table_x + 0.6, 0.6, table_z + 0.3])
    return room.scene("thin_structures", seed)


def _opening_wall(room: _Room, z: float, thickness: float, hole: tuple[float, float, float, float]) -> None:
    """The wall at ``z`` (its room side) with a rectangular opening (x0, x1, y0, y1) through it: the
    room side facing -z, the outer side facing +z at ``z + thickness``, and the opening's lining."""
    W, H, _ = room.size
    x0, x1, y0, y1 = hole
    paint = 2  # the room's wall material
    for side, toward in ((z, -1.0), (z + thickness, 1.0)):
        for i, (a0, a1, b0, b1) in enumerate([(0.0, x0, 0.0, H), (x1, W, 0.0, H), (x0, x1, 0.0, y0), (x0, x1, y1, H)]):
            corners = facing([[a0, b0, side], [a1, b0, side], [a1, b1, side], [a0, b1, side]], [0.0, 0.0, toward])
            room.parts.append(planar_quad(corners, paint, f"wall_opening{i}", _TILE))
    near, far = z, z + thickness
    lining = {  # each quad, and the way it faces: into the opening
        "sill": ([[x0, y0, near], [x1, y0, near], [x1, y0, far], [x0, y0, far]], [0.0, 1.0, 0.0]),
        "head": ([[x0, y1, near], [x1, y1, near], [x1, y1, far], [x0, y1, far]], [0.0, -1.0, 0.0]),
        "left_jamb": ([[x0, y0, near], [x0, y1, near], [x0, y1, far], [x0, y0, far]], [1.0, 0.0, 0.0]),
        "right_jamb": ([[x1, y0, near], [x1, y1, near], [x1, y1, far], [x1, y0, far]], [-1.0, 0.0, 0.0]),
    }
    for name, (corners, toward) in lining.items():
        room.parts.append(planar_quad(facing(corners, toward), paint, f"opening.{name}", _TILE))


def window(seed: int = 0) -> Scene:
    """A room whose far wall has a large opening onto a sunlit courtyard under the sky.

    Failure: an opening that fills the frame. Through it, the courtyard's ground and buildings lie
    metres beyond the wall and the sky has no depth at all; framed by the opening, a model may
    read the view as a picture on the wall, or the wall as part of the view.
    """
    rng = np.random.default_rng([seed, 4])
    W, H, D = rng.uniform(4.5, 5.5), rng.uniform(2.7, 3.0), rng.uniform(4.5, 5.5)
    thickness = 0.2
    # the floor, ceiling and side walls run on past the wall's thickness, closing it
    room = _Room(rng, (W, H, D + thickness))
    del room.parts[3]  # the wall at z = D + thickness: rebuilt at z = D with its opening
    x0, x1 = W / 2 - rng.uniform(1.0, 1.4), W / 2 + rng.uniform(1.0, 1.4)
    y0, y1 = rng.uniform(0.6, 0.9), H - rng.uniform(0.3, 0.5)
    _opening_wall(room, D, thickness, (x0, x1, y0, y1))
    ground, backdrop = room.role("ground"), room.role("backdrop")
    out_z, reach = D + thickness, rng.uniform(7.0, 10.0)
    # the ground runs under the room's wall so that no gap shows at its foot
    ground_corners = [[-6.0, 0.0, D], [W + 6.0, 0.0, D], [W + 6.0, 0.0, out_z + reach], [-6.0, 0.0, out_z + reach]]
    room.parts.append(planar_quad(facing(ground_corners, [0.0, 1.0, 0.0]), ground, "courtyard.ground", 2.0))
    z = out_z + reach
    far = facing([[-6.0, 0.0, z], [W + 6.0, 0.0, z], [W + 6.0, 6.0, z], [-6.0, 6.0, z]], [0.0, 0.0, -1.0])
    room.parts.append(quad_part(far, backdrop, "courtyard.backdrop", ((W + 12.0) / 12.0, 1.0)))
    sky = Emitters(sky_radiance=np.array([1.0, 1.05, 1.15]))
    sun = sky.sun(np.array([0.3, 0.8, 0.5]) / np.linalg.norm([0.3, 0.8, 0.5]), np.full(3, 3.0))
    room.camera([W / 2, 1.5, 1.0], [W / 2, 1.3, D])
    room.camera([0.9, 1.5, 1.5], [W / 2 + 0.5, 1.4, D])
    return room.scene("window", seed, emitters=sun)


def textureless_close(seed: int = 0) -> Scene:
    """A large plain cabinet, one flat colour without texture, standing in a textured room.

    Failure: a close, textureless surface. Near it, the frame holds two or three faces of one
    colour, whose only depth cues are their shading and their edges; a model has nothing to
    measure their slant or distance by.
    """
    rng = np.random.default_rng([seed, 5])
    W, H, D = rng.uniform(5.5, 6.5), rng.uniform(2.6, 3.0), rng.uniform(5.5, 6.5)
    room = _Room(rng, (W, H, D))
    grey = rng.uniform(0.75, 0.9)
    plain = room.material(Material("plain", base_color=np.full(3, grey)))
    lo = np.array([W / 2 - 0.5, 0.0, D / 2])
    room.box(lo, lo + [1.0, 1.9, 0.8], plain, "cabinet")
    room.camera([W - 0.8, 1.5, 0.8], lo + [1.0, 0.9, 0.0])
    room.camera([0.8, 1.6, 0.9], lo + [0.0, 0.9, 0.0])
    return room.scene("textureless_close", seed)


def dim_lamp(seed: int = 0) -> Scene:
    """A room lit only by one small lamp low in a corner: one bright pool, the rest in shadow.

    Failure: shading read as depth. Light falls off with the square of the distance from the lamp
    and furniture casts long shadows across the floor and walls; a model that takes brightness
    for nearness sees the lit corner close and the dark walls far.
    """
    rng = np.random.default_rng([seed, 6])
    W, H, D = rng.uniform(4.5, 5.5), rng.uniform(2.5, 2.8), rng.uniform(4.5, 5.5)
    room = _Room(rng, (W, H, D))
    furniture, fabric = room.role("wood"), room.role("fabric")
    room.box([0.3, 0.0, D - 0.8], [0.8, 0.5, D - 0.3], furniture, "side_table")
    room.box([1.1, 0.0, D - 1.0], [3.1, 0.8, D - 0.1], fabric, "sofa")
    room.box([W - 1.6, 0.0, 1.8], [W - 0.4, 0.45, 2.8], furniture, "low_table")
    room.box([W - 0.5, 0.0, 0.4], [W - 0.1, 1.8, 1.6], furniture, "shelf")
    lamp = np.array([0.55, 0.75, D - 0.55])
    room.box(lamp - [0.05, 0.26, 0.05], lamp - [-0.05, 0.1, -0.05], furniture, "lamp_stand")
    emitters = Emitters().point(lamp, np.full(3, rng.uniform(1.5, 3.0)) * np.array([1.0, 0.85, 0.65]))
    room.camera([W - 1.0, 1.5, 0.8], [W * 0.35, 0.8, D - 0.8])
    room.camera([W / 2, 1.6, 1.0], [W / 2, 1.0, D])
    return room.scene("dim_lamp", seed, lights=lamp[None], emitters=emitters)


def stairs(seed: int = 0) -> Scene:
    """A straight flight of stairs up to a landing along the far wall.

    Failure: repeated steps. Treads and risers alternate in a regular pattern whose depth rises in
    steps; models smooth them into a ramp, or mistake the pattern's repeats for one surface.
    """
    rng = np.random.default_rng([seed, 7])
    W, H, D = rng.uniform(4.5, 5.5), rng.uniform(3.6, 4.0), rng.uniform(6.5, 7.5)
    room = _Room(rng, (W, H, D))
    tread, rail = room.role("wood"), room.role("paint")
    steps = int(rng.integers(10, 13))
    rise, run, width = 0.18, 0.28, rng.uniform(1.0, 1.4)
    x0 = W / 2 - width / 2
    start = D - 1.0 - steps * run
    for i in range(steps):
        z = start + i * run
        room.box([x0, 0.0, z], [x0 + width, (i + 1) * rise, z + run], tread, f"step{i}")
    room.box([x0 - 0.5, 0.0, D - 1.0], [x0 + width + 0.5, steps * rise, D - 0.02], rail, "landing")
    room.camera([W / 2 + 0.4, 1.6, max(0.8, start - 3.0)], [W / 2, 1.0, start + steps * run / 2])
    room.camera([0.8, 1.5, max(0.8, start - 2.0)], [x0 + width / 2, 1.2, start + steps * run])
    return room.scene("stairs", seed)


def mirror(seed: int = 0) -> Scene:
    """A large wall mirror in a wooden frame beside a sideboard, facing a sofa across the room.

    Failure: a reflection read as space. The mirror shows the room again, as a perfect specular
    bounce (:attr:`~kadv.scenes.Material.mirror`), while its depth is the mirror's plane; a model
    that reads the reflected room as a room behind the wall puts a hole in the wall, and may
    flatten the furniture beside it into the picture.
    """
    rng = np.random.default_rng([seed, 8])
    W, H, D = rng.uniform(4.5, 5.5), rng.uniform(2.6, 3.0), rng.uniform(5.5, 6.5)
    room = _Room(rng, (W, H, D))
    frame, furniture, fabric = room.role("wood"), room.role("wood"), room.role("fabric")
    glass = room.material(Material("mirror", base_color=np.full(3, rng.uniform(0.85, 0.95)), mirror=True))
    z0, z1 = D / 2 - rng.uniform(0.9, 1.2), D / 2 + rng.uniform(0.9, 1.2)
    y0, y1 = rng.uniform(0.35, 0.55), H - rng.uniform(0.35, 0.5)
    border = 0.08
    room.box([0.0, y0 - border, z0 - border], [0.04, y1 + border, z1 + border], frame, "mirror.frame")
    corners = [[0.05, y0, z1], [0.05, y0, z0], [0.05, y1, z0], [0.05, y1, z1]]
    room.parts.append(quad_part(facing(corners, [1.0, 0.0, 0.0]), glass, "mirror"))
    room.box([0.0, 0.0, z1 + 0.2], [0.5, 0.85, z1 + 1.4], furniture, "sideboard")
    room.box([W - 0.95, 0.0, z0 - 0.2], [W - 0.05, 0.8, z1 + 0.2], fabric, "sofa")
    room.box([W / 2 - 0.4, 0.0, D / 2 - 0.5], [W / 2 + 0.4, 0.45, D / 2 + 0.5], furniture, "low_table")
    room.camera([W - 1.4, 1.5, 0.9], [0.0, 1.3, D / 2])
    room.camera([W - 0.8, 1.5, D / 2 - 1.5], [0.0, 1.3, D / 2 + 0.3])
    return room.scene("mirror", seed)


PROBES: dict[str, Callable[[int], Scene]] = {
    "photo_wall": photo_wall,
    "grazing_floor": grazing_floor,
    "thin_structures": thin_structures,
    "window": window,
    "textureless_close": textureless_close,
    "dim_lamp": dim_lamp,
    "stairs": stairs,
    "mirror": mirror,
}


def probe_names() -> list[str]:
    """The probes' names, in the scorecard's order."""
    return list(PROBES)


def probe_scene(name: str, seed: int = 0) -> Scene:
    """The probe ``name`` (one of :data:`PROBES`) built with ``seed``.

    Raises:
        ValueError: an unknown name, listing the probes.
    """
    if name not in PROBES:
        raise ValueError(f"no probe scene {name!r}; the probes are: {', '.join(PROBES)}")
    return PROBES[name](seed)
