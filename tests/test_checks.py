"""kadv.checks.check_shape: declared shapes, named sizes that must repeat."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.checks import check_shape


def test_matching_shapes_bind_their_names() -> None:
    assert check_shape(torch.zeros(5, 6), "B 6", "params") == {"B": 5}
    assert check_shape(np.zeros((2, 3, 4, 5)), "B 3 H W", "rgb") == {"B": 2, "H": 4, "W": 5}
    assert check_shape(torch.zeros(4, 4, 4), "B 4 4", "pose") == {"B": 4}


@pytest.mark.parametrize("shape, spec", [((5, 7), "B 6"), ((5,), "B 6"), ((2, 5, 6), "B 6"), ((3, 4), "N N")])
def test_mismatches_name_the_input_and_both_shapes(shape, spec) -> None:
    with pytest.raises(ValueError, match=rf"^x: expected shape \(.*\), got \({shape[0]},"):
        check_shape(torch.zeros(shape), spec, "x")


def test_a_size_bound_by_an_earlier_check_must_repeat() -> None:
    sizes = check_shape(torch.zeros(3, 3), "B 3", "c_old")
    with pytest.raises(ValueError, match="c_new"):
        check_shape(torch.zeros(4, 3), "B 3", "c_new", sizes)
