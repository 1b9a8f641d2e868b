"""tanbench.numpy_stream: the sensors' array draws are the Generator's own, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from tanbench.numpy_stream import standard_normal, uniform


@pytest.mark.parametrize("shape", [(), 1, 3, (7, 3), (2, 5, 4), (0, 3)])
def test_array_draws_equal_the_generators_own(shape):
    g, h = np.random.default_rng([2017, 5]), np.random.default_rng([2017, 5])
    for _ in range(2):  # and the state after them: the next draws agree too
        a, b = g.standard_normal(shape), standard_normal(h, shape)
        assert np.shape(a) == b.shape and np.array_equal(a, b)
        a, b = g.uniform(-2.5, 4.0, shape), uniform(h, -2.5, 4.0, shape)
        assert np.shape(a) == b.shape and np.array_equal(a, b)
    assert g.bit_generator.state == h.bit_generator.state


def test_a_long_run_through_the_wedges_and_the_tail():
    """300k normals: about 3600 through the ziggurat's wedges and tail, as numpy draws them."""
    g, h = np.random.default_rng(99), np.random.default_rng(99)
    assert np.array_equal(g.standard_normal((100_000, 3)), standard_normal(h, (100_000, 3)))


def test_other_bit_generators_draw_themselves():
    g, h = np.random.Generator(np.random.Philox(3)), np.random.Generator(np.random.Philox(3))
    assert np.array_equal(g.standard_normal((4, 3)), standard_normal(h, (4, 3)))
    assert np.array_equal(g.uniform(0.0, 2.0, 9), uniform(h, 0.0, 2.0, 9))
