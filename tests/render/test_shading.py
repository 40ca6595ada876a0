"""kadv.render.shading: texture lookups, mip levels and the view-independent shading model."""

from __future__ import annotations

import numpy as np
import torch

from kadv.render.shading import Shading, shade
from kadv.render.textures import TextureAtlas, mip_pyramid, sample_texture


def _texture() -> np.ndarray:
    return np.random.default_rng(0).random((4, 8, 3)).astype(np.float32)


def test_bilinear_lookup_returns_texels_at_their_centres_and_wraps_around() -> None:
    texture = torch.from_numpy(_texture())
    rows, columns = torch.meshgrid(torch.arange(4), torch.arange(8), indexing="ij")
    # texel (row, column) centre: u = (column + 0.5) / W, v = 1 - (row + 0.5) / H (v = 1 is the first row)
    uv = torch.stack([(columns.flatten() + 0.5) / 8, 1.0 - (rows.flatten() + 0.5) / 4], dim=1).double()
    torch.testing.assert_close(sample_texture(texture, uv), texture.reshape(-1, 3), atol=1e-6, rtol=0)
    torch.testing.assert_close(sample_texture(texture, uv + 1.0), sample_texture(texture, uv), atol=1e-6, rtol=0)
    halfway = sample_texture(texture, torch.tensor([[1.0 / 8, 1.0 - 0.5 / 4]], dtype=torch.float64))[0]
    torch.testing.assert_close(halfway, 0.5 * (texture[0, 0] + texture[0, 1]), atol=1e-6, rtol=0)  # texels 0 and 1


def test_mip_levels_halve_down_to_the_mean_and_the_lookup_blends_two_levels() -> None:
    levels = mip_pyramid(_texture())
    assert [tuple(level.shape[:2]) for level in levels] == [(4, 8), (2, 4), (1, 2), (1, 1)]
    np.testing.assert_allclose(levels[-1][0, 0].numpy(), _texture().mean(axis=(0, 1)), atol=1e-6)
    atlas = TextureAtlas.build([_texture()])
    uv = torch.tensor([[0.3, 0.6]], dtype=torch.float64)
    slot = torch.zeros(1, dtype=torch.int64)
    between = atlas.trilinear(slot, uv, torch.tensor([2.25]))
    torch.testing.assert_close(between, 0.75 * sample_texture(levels[2], uv) + 0.25 * sample_texture(levels[3], uv))
    torch.testing.assert_close(atlas.trilinear(slot, uv, torch.tensor([9.0])), levels[-1][0])


def test_one_atlas_samples_textures_of_several_sizes_and_a_texel_of_ones_in_one_call() -> None:
    small = np.random.default_rng(1).random((2, 3, 3)).astype(np.float32)
    atlas = TextureAtlas.build([_texture(), None, small])
    uv = torch.tensor([[0.3, 0.6], [0.7, 0.1], [0.45, 0.8], [-2.3, 5.6]], dtype=torch.float64)
    slots = torch.tensor([0, 1, 2, 0])
    levels = torch.tensor([0.0, 0.0, 1.5, 0.5])
    mixed = atlas.trilinear(slots, uv, levels)
    torch.testing.assert_close(mixed[0], sample_texture(torch.from_numpy(_texture()), uv[:1])[0])
    torch.testing.assert_close(mixed[1], torch.ones(3))
    # the small texture has two levels: 1.5 blends its last level with itself
    torch.testing.assert_close(mixed[2], mip_pyramid(small)[1].reshape(3))
    alone = TextureAtlas.build([_texture()]).trilinear(torch.tensor([0]), uv[3:], levels[3:])
    torch.testing.assert_close(mixed[3:], alone, rtol=0, atol=0)


def test_ambient_only_returns_the_base_colour_and_a_facing_light_adds_the_diffuse_weight() -> None:
    base = torch.tensor([[0.2, 0.4, 0.6]], dtype=torch.float64)
    point, normal = torch.zeros(1, 3, dtype=torch.float64), torch.tensor([[0.0, 1.0, 0.0]], dtype=torch.float64)
    above, below = (
        torch.tensor([[0.0, 5.0, 0.0]], dtype=torch.float64),
        torch.tensor([[0.0, -5.0, 0.0]], dtype=torch.float64),
    )
    close = {"rtol": 1e-7, "atol": 0.0}
    torch.testing.assert_close(shade(Shading(ambient=1.0, diffuse=0.0), above, point, normal, base), base, **close)
    torch.testing.assert_close(
        shade(Shading(ambient=0.3, diffuse=0.5), above, point, normal, base), base * 0.8, **close
    )
    torch.testing.assert_close(
        shade(Shading(ambient=0.3, diffuse=0.5), below, point, normal, base), base * 0.3, **close
    )
