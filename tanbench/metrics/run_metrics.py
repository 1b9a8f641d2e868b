"""The per-run consistency and efficiency metrics that scoring adds to each run.

Scoring (which alone reads the truth) calls :func:`score_consistency_and_bound` with the
run's errors and the method's reported covariance; it returns

* metrics: the NEES summaries of :func:`tanbench.metrics.consistency.run_summary`;
  ``pcrb_after_convergence_m``, the RMS of the cell's PCRB (:mod:`tanbench.bounds.pcrb`)
  over the updates after the run's convergence, and ``rmse_pcrb_ratio``, the run's RMSE
  after convergence divided by it (NaN if the run never converged or the method has no
  bound);
* series: per-update ``nees``, ``pcrb_horizontal_m`` and ``pcrb_heading_deg``.

Their names and types are declared in :mod:`tanbench.schema`.
"""

from __future__ import annotations

import numpy as np

from tanbench.metrics.consistency import nees, run_summary


def score_consistency_and_bound(scenario, method: str | None, t: np.ndarray, err_e, err_n, var_e, var_n, cov_en,
                                convergence_time_s: float, rmse_after_convergence_m: float,
                                bound=None) -> tuple[dict, dict]:
    """(metrics, series) of the module docstring for one run; ``bound``: the PCRB series of the
    method in the cell (:func:`tanbench.bounds.pcrb.method_bound`, handed down by the caller; None: no bound)."""
    values = nees(err_e, err_n, var_e, var_n, cov_en)
    metrics = run_summary(t, values, convergence_time_s)
    nan = np.full(t.size, np.nan)
    if bound is None or bound["t"].size != t.size:
        pcrb_h, pcrb_psi = nan, nan
    else:
        pcrb_h, pcrb_psi = bound["pcrb_horizontal_m"].to_numpy(), bound["pcrb_heading_deg"].to_numpy()
    after = (t - t[0] >= convergence_time_s) if np.isfinite(convergence_time_s) else np.zeros(t.size, bool)
    if after.any() and np.isfinite(pcrb_h[after]).all():
        pcrb_rms = float(np.sqrt(np.mean(pcrb_h[after] ** 2)))
        ratio = rmse_after_convergence_m / pcrb_rms
    else:
        pcrb_rms = ratio = float("nan")
    metrics.update(pcrb_after_convergence_m=pcrb_rms, rmse_pcrb_ratio=float(ratio))
    return metrics, {"nees": values, "pcrb_horizontal_m": pcrb_h, "pcrb_heading_deg": pcrb_psi}
