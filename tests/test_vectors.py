"""The hot paths' cross products against numpy's."""

import numpy as np
import pytest

from sit2stand.vectors import cross, skew_rows


@pytest.mark.parametrize("shape_a, shape_b", [((3,), (3,)), ((7, 3), (3,)), ((3,), (7, 3)), ((7, 3), (7, 3)),
                                              ((2, 5, 3), (5, 3))])
def test_cross_equals_numpys_for_single_vectors_and_stacks(shape_a, shape_b):
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=shape_a), rng.normal(size=shape_b)
    np.testing.assert_allclose(cross(a, b), np.cross(a, b), rtol=0, atol=1e-15)


def test_cross_takes_lists():
    np.testing.assert_array_equal(cross([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]), [0.0, 0.0, 1.0])


def test_skew_rows_are_the_cross_product_matrices_of_the_rows():
    rng = np.random.default_rng(5)
    r, w = rng.normal(size=(4, 3)), rng.normal(size=(3, 9))
    np.testing.assert_allclose(skew_rows(r) @ w, np.cross(r[:, None, :], w.T[None]).transpose(0, 2, 1), atol=1e-15)
