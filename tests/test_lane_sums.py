"""The fixed-order sums over particles as vector lanes (``filters/vecmath.py`` ``lane_*``): the same bits as the
four scalar chains they replace (``estimate.weighted_moments_scalar``, ``weighted_cross_scalar``,
``resample.sum4_scalar``, ``sum_sq4_scalar``), whatever the length, scale or non-finite entries; and the
estimate still equals its plain-numpy reference."""

from __future__ import annotations

import numpy as np
import pytest

from tanbench.filters import estimate as est
from tanbench.filters import resample as rs


def _cases(seed, count=120):
    rng = np.random.default_rng(seed)
    for trial in range(count):
        m = int(rng.integers(0, 4100))
        row = rng.normal(size=m) * 10.0 ** rng.uniform(-6, 4) + rng.uniform(-2000, 2000)
        if m and trial % 7 == 0:
            row[rng.integers(0, m)] = (np.nan, np.inf, -np.inf)[trial % 3]
        w = rng.random(m)
        yield row, w / w.sum() if m else w, float(rng.uniform(-4, 4))


def _same(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return np.array_equal(a, b, equal_nan=True) and np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("angle", [False, True])
def test_weighted_moments_lanes_equal_the_scalar_chains(angle):
    for row, w, ref in _cases(1 + angle):
        ref = ref if angle else (row[0] if row.size else 0.0)
        assert _same(est.weighted_moments(row, w, ref, angle), est.weighted_moments_scalar(row, w, ref, angle))


def test_weighted_cross_and_sums_lanes_equal_the_scalar_chains():
    for row, w, ref in _cases(3):
        other = row[::-1].copy()
        assert _same(est.weighted_cross(row, other, w, ref, -ref), est.weighted_cross_scalar(row, other, w, ref, -ref))
        assert _same(rs.sum4(row), rs.sum4_scalar(row))
        assert _same(rs.sum_sq4(row), rs.sum_sq4_scalar(row))


def test_weighted_estimate_still_matches_numpy():
    rng = np.random.default_rng(5)
    m = 3001
    x = rng.normal(size=(8, m)) * np.array([40, 40, 1, 0.01, 0.01, 0.5, 1e-5, 1e-5])[:, None]
    x += np.array([900.0, 700.0, -20.0, 0.0, 0.0, 3.1, 0.0, 0.0])[:, None]
    w = rng.random(m)
    w /= w.sum()
    mean, var, cov = np.empty(8), np.empty(8), np.empty((2, 2))
    est.weighted_estimate(x, w, 5, 3.0, mean, var, cov)
    want = est.weighted_estimate_numpy(x, w, 5, 3.0)
    np.testing.assert_allclose(mean, want[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(var, want[1], rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(cov, want[2], rtol=1e-9, atol=1e-15)


def test_max_log_weight_lanes_find_the_first_maximum():
    """``resample.max_log_weight`` from ``vecmath.lane_first_max``: the value element-by-element search finds,
    NaN passed over, -inf for none, and among zeros of both signs the first one (the sign of zero included)."""
    rng = np.random.default_rng(9)
    for trial in range(300):
        m = int(rng.integers(0, 300 if trial % 2 else 5000))
        a = rng.normal(size=m) * 10.0 ** rng.uniform(-3, 3)
        if trial % 5 == 0 and m:
            a[rng.integers(0, m, 3)] = np.nan
        if trial % 7 == 0:
            a = np.where(rng.random(m) < 0.5, 0.0, -0.0) - (rng.random(m) < 0.3)
        if trial % 11 == 0:
            a[:] = (np.nan, -np.inf)[trial % 2]
        assert _same(rs.max_log_weight(a), rs.max_log_weight_scalar(a))
    assert rs.max_log_weight(np.array([-0.0, 0.0, -1.0, -2.0, 0.0])) == 0.0
    assert np.signbit(rs.max_log_weight(np.array([-0.0, 0.0, -1.0, -2.0, 0.0])))
    assert not np.signbit(rs.max_log_weight(np.array([-3.0, 0.0, -1.0, -2.0, -0.0, 0.0])))
