"""kadv.render.shading: texture lookups, mip levels and the view-independent shading model."""
from __future__ import annotations

import numpy as np

from kadv.render.shading import Shading, mip_pyramid, sample_texture, shade


def _texture() -> np.ndarray:
    return np.random.default_rng(0).random((4, 8, 3)).astype(np.float32)


def test_bilinear_lookup_returns_texels_at_their_centres_and_wraps_around() -> None:
    texture = _texture()
    rows, columns = np.meshgrid(np.arange(4), np.arange(8), indexing="ij")
    # texel (row, column) centre: u = (column + 0.5) / W, v = 1 - (row + 0.5) / H (v = 1 is the first row)
    uv = np.c_[(columns.ravel() + 0.5) / 8, 1.0 - (rows.ravel() + 0.5) / 4]
    np.testing.assert_allclose(sample_texture(texture, uv), texture.reshape(-1, 3), atol=1e-6)
    np.testing.assert_allclose(sample_texture(texture, uv + 1.0), sample_texture(texture, uv), atol=1e-6)
    halfway = sample_texture(texture, np.array([[1.0 / 8, 1.0 - 0.5 / 4]]))[0]  # between texels 0 and 1 of row 0
    np.testing.assert_allclose(halfway, 0.5 * (texture[0, 0] + texture[0, 1]), atol=1e-6)


def test_mip_levels_halve_down_to_the_mean() -> None:
    levels = mip_pyramid(_texture())
    assert [level.shape[:2] for level in levels] == [(4, 8), (2, 4), (1, 2), (1, 1)]
    np.testing.assert_allclose(levels[-1][0, 0], _texture().mean(axis=(0, 1)), atol=1e-6)


def test_ambient_only_returns_the_base_colour_and_a_facing_light_adds_the_diffuse_weight() -> None:
    base = np.array([[0.2, 0.4, 0.6]])
    point, normal = np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]])
    np.testing.assert_allclose(shade(Shading(ambient=1.0, diffuse=0.0), np.array([[0.0, 5.0, 0.0]]), point, normal, base), base)
    lit = shade(Shading(ambient=0.3, diffuse=0.5), np.array([[0.0, 5.0, 0.0]]), point, normal, base)
    np.testing.assert_allclose(lit, base * 0.8)
    behind = shade(Shading(ambient=0.3, diffuse=0.5), np.array([[0.0, -5.0, 0.0]]), point, normal, base)
    np.testing.assert_allclose(behind, base * 0.3)
