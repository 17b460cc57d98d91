"""The atlas's fixed pseudo-random numbers, written out so that planning does not import
numpy.random (atlas/polytope.py's hash weights, atlas/domain.py's directions' draws): they
are the generator's, bit for bit."""

import numpy as np
import pytest

from cdh_planner.atlas import domain, polytope


def test_the_hash_weights_are_the_generators():
    assert np.array_equal(polytope._HASH, np.random.default_rng(0).uniform(1.0, 2.0, 16))


@pytest.mark.parametrize("n", range(1, domain.DRAWS_MAX_DIM + 1))
@pytest.mark.parametrize("count", [1, 7, domain.DRAWS_MAX_COUNT])
def test_the_written_draws_are_the_generators(n, count):
    expected = np.random.default_rng(1000 * n).standard_normal((count, n))
    assert np.array_equal(domain._normal_draws(1000 * n, (count, n)), expected)


@pytest.mark.parametrize("seed, shape", [(6001, (384, 6)), (7000, (5, 7)), (1000, (385, 1))])
def test_draws_the_file_does_not_hold_come_from_the_generator(seed, shape):
    expected = np.random.default_rng(seed).standard_normal(shape)
    assert np.array_equal(domain._normal_draws(seed, shape), expected)


def test_the_file_holds_exactly_the_draws_of_dimensions_one_to_six():
    draws = np.load(domain.DRAWS_FILE)
    assert draws.dtype == np.float64
    assert draws.shape == (domain.DRAWS_MAX_COUNT * sum(range(1, domain.DRAWS_MAX_DIM + 1)),)


def test_unit_directions_are_unit_vectors_of_the_draws():
    u = domain.unit_directions(4, 50)
    g = np.random.default_rng(4000).standard_normal((50, 4))
    assert np.array_equal(u, g / np.linalg.norm(g, axis=1, keepdims=True))
    assert np.allclose(np.linalg.norm(u, axis=1), 1.0, rtol=0, atol=1e-15)
