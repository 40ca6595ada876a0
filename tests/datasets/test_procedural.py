"""kadv.datasets: procedural training views."""

from __future__ import annotations

import pytest
import torch

from kadv.datasets import render_procedural_views


def test_views_are_deterministic_per_seed_and_consistent() -> None:
    first = render_procedural_views(6, seed=3, height=12, width=16, views_per_room=3, progress=False)
    again = render_procedural_views(6, seed=3, height=12, width=16, views_per_room=3, progress=False)
    other = render_procedural_views(6, seed=4, height=12, width=16, views_per_room=3, progress=False)
    assert first.rgb.shape == (6, 3, 12, 16) and first.depth.shape == first.mask.shape == (6, 1, 12, 16)
    assert torch.equal(first.rgb, again.rgb) and torch.equal(first.depth, again.depth)
    assert not torch.equal(first.depth, other.depth)
    assert torch.equal(first.mask, first.depth > 0)
    assert float(first.mask.float().mean()) > 0.95  # views from inside closed rooms


def test_a_share_of_the_rooms_is_furnished() -> None:
    boxes = render_procedural_views(4, seed=3, height=12, width=16, views_per_room=2, progress=False)
    mixed = render_procedural_views(
        4, seed=3, height=12, width=16, views_per_room=2, furnished_share=0.5, progress=False
    )
    # room 0 is a box room in both, room 1 is furnished in the mix
    assert torch.equal(boxes.rgb[:2], mixed.rgb[:2])
    assert not torch.equal(boxes.depth[2:], mixed.depth[2:])
    with pytest.raises(ValueError, match="furnished_share"):
        render_procedural_views(4, seed=3, height=12, width=16, furnished_share=1.5, progress=False)
