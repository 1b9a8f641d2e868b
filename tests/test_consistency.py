"""NEES: its value against a linear-algebra reference, its bounds, and the cell verdict."""

from __future__ import annotations

import numpy as np

from tanbench.metrics.consistency import (cell_verdict, mc_bounds, nees, one_run_bounds, run_summary)

SEED = 1505


def correlated_errors(rng, n, cov):
    return rng.multivariate_normal([0.0, 0.0], cov, size=n)


def test_nees_matches_solve():
    rng = np.random.default_rng(SEED)
    cov = np.array([[4.0, 1.5], [1.5, 2.0]])
    e = correlated_errors(rng, 50, cov)
    ref = np.einsum("ki,ij,kj->k", e, np.linalg.inv(cov), e)
    got = nees(e[:, 0], e[:, 1], np.full(50, 4.0), np.full(50, 2.0), np.full(50, 1.5))
    np.testing.assert_allclose(got, ref, rtol=1e-12)
    diag = nees(e[:, 0], e[:, 1], np.full(50, 4.0), np.full(50, 2.0))
    np.testing.assert_allclose(diag, e[:, 0] ** 2 / 4 + e[:, 1] ** 2 / 2, rtol=1e-12)
    assert np.isnan(nees([1.0], [1.0], [0.0], [1.0]))[0]


def test_bounds():
    lo, hi = one_run_bounds()
    assert abs(lo - 0.0506) < 1e-3 and abs(hi - 7.378) < 1e-3
    l1, h1 = mc_bounds(1)
    assert abs(l1 - lo) < 1e-12 and abs(h1 - hi) < 1e-12
    l50, h50 = mc_bounds(50)
    assert 1.4 < l50 < 2 < h50 < 2.7


def test_consistent_filter_stays_inside_and_overconfident_one_is_flagged():
    rng = np.random.default_rng(SEED)
    runs, steps = 50, 200
    cov = np.array([[9.0, 2.0], [2.0, 4.0]])
    t = np.arange(steps, dtype=float)
    summaries = {"true": [], "small": [], "large": []}
    mc = []
    for _ in range(runs):
        e = correlated_errors(rng, steps, cov)
        for label, scale in (("true", 1.0), ("small", 0.1), ("large", 30.0)):
            v = nees(e[:, 0], e[:, 1], np.full(steps, 9.0 * scale), np.full(steps, 4.0 * scale),
                     np.full(steps, 2.0 * scale))
            summaries[label].append(run_summary(t, v, 0.0))
            if label == "true":
                mc.append(v)
    mean_over_runs = np.mean(mc, axis=0)
    lo, hi = mc_bounds(runs)
    inside = np.mean((mean_over_runs > lo) & (mean_over_runs < hi))
    assert 0.9 < inside <= 1.0
    true = summaries["true"]
    assert abs(np.mean([s["nees_mean_after_convergence"] for s in true]) - 2.0) < 0.1
    assert abs(np.mean([s["nees_above_95"] for s in true]) - 0.025) < 0.01

    def verdict(label):
        s = summaries[label]
        return cell_verdict([x["nees_above_95"] for x in s], [x["nees_below_95"] for x in s])

    assert verdict("true") == "consistent"
    assert verdict("small") == "over-confident"
    assert verdict("large") == "under-confident"


def test_run_summary_after_convergence_only():
    t = np.arange(10.0)
    v = np.array([100.0] * 5 + [2.0] * 5)
    s = run_summary(t, v, 5.0)
    assert s["nees_mean_after_convergence"] == 2.0
    assert s["nees_above_95"] == 0.5
    assert np.isnan(run_summary(t, v, float("nan"))["nees_mean_after_convergence"])


def test_one_run_bounds_at_the_defaults_are_scipys_numbers():
    """The stored default bounds (which spare the workers scipy.stats' import) are scipy's, to the bit."""
    from scipy import stats

    from tanbench.metrics import consistency

    a = (1 - consistency.LEVEL) / 2
    assert one_run_bounds() == (float(stats.chi2.ppf(a, consistency.NEES_DOF)),
                                float(stats.chi2.ppf(1 - a, consistency.NEES_DOF)))
    b = (1 - 0.9) / 2
    assert one_run_bounds(3, 0.9) == (float(stats.chi2.ppf(b, 3)), float(stats.chi2.ppf(1 - b, 3)))


def test_mc_bounds_are_scipy_stats_numbers():
    """mc_bounds (scipy.special's inverse incomplete gamma) gives chi2.ppf's values to the bit."""
    from scipy import stats

    n = np.array([1, 2, 5, 30, 200, 1650, 123456], dtype=float)
    for level in (0.95, 0.9):
        a = (1 - level) / 2
        lo, hi = mc_bounds(n, 2, level)
        np.testing.assert_array_equal(lo, stats.chi2.ppf(a, 2 * n) / n)
        np.testing.assert_array_equal(hi, stats.chi2.ppf(1 - a, 2 * n) / n)


def test_nees_of_a_wild_method_is_inf_or_nan_without_a_warning():
    """A plug-in's estimates near 1e300 made numpy print an overflow warning line (found by an audit)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = nees(np.array([1e300, 1.0]), np.array([1.0, 1.0]), np.array([1e300, 1.0]), np.array([1e300, 1.0]))
    assert not np.isfinite(out[0]) and out[1] == 2.0
