from __future__ import annotations

import numpy as np
import pytest

from kadv.penalties import random_valid_poses, view_validity
from kadv.penalties.validity import fibonacci_sphere
from kadv.render import ExactRenderer
from kadv.scenes import procedural_room

SEEDS = range(12)  # rooms, an L, a hall (2) and corridors along x (3) and z (11)


def _floor_sides(room) -> list[float]:
    """The room's floor extent along x and z, shorter first."""
    return sorted((room.interior[1, [0, 2]] - room.interior[0, [0, 2]]).tolist())


def test_same_seed_same_room_bit_for_bit() -> None:
    a, b = procedural_room(seed=5), procedural_room(seed=5)
    for name in ("vertices", "faces", "uvs", "normals", "material_ids", "lights"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert all(np.array_equal(x.texture, y.texture) for x, y in zip(a.materials, b.materials))
    assert np.array_equal(a.cameras[0].world_T_cam, b.cameras[0].world_T_cam)
    assert a.vertices.shape != procedural_room(seed=6).vertices.shape or not np.array_equal(
        a.vertices, procedural_room(seed=6).vertices
    )


@pytest.mark.parametrize("seed", SEEDS)
def test_rooms_are_closed_but_for_their_windows_and_their_cameras_valid(seed: int) -> None:
    scene = procedural_room(seed=seed)
    glazed = ExactRenderer(procedural_room(seed=seed, drop_transparent=False))
    glass = [i for i, m in enumerate(glazed.scene.materials) if m.transparent]
    renderer = ExactRenderer(scene)
    camera = scene.cameras[0]
    K = camera.intrinsics(24, 32)
    assert bool(view_validity(renderer, camera.world_T_cam, K, 24, 32).valid.all())
    sampled = random_valid_poses(renderer, 6, np.random.default_rng(seed), 70.0)
    centres = np.concatenate([camera.world_T_cam[None, :3, 3].numpy(), sampled[:, :3, 3].numpy()])
    directions = fibonacci_sphere(2048)
    for centre in centres:
        origins = np.broadcast_to(centre, directions.shape)
        through_glass = glazed.cast(origins, directions)
        # with its glass in place the room is sealed, and from inside only front faces are seen but
        # for the slivers of back that the 1 mm edge overlaps sealing every seam show at grazing angles
        assert through_glass.hit.all()
        assert glazed.back_facing(through_glass, directions).mean() < 0.01
        # without it, a ray escapes only where the glass was
        escaped = ~renderer.cast(origins, directions).hit
        assert np.isin(glazed.scene.material_ids[through_glass.triangle_ids[escaped]], glass).all()


def test_rooms_vary_and_are_lit_at_their_lamps_and_windows() -> None:
    rooms = [procedural_room(seed=seed) for seed in SEEDS]
    assert all(len(room.lights) >= 1 for room in rooms)
    heights = [float(room.interior[1, 1]) for room in rooms]
    assert min(heights) >= 2.4 and max(heights) <= 3.4 and max(heights) - min(heights) > 0.4
    sides = [_floor_sides(room) for room in rooms]
    corridors = [short <= 3.2 and long >= 10.0 for short, long in sides]
    assert sum(corridors) >= 2 and any(short >= 8.0 for short, _ in sides)  # corridors and a hall
    assert any(not corridor and long <= 8.0 for corridor, (_, long) in zip(corridors, sides, strict=True))
    assert len({room.num_triangles for room in rooms}) == len(rooms)
    # windows: from some rooms' cameras, rays leave through the (dropped) glass over the courtyard walls
    directions = fibonacci_sphere(4096)
    escapes = [
        (
            ~ExactRenderer(room)
            .cast(np.broadcast_to(room.cameras[0].world_T_cam[:3, 3].numpy(), directions.shape), directions)
            .hit
        ).mean()
        for room in rooms
    ]
    assert max(escapes) > 0.0


def test_the_shares_choose_the_footprints() -> None:
    assert all(_floor_sides(procedural_room(seed, corridor_share=0, hall_share=0))[1] <= 8.0 for seed in SEEDS)
    assert all(_floor_sides(procedural_room(seed, corridor_share=1, hall_share=0))[1] >= 10.0 for seed in SEEDS)
    with pytest.raises(ValueError, match="sum to at most 1"):
        procedural_room(0, corridor_share=0.6, hall_share=0.6)
