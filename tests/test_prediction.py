"""Prediction checked against outcome: the rank correlations and the per-cell predictors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from tanbench.prediction import PREDICTORS, correlations

ROOT = Path(__file__).resolve().parents[1]


def test_correlations_rank_monotone_relations():
    x = np.array([0.5, 1.0, 2.0, 4.0, 8.0])
    cells = pd.DataFrame({"method": "tight-dvl", "suitability_std_m": x, "information_per_ping": 1 / x,
                          "pcrb_mean_m": x ** 2, "mean_time_avg_error_m": 3 * x + 1,
                          "mean_final_error_m": [5.0, 4.0, 3.0, 2.0, 1.0]})
    c = correlations(cells).set_index(["method", "predictor", "outcome"])
    rho = c["spearman_rho"]
    assert abs(rho[("tight-dvl", "suitability_std_m", "mean_time_avg_error_m")] - 1.0) < 1e-12
    assert abs(rho[("tight-dvl", "information_per_ping", "mean_time_avg_error_m")] + 1.0) < 1e-12
    assert abs(rho[("all", "pcrb_mean_m", "mean_final_error_m")] + 1.0) < 1e-12
    assert c.loc[("tight-dvl", "pcrb_mean_m", "mean_final_error_m"), "n_cells"] == 5


def test_cell_table_of_the_ci_baseline(monkeypatch):
    from tanbench.prediction import cell_table

    monkeypatch.chdir(ROOT)
    cells = cell_table(ROOT / "results" / "ci-baseline")
    assert set(cells["method"]) == {"tight-dvl", "tight-sbe", "loose-dvl"}
    assert np.isfinite(cells[list(PREDICTORS)].to_numpy()).all()
    dvl = cells[cells["method"] == "tight-dvl"].set_index(["map_resolution_m", "sampling_time_s"])
    # a coarser map keeps less slope: less information, a larger predicted std and bound
    assert dvl.loc[(20.0, 1.0), "information_per_ping"] < dvl.loc[(10.0, 1.0), "information_per_ping"]
    assert dvl.loc[(20.0, 1.0), "pcrb_mean_m"] > dvl.loc[(10.0, 1.0), "pcrb_mean_m"]
    # fewer updates (5 s sampling) on the same map: the same suitability, a larger bound
    assert dvl.loc[(10.0, 5.0), "suitability_std_m"] == dvl.loc[(10.0, 1.0), "suitability_std_m"]
    assert dvl.loc[(10.0, 5.0), "pcrb_mean_m"] > dvl.loc[(10.0, 1.0), "pcrb_mean_m"]


def test_predict_bad_input_is_one_line(tmp_path):
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-m", "tanbench.cli", "predict", str(tmp_path / "missing"),
                          "--out", str(tmp_path / "out")], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 2
    assert res.stderr.startswith("error: ") and res.stderr.count("\n") == 1
    assert not (tmp_path / "out").exists()
