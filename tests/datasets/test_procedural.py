"""kadv.datasets: procedural training views."""
from __future__ import annotations

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
