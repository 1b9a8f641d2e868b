"""The statistics of tanbench's verdicts: exact tests of lost-run flags, permutation tests of
means and tails against a margin, Holm's correction, exact intervals, minimal detectable effects.

Used by :mod:`tanbench.check` (regression verdicts) and :mod:`tanbench.results` (intervals in
the tables). docs/results.md ("Verdicts") states every choice; the tests in
tests/test_verdicts.py check them, including the false-alarm rate on simulated nulls.

* **Lost runs** (0/1 flags): paired (runs share seeds) by McNemar's exact test on the
  discordant pairs (a binomial test of b against c), unpaired by Fisher's exact test.
* **Accuracy** (a mean or the 90th percentile of a metric): a permutation test of the
  statistic's change against a margin delta. H0 "the change is at most delta" is tested by
  shifting NEW down by delta and asking whether the two samples are exchangeable: paired,
  each pair's two values are swapped at random (for the mean this is the sign-flip test of
  the differences); unpaired, the labels are permuted. Exact at a change of exactly delta
  and conservative below it for the mean and any quantile (both move with a shift).
* **Holm-Bonferroni** adjusted p-values over a family of tests.
* **Minimal detectable effect** at 80 % power for a one-sided level ``a`` (normal
  approximation): ``margin + (z_{1-a} + z_{0.8}) * se`` for a change of a mean or a
  percentile, with se from the baseline's own spread under reseeding; for a lost-run rate
  the increase whose Cohen's h equals ``(z_{1-a} + z_{0.8}) * sqrt(1/n_new + 1/n_base)``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

POWER = 0.80
PERMUTATIONS = 4000


def holm(p) -> np.ndarray:
    """Holm-Bonferroni adjusted p-values."""
    p = np.asarray(p, dtype=float)
    m = p.size
    order = np.argsort(p, kind="stable")
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, (m - rank) * p[i])
        adj[i] = min(1.0, running)
    return adj


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact (Clopper-Pearson) interval of a binomial rate k / n."""
    if n <= 0:
        return (math.nan, math.nan)
    a = (1.0 - level) / 2.0
    lo = 0.0 if k == 0 else _beta_quantile(a, k, n - k + 1)
    hi = 1.0 if k == n else _beta_quantile(1.0 - a, k + 1, n - k)
    return lo, hi


def _beta_quantile(q: float, a: float, b: float) -> float:
    """``scipy.stats.beta.ppf(q, a, b)`` (the same bits, tests/test_speed_paths.py) by scipy.special's public
    inverse of the regularised incomplete beta function, without importing scipy.stats: a results table
    needs only this, and scipy.stats costs a sweep's parent about a second to import."""
    return float(special.betaincinv(a, b, q))


def _stats():
    """scipy.stats, imported when a test needs it (the verdicts), not with the tables."""
    from scipy import stats

    return stats


def lost_tests(new: np.ndarray, base: np.ndarray, paired: bool) -> tuple[float, float]:
    """One-sided p-values (more lost in NEW, fewer lost in NEW) of two sets of lost flags."""
    new, base = np.asarray(new, bool), np.asarray(base, bool)
    if paired:
        b = int(np.sum(new & ~base))  # lost only in NEW
        c = int(np.sum(base & ~new))
        if b + c == 0:
            return 1.0, 1.0
        return float(_stats().binom.sf(b - 1, b + c, 0.5)), float(_stats().binom.sf(c - 1, b + c, 0.5))
    if new.size == 0 or base.size == 0:
        return 1.0, 1.0
    table = [[int(new.sum()), int((~new).sum())], [int(base.sum()), int((~base).sum())]]
    return (float(_stats().fisher_exact(table, alternative="greater").pvalue),
            float(_stats().fisher_exact(table, alternative="less").pvalue))


def p90(values: np.ndarray, axis=-1):
    """The 90th percentile (linear interpolation), the tail statistic of the verdicts."""
    return np.percentile(values, 90, axis=axis)


STATISTICS = {"mean": lambda v, axis=-1: np.mean(v, axis=axis), "p90": p90}


