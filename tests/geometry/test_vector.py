"""kadv.geometry.vector: written-out 3-vector products agree with the library reductions, to the bit."""

from __future__ import annotations

import numpy as np
import torch

from kadv.geometry.vector import dot, mat_vec


def test_dot_equals_the_summed_product_in_numpy_and_torch_and_broadcasts() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(50, 4, 3)), rng.normal(size=(50, 1, 3))
    np.testing.assert_array_equal(dot(a, b), (a * b).sum(-1))
    assert dot(a, b).shape == (50, 4)
    ta, tb = torch.from_numpy(a).float(), torch.from_numpy(b).float()
    assert torch.equal(dot(ta, tb), (ta * tb).sum(-1))
    assert dot(np.array([1.0, 2.0, 3.0]), np.array([4.0, -5.0, 6.0])) == 12.0


def test_mat_vec_applies_each_matrix_to_its_vectors() -> None:
    rng = np.random.default_rng(1)
    M, x = rng.normal(size=(20, 3, 3)), rng.normal(size=(20, 5, 2, 3))
    np.testing.assert_allclose(mat_vec(M, x), np.einsum("nij,nekj->neki", M, x), rtol=1e-14, atol=1e-14)
    swap = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    np.testing.assert_array_equal(mat_vec(swap[None], np.array([[1.0, 2.0, 3.0]])), [[2.0, 1.0, 6.0]])
    tM, tx = torch.from_numpy(M), torch.from_numpy(x[:, 0, 0])
    torch.testing.assert_close(mat_vec(tM, tx), (tM @ tx[..., None])[..., 0], rtol=1e-14, atol=1e-14)
