from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.render import ExactRenderer
from kadv.scenes import box_room


def test_same_seed_same_room_bit_for_bit() -> None:
    a, b = box_room(seed=3), box_room(seed=3)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.uvs, b.uvs)
    assert all(np.array_equal(x.texture, y.texture) for x, y in zip(a.materials, b.materials))
    assert not np.array_equal(a.vertices, box_room(seed=4).vertices)


@pytest.mark.parametrize("seed", range(5))
def test_room_is_closed_and_camera_is_sensible(seed: int) -> None:
    scene = box_room(seed=seed)
    renderer = ExactRenderer(scene)
    camera = scene.cameras[0]
    centre = camera.world_T_cam[:3, 3].numpy()
    directions = np.random.default_rng(seed).normal(size=(2000, 3))
    hits = renderer.cast(np.broadcast_to(centre, directions.shape), directions).numpy()
    assert hits.hit.all()  # closed: every direction from inside hits a surface
    assert (hits.t * np.linalg.norm(directions, axis=1)).min() > 0.5
    out = renderer.render(camera.world_T_cam, camera.intrinsics(60, 80), 60, 80)
    assert out.mask.all() and float(out.rgb.std()) > 0.05  # textured, not blank
    assert scene.num_triangles >= 12 + 12  # walls plus at least one box


def test_too_small_room_is_rejected() -> None:
    with pytest.raises(ValueError, match=">= 2 m"):
        box_room(seed=0, size=(1.0, 3.0, 3.0))


def test_camera_looks_into_the_room(room) -> None:
    camera = room.cameras[0]
    forward = camera.world_T_cam[:3, 2]
    assert float(forward[0]) > 0 and float(forward[2]) > 0
    assert torch.isclose(camera.world_T_cam[1, 3], torch.tensor(1.5, dtype=torch.float64))
