"""hemishadow.products.matmul: numpy's product, without numpy's BLAS threads."""

import time

import numpy as np
import pytest

from hemishadow.products import matmul


@pytest.mark.parametrize("shape", [(0, 25, 3), (1, 1, 1), (1369, 25, 25), (5000, 3, 3), (8, 40000, 3)])
def test_matches_numpy(shape):
    n, k, m = shape
    rng = np.random.default_rng(n + k + m)
    a, b = rng.normal(size=(n, k)), rng.normal(size=(k, m))
    exact = a @ b
    np.testing.assert_allclose(matmul(a, b), exact, rtol=1e-12, atol=1e-12 * np.sqrt(k))
    single = matmul(a.astype(np.float32), b.astype(np.float32))
    assert single.dtype == np.float32 and single.shape == (n, m)
    np.testing.assert_allclose(single, exact, rtol=1e-5, atol=1e-5 * np.sqrt(k))


def test_wider_type_wins_and_views_are_read_as_they_are():
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    b = np.arange(20, dtype=np.float64).reshape(5, 4)
    assert matmul(a, b.T).dtype == np.float64
    np.testing.assert_array_equal(matmul(a, b.T), a @ b.T)  # a transposed view
    np.testing.assert_array_equal(matmul(a[:, ::2], b[:2, ::2]), a[:, ::2] @ b[:2, ::2])  # strided


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match="cannot multiply shapes"):
        matmul(np.ones((3, 4)), np.ones((3, 4)))
    with pytest.raises(ValueError, match="2-D"):
        matmul(np.ones(3), np.ones((3, 1)))


def test_leaves_no_thread_spinning():
    a, b = np.ones((4000, 25), np.float32), np.ones((25, 25), np.float32)
    time.sleep(0.5)  # threads woken earlier (numpy's own products) go back to sleep
    for _ in range(5):
        matmul(a, b)
    start = time.process_time()
    time.sleep(0.3)
    assert time.process_time() - start < 0.03
