"""kadv.scenes.textures: the sRGB transfer function and its inverse."""

from __future__ import annotations

import numpy as np

from kadv.scenes.textures import linear_to_srgb, srgb_to_linear


def test_srgb_decoding_inverts_encoding_on_both_branches() -> None:
    linear = np.array([0.0, 0.001, 0.0031308, 0.01, 0.2, 0.5, 1.0])
    np.testing.assert_allclose(srgb_to_linear(linear_to_srgb(linear)), linear, atol=1e-12)
    np.testing.assert_allclose(srgb_to_linear(np.array([0.5])), [0.214041140], atol=1e-8)  # a textbook value
    assert srgb_to_linear(np.array([2.0]))[0] == 1.0  # clipped like the encoder
