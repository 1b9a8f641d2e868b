"""Filter consistency: the normalised estimation error squared (NEES) of the horizontal position.

At each update a method reports its horizontal covariance P (``var_e``, ``var_n`` and,
if it reports one, ``cov_en``; without it, or where it is NaN, P is taken as diagonal).
With the error
e = estimate - truth,

    NEES_k = e_k^T P_k^{-1} e_k,

which for a consistent filter (errors zero-mean with the reported covariance) is
chi-square with 2 degrees of freedom, mean 2. Two tests (Bar-Shalom, Li & Kirubarajan
2001, section 5.4):

* **over runs** (the Monte Carlo mean at each time): with N runs, N * mean_k ~ chi2(2N),
  so the mean lies in [chi2_{0.025}(2N) / N, chi2_{0.975}(2N) / N] 95 % of the time
  (:func:`mc_bounds`);
* **one run**: NEES_k lies in [chi2_{0.025}(2), chi2_{0.975}(2)] = [0.051, 7.38] 95 % of
  the time, 2.5 % above and 2.5 % below.

Per run (:func:`run_summary`): the mean NEES after convergence, the fractions of all
updates above and below the one-run bounds, the **whole-run average NEES** ANEES_r (every
update with a defined NEES: convergence, steady state and, for a lost run, its wandering)
and whether the reported horizontal std, RMS over the run, is below the RMS of the bound.

Per cell, the verdict (docs/model.md 9.2; docs/filters.md section 2, fixed before it was
computed; :func:`whole_run_verdict`): ANEES = the mean of ANEES_r over the N runs; the band
[chi2_0.025(2N) / N, chi2_0.975(2N) / N] (:func:`mc_bounds`); **over-confident** above it,
**under-confident** below it, else **consistent**; and, for a method with a bound,
**over-confident (below the bound)** whatever the ANEES if its reported std is below the
bound in more than half of its runs. The NEES figure draws the same ANEES (the time average
of the Monte Carlo mean NEES, :func:`anees_of_series`) with the same band and verdict.
The earlier fraction rule (:func:`cell_verdict`: over-confident when on average more than
``VERDICT_FRACTION`` of the updates lie above the one-run bound) is kept for comparison;
its columns stay in the tables.
"""

from __future__ import annotations

import numpy as np

NEES_DOF = 2
LEVEL = 0.95
VERDICT_FRACTION = 0.25
# scipy.stats.chi2.ppf's bounds of one NEES value at the defaults, as scipy gives them (a test
# checks them): every run uses them, and a worker then never imports scipy.stats (2-4 s)
_ONE_RUN_BOUNDS = {(NEES_DOF, LEVEL): (0.050635615968579795, 7.377758908227871)}


def nees(err_e, err_n, var_e, var_n, cov_en=None) -> np.ndarray:
    """Per-update NEES of the horizontal error; NaN where the covariance is not positive definite."""
    err_e, err_n = np.asarray(err_e, float), np.asarray(err_n, float)
    var_e, var_n = np.asarray(var_e, float), np.asarray(var_n, float)
    c = np.zeros_like(var_e) if cov_en is None else np.nan_to_num(np.asarray(cov_en, float), nan=0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a wild method's inf is its NEES
        det = var_e * var_n - c * c
        out = (var_n * err_e**2 - 2 * c * err_e * err_n + var_e * err_n**2) / det
    return np.where((det > 0) & (var_e > 0), out, np.nan)


def one_run_bounds(dof: int = NEES_DOF, level: float = LEVEL) -> tuple[float, float]:
    """Two-sided bounds of one NEES value."""
    known = _ONE_RUN_BOUNDS.get((dof, level))
    if known is not None:
        return known
    from scipy import stats

    a = (1 - level) / 2
    return float(stats.chi2.ppf(a, dof)), float(stats.chi2.ppf(1 - a, dof))


def mc_bounds(n_runs, dof: int = NEES_DOF, level: float = LEVEL):
    """Two-sided bounds of the mean NEES over ``n_runs`` runs (array or scalar).

    ``scipy.stats.chi2.ppf(q, k)`` is ``2 gammaincinv(k / 2, q)`` (its own definition, so the
    same bits; a test checks them) from scipy.special, a fraction of scipy.stats' import time."""
    from scipy import special

    n = np.asarray(n_runs, dtype=float)
    a = (1 - level) / 2
    return 2 * special.gammaincinv(dof * n / 2, a) / n, 2 * special.gammaincinv(dof * n / 2, 1 - a) / n


def reported_below_bound(var_e, var_n, pcrb_h) -> float:
    """1.0 if the reported horizontal std, RMS over the updates where it and the bound are
    defined, sqrt(mean(var_e + var_n)), is below the RMS of the bound ``pcrb_h`` over the same
    updates; 0.0 if not; NaN without a bound."""
    v = np.asarray(var_e, float) + np.asarray(var_n, float)
    b = np.asarray(pcrb_h, float)
    ok = np.isfinite(v) & np.isfinite(b)
    if not ok.any():
        return float("nan")
    return float(np.sqrt(np.mean(v[ok])) < np.sqrt(np.mean(b[ok] ** 2)))


def whole_run_verdict(anees: float, n_runs: int, below_bound_share: float = float("nan")) -> str:
    """The cell verdict of the module docstring from the cell's ANEES over ``n_runs`` runs and the
    share of its runs whose reported std is below the bound (NaN: no bound)."""
    if not n_runs or not np.isfinite(anees):
        return "-"
    if np.isfinite(below_bound_share) and below_bound_share > 0.5:
        return "over-confident (below the bound)"
    lo, hi = mc_bounds(n_runs)
    if anees > hi:
        return "over-confident"
    if anees < lo:
        return "under-confident"
    return "consistent"


def anees_of_series(nees_mean) -> float:
    """ANEES read off the figure's curve: the time average of the Monte Carlo mean NEES (equal to
    the mean of the runs' whole-run averages when every run has a NEES at every update)."""
    v = np.asarray(nees_mean, float)
    v = v[~np.isnan(v)]  # an infinite mean (a float32 summary overflows above 3.4e38) stays: over-confident
    return float(v.mean()) if v.size else float("nan")


def run_summary(t, values: np.ndarray, convergence_time_s: float) -> dict:
    """Per-run NEES summary (``RUN_COLUMNS``) of the per-update values."""
    t = np.asarray(t, float)
    values = np.asarray(values, float)
    lo, hi = one_run_bounds()
    ok = ~np.isnan(values)
    n = max(int(ok.sum()), 1)
    after = values[ok & (t - t[0] >= convergence_time_s)] if np.isfinite(convergence_time_s) else values[:0]
    return {
        "nees_mean_after_convergence": float(after.mean()) if after.size else float("nan"),
        "nees_above_95": float((values[ok] > hi).sum() / n) if ok.any() else float("nan"),
        "nees_below_95": float((values[ok] < lo).sum() / n) if ok.any() else float("nan"),
        "nees_mean_whole_run": float(values[ok].mean()) if ok.any() else float("nan"),
    }


def cell_verdict(above: np.ndarray, below: np.ndarray) -> str:
    """'over-confident', 'under-confident' or 'consistent' from the runs' fractions (see the module)."""
    above = np.asarray(above, float)
    below = np.asarray(below, float)
    if np.isnan(above).all():
        return "-"
    if np.nanmean(above) > VERDICT_FRACTION:
        return "over-confident"
    if np.nanmean(below) > VERDICT_FRACTION:
        return "under-confident"
    return "consistent"
