"""The reproduction criterion (tanbench/criterion.py, docs/model.md section 11)."""

import numpy as np
from math import comb

from tanbench import criterion as cr


def test_extreme_critical_is_the_exact_rank_probability():
    # P(K >= k) = C(n, k) / C(n + m, k): at least k of n runs above the largest of m runs, one distribution
    for n, m in ((50, 50), (20, 50), (10, 50)):
        k = cr.extreme_critical(n, m)
        assert comb(n, k) / comb(n + m, k) <= cr.EXTREME_LEVEL < comb(n, k - 1) / comb(n + m, k - 1)
    assert cr.extreme_critical(50, 50) == 7


def test_extreme_rank_probability_by_simulation():
    rng = np.random.default_rng(1)
    x = rng.exponential(size=(20000, 100))
    k = (x[:, :50] > x[:, 50:].max(axis=1, keepdims=True)).sum(axis=1)
    assert abs((k >= 4).mean() - comb(50, 4) / comb(100, 4)) < 0.006


def test_cell_mean_interval_is_a_prediction_interval():
    rng = np.random.default_rng(2)
    ours, paper = rng.gamma(1.5, 10.0, (4000, 50)), rng.gamma(1.5, 10.0, (4000, 50))
    mean_ok, _ = cr._cell_flags(ours, paper.mean(axis=1), paper.min(axis=1), paper.max(axis=1))
    assert 0.92 < mean_ok.mean() < 0.97  # about 95 %, where the plain CI of our mean would cover about 83 %


def test_fitted_distribution_has_the_papers_mean_and_spread():
    for family in ("gamma", "lognormal"):
        d = cr.fitted_distribution(family, 50.9, 0.1, 96.1)
        lo, hi = cr._order_quantiles()
        assert abs(d.mean() - 50.9) < 1e-6
        assert abs((d.ppf(hi) - d.ppf(lo)) - 96.0) < 0.01


def test_steps_and_modes():
    sts = {s.key: s for s in cr.statements()}
    assert set(cr.NINETEEN) <= set(sts) and len(cr.NINETEEN) == 19
    assert sts["6b"].steps[0].column == cr.TIME_AVG  # 6b on its original statistic
    assert not sts["3a"].steps[0].paired and sts["3c"].steps[0].paired
    a = np.array([[1.0, 2.0, 3.0, 4.0, 5.0]])
    assert cr.step_pass(a + 10, a, True, "directional")[0]
    assert not cr.step_pass(a, a + 10, True, "not reversed")[0]
    assert cr.step_pass(a, a + 0.01 * np.array([1, -1, 1, -1, 0]), True, "not reversed")[0]
    assert cr.bound_pass(np.full((1, 50), 9.7) + np.linspace(-1, 1, 50), 10.0)[0]
    assert not cr.bound_pass(np.full((1, 50), 20.0) + np.linspace(-1, 1, 50), 10.0)[0]


def test_faithful_copy_passes_the_simulable_statements_often(monkeypatch):
    # modes from 300 copies here (make criterion uses 2000): a step near the 0.95 power line may differ
    t = cr.choose_modes(reps=300)
    monkeypatch.setattr(cr, "_MODES", dict(zip(t["step"], t["mode"])))
    rows, cells, counts = cr.faithful_pass(reps=300, seed=7)
    p = rows.groupby("key")["p"].min()
    assert (p[[k for k in cr.NINETEEN if k in p.index]] >= 0.85).all()  # >= 0.90 at 2000 copies (make criterion)
    assert cells["p_cell"].min() > 0.8