def permutation_p(x: np.ndarray, y: np.ndarray, shift: float, paired: bool, statistic: str = "mean",
                  n: int = PERMUTATIONS, seed: int = 0) -> float:
    """One-sided p-value of H0 "stat(x) - stat(y) <= shift" (see the module docstring)."""
    x = np.asarray(x, float) - shift
    y = np.asarray(y, float)
    if x.size < 2 or y.size < 2:
        return 1.0
    stat = STATISTICS[statistic]
    observed = float(stat(x) - stat(y))
    rng = np.random.default_rng(seed)
    if paired:
        swap = rng.random((n, x.size)) < 0.5
        a, b = np.where(swap, y, x), np.where(swap, x, y)
    else:
        both = np.concatenate([x, y])
        order = np.argsort(rng.random((n, both.size)), axis=1)
        perm = both[order]
        a, b = perm[:, :x.size], perm[:, x.size:]
    null = stat(a, axis=1) - stat(b, axis=1)
    return float((1 + np.sum(null >= observed - 1e-12 * max(1.0, abs(observed)))) / (n + 1))


def bootstrap_change_ci(x: np.ndarray, y: np.ndarray, paired: bool, statistic: str = "mean", level: float = 0.95,
                        n: int = 2000, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of stat(x) - stat(y) (pairs resampled jointly when paired)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.size == 0 or y.size == 0:
        return (math.nan, math.nan)
    stat = STATISTICS[statistic]
    rng = np.random.default_rng(seed)
    if paired:
        idx = rng.integers(0, x.size, (n, x.size))
        reps = stat(x[idx], axis=1) - stat(y[idx], axis=1)
    else:
        reps = (stat(x[rng.integers(0, x.size, (n, x.size))], axis=1)
                - stat(y[rng.integers(0, y.size, (n, y.size))], axis=1))
    a = 50.0 * (1.0 - level)
    lo, hi = np.percentile(reps, [a, 100.0 - a])
    return float(lo), float(hi)


def bootstrap_sd(y: np.ndarray, statistic: str, n: int = 1000, seed: int = 0) -> float:
    """Bootstrap standard error of a statistic of one sample."""
    y = np.asarray(y, float)
    if y.size < 2:
        return math.nan
    rng = np.random.default_rng(seed)
    return float(np.std(STATISTICS[statistic](y[rng.integers(0, y.size, (n, y.size))], axis=1), ddof=1))


def z_sum(level: float, power: float = POWER) -> float:
    """z_{1-level} + z_{power}: the distance, in standard errors, of a detectable effect."""
    return float(_stats().norm.ppf(1.0 - level) + _stats().norm.ppf(power))


def mde_shift(margin: float, se: float, level: float) -> float:
    """Smallest true change detected with 80 % power by the one-sided test against ``margin``."""
    return margin + z_sum(level) * se if np.isfinite(se) else math.inf


def reseed_se(base: np.ndarray, statistic: str, n_new: int) -> float:
    """Standard error of a change of ``statistic`` between NEW and BASELINE when NEW is a
    reseed of BASELINE (independent runs of the same spread): the baseline's own spread."""
    base = np.asarray(base, float)
    if base.size < 2 or n_new < 2:
        return math.inf
    if statistic == "mean":
        sd = float(np.std(base, ddof=1))
        return sd * math.sqrt(1.0 / base.size + 1.0 / n_new)
    return bootstrap_sd(base, statistic) * math.sqrt(1.0 + base.size / n_new)


def mde_lost(rate_base: float, n_new: int, n_base: int, level: float) -> float:
    """Smallest increase of the lost-run rate detected with 80 % power (Cohen's h, arcsine scale)."""
    if n_new < 1 or n_base < 1:
        return math.inf
    h = z_sum(level) * math.sqrt(1.0 / n_new + 1.0 / n_base)
    phi = 2.0 * math.asin(math.sqrt(min(max(rate_base, 0.0), 1.0))) + h
    if phi >= math.pi:
        return math.inf
    return float(math.sin(phi / 2.0) ** 2 - rate_base)


def mde_lost_paired(n: int, reshuffled: int, level: float) -> float:
    """Smallest rate of newly lost runs detected with 80 % power by McNemar's exact test on
    ``n`` pairs, when ``reshuffled`` runs are lost only in BASELINE (the reseed noise of the
    flags, taken at its observed count): runs lost only in NEW are Poisson(n * (mde + c / n))."""
    if n < 1:
        return math.inf
    c = int(reshuffled)
    b = 1
    while _stats().binom.sf(b - 1, b + c, 0.5) > level:  # the fewest runs lost only in NEW that reject
        b += 1
        if b > 10 * n + 100:
            return math.inf
    lam = float(special.gammaincinv(b, POWER))  # P(Poisson(lam) >= b) = POWER
    return max(lam / n - c / n, 0.0)
