"""The per-run consistency and efficiency metrics that scoring adds to each run.

Scoring (which alone reads the truth) calls :func:`score_consistency_and_bound` with the
run's errors and the method's reported covariance; it returns

* metrics: the NEES summaries of :func:`tanbench.metrics.consistency.run_summary`;
  ``pcrb_after_convergence_m``, the RMS of the cell's PCRB (:mod:`tanbench.bounds.pcrb`)
  over the updates after the run's convergence, and ``rmse_pcrb_ratio``, the run's RMSE
  after convergence divided by it (NaN if the run never converged or the method has no
  bound); ``pcrb_map_after_convergence_m`` and ``rmse_pcrb_map_ratio``, the same two against
  the second bound, whose beams carry the map's declared error (``MAP_BOUND_COLUMN`` of
  :func:`tanbench.bounds.pcrb.method_bound`; NaN when the bound series has no such column);
* series: per-update ``nees``, ``pcrb_horizontal_m`` and ``pcrb_heading_deg``.

Their names and types are declared in :mod:`tanbench.schema`.
"""

from __future__ import annotations

import numpy as np

from tanbench.bounds.pcrb import MAP_BOUND_COLUMN
from tanbench.metrics.consistency import nees, reported_below_bound, run_summary


def after_convergence(bound_h: np.ndarray, after: np.ndarray, rmse_after_convergence_m: float) -> tuple[float, float]:
    """(RMS of the horizontal bound ``bound_h`` over the updates ``after`` convergence, the run's RMSE
    after convergence / that); both NaN if there is no such update or the bound is not finite there."""
    if after.any() and np.isfinite(bound_h[after]).all():
        rms = float(np.sqrt(np.mean(bound_h[after] ** 2)))
        return rms, float(rmse_after_convergence_m / rms)
    return float("nan"), float("nan")


def score_consistency_and_bound(scenario, method: str | None, t: np.ndarray, err_e, err_n, var_e, var_n, cov_en,
                                convergence_time_s: float, rmse_after_convergence_m: float,
                                bound=None) -> tuple[dict, dict]:
    """(metrics, series) of the module docstring for one run; ``bound``: the PCRB series of the
    method in the cell (:func:`tanbench.bounds.pcrb.method_bound`, handed down by the caller; None: no bound)."""
    values = nees(err_e, err_n, var_e, var_n, cov_en)
    metrics = run_summary(t, values, convergence_time_s)
    nan = np.full(t.size, np.nan)
    if bound is None or bound["t"].size != t.size:
        pcrb_h, pcrb_psi, pcrb_map_h = nan, nan, nan
    else:
        pcrb_h, pcrb_psi = bound["pcrb_horizontal_m"].to_numpy(), bound["pcrb_heading_deg"].to_numpy()
        pcrb_map_h = bound[MAP_BOUND_COLUMN].to_numpy() if MAP_BOUND_COLUMN in bound else nan
    after = (t - t[0] >= convergence_time_s) if np.isfinite(convergence_time_s) else np.zeros(t.size, bool)
    pcrb_rms, ratio = after_convergence(pcrb_h, after, rmse_after_convergence_m)
    map_rms, map_ratio = after_convergence(pcrb_map_h, after, rmse_after_convergence_m)
    metrics.update(pcrb_after_convergence_m=pcrb_rms, rmse_pcrb_ratio=ratio,
                   reported_std_below_bound=reported_below_bound(var_e, var_n, pcrb_h),
                   pcrb_map_after_convergence_m=map_rms, rmse_pcrb_map_ratio=map_ratio)
    return metrics, {"nees": values, "pcrb_horizontal_m": pcrb_h, "pcrb_heading_deg": pcrb_psi}
