"""Statements about the committed estimator comparison in results/methods (``make methods``).

Stated in docs/methods.md ("The field's other estimators") before the committed sweep was
run. Skipped only while results/methods does not exist (before the lead's first ``make
methods``); once it is committed, every statement here is checked on it.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

RESULTS = Path(__file__).resolve().parents[1] / "results" / "methods"
METHODS = ["tight-dvl", "tight-sbe", "loose-dvl", "pmf-dvl", "pmf-sbe", "mpf-dvl", "ekf-dvl", "tercom-dvl"]


@pytest.fixture(scope="module")
def default_a():
    if not (RESULTS / "runs").exists():
        pytest.skip("results/methods is not generated yet (make methods)")
    table = pd.read_parquet(RESULTS / "tables" / "budget-default.parquet")
    return table[table["area"] == "A"].set_index("method")


def test_every_method_ran_every_run(default_a):
    assert list(default_a.index) == METHODS
    assert (default_a["n_failed"] == 0).all()


def test_pmf_within_1_5x_of_tight_at_no_more_wall_time(default_a):
    """Area A, default budget: pmf-dvl's mean final error is within 1.5x of tight-dvl's, and its mean
    filter wall time per run is no more than tight-dvl's."""
    pmf, tight = default_a.loc["pmf-dvl"], default_a.loc["tight-dvl"]
    assert pmf["mean_final_error_m"] <= 1.5 * tight["mean_final_error_m"]
    assert pmf["mean_filter_wall_s"] <= tight["mean_filter_wall_s"]
