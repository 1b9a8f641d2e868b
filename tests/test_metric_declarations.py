"""Metrics as declarations (issue 26): one record per metric, read by scoring, schema, tables and check.

``lost_time_fraction`` was added as one declaration in tanbench/metrics/declarations.py; this
file is its test (docs/results.md, "Metrics as declarations", lists the files touched).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from tanbench.config import FilterSpec
from tanbench.metrics.declarations import BY_NAME, METRICS, RunScore, accuracy_metrics, compute_all, lost_metric
from tanbench.results import summarize
from tanbench.schema import METRIC_COLUMNS, METRIC_TYPES, run_schema


def _run(err_h) -> RunScore:
    err_h = np.asarray(err_h, float)
    n = err_h.size
    return RunScore(t=np.arange(n, dtype=float), err_e=err_h, err_n=np.zeros(n), err_h=err_h,
                    heading_err=np.zeros(n), reinit=np.zeros(n, bool), left_map=False, filter=FilterSpec(),
                    wall=0.1, conv_time=np.nan, rmse=np.nan, recovery=(0, np.nan, np.nan),
                    consistency={k: np.nan for k in ("nees_mean_after_convergence", "nees_above_95", "nees_below_95",
                                                     "pcrb_after_convergence_m", "rmse_pcrb_ratio",
                                                     "nees_mean_whole_run", "reported_std_below_bound",
                                                     "pcrb_map_after_convergence_m", "rmse_pcrb_map_ratio")})


def test_lost_time_fraction_is_the_share_of_updates_beyond_the_divergence_threshold():
    threshold = FilterSpec().divergence_threshold_m  # 75 m
    m = compute_all(_run([10.0, threshold + 5, 300.0, threshold, 3.0]))
    assert m["lost_time_fraction"] == 0.4  # 2 of 5 above (the threshold itself is not above)
    assert m["diverged"] is False and compute_all(_run([1.0, 80.0]))["diverged"] is True


def test_every_layer_reads_the_declarations():
    assert METRIC_COLUMNS == tuple(m.name for m in METRICS)
    assert METRIC_TYPES["lost_time_fraction"] == pa.float64() and METRIC_TYPES["diverged"] == pa.bool_()
    assert run_schema([]).field("lost_time_fraction").type == pa.float64()
    assert set(compute_all(_run([1.0, 2.0]))) == set(METRIC_COLUMNS)
    assert lost_metric().name == "diverged"
    assert [m.label for m in accuracy_metrics()] == ["final", "time-avg"]
    runs = pd.DataFrame({"cell_id": "c", "method": "m", "status": "ok", "diverged": [False, True],
                         "final_horizontal_error_m": [1.0, 90.0], "mean_horizontal_error_m": [1.0, 40.0],
                         "final_heading_error_deg": 0.0, "lost_time_fraction": [0.0, 0.5]})
    row = summarize(runs).iloc[0]
    assert row["mean_lost_time_fraction"] == 0.25 and row["lost_rate"] == 0.5
    assert BY_NAME["lost_time_fraction"].summary == "mean" and BY_NAME["lost_time_fraction"].check is None


@pytest.mark.parametrize("stored", ["ci-baseline", "methods"])
def test_scored_runs_carry_it(stored):
    """Committed results (scored with the declaration): a fraction in [0, 1], positive in every
    lost run (its last update is beyond the threshold) and in every run whose time-averaged error
    exceeds the threshold (some update must). The CI baseline has no lost run; results/methods
    has (the EKF's and TERCOM's), so the two implications are checked on real lost runs."""
    from pathlib import Path

    import tanbench.results as tr

    runs = tr.load(Path(__file__).resolve().parents[1] / "results" / stored, status="ok")
    f = runs["lost_time_fraction"].to_numpy(float)
    assert np.isfinite(f).all() and (f >= 0).all() and (f <= 1).all()
    lost = runs["diverged"].astype(bool).to_numpy()
    far = runs["mean_horizontal_error_m"].to_numpy(float) > 75.0
    assert (f[lost] > 0).all() and (f[far] > 0).all()
    if stored == "methods":
        assert lost.sum() >= 10 and far.sum() >= 10  # the implications are not vacuous here
