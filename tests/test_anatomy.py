"""tanbench.anatomy: paired and unpaired differences with intervals, on a hand-made results table."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from tanbench.anatomy import anatomy_markdown, anatomy_table, difference_interval
from tanbench.sweep import parse_sweep

SWEEP = """name: a
seed: 1
runs: 4
profile: zhou2017-literal
methods: [tight-dvl, loose-dvl]
tables:
  t3__literal: {}
  t3__propagation: {filter.propagation: [exact]}
  t3__terrain: {terrain.region_hurst: [{A: 0.8}]}
"""


def fake_runs(sweep, values):
    rows = []
    for cell in sweep.cells:
        table = cell.tables[0]
        for method in sweep.spec.methods:
            for run, v in enumerate(values[(table, method)]):
                rows.append(dict(cell_id=cell.cell_id, method=method, run=run, status="ok",
                                 final_horizontal_error_m=v, diverged=v > 75))
    return pd.DataFrame(rows)


def test_difference_interval_paired_and_welch():
    a = pd.Series([5.0, 7.0, 9.0, 12.0])
    b = pd.Series([4.0, 5.0, 8.0, 9.0])
    n, d, lo, hi = difference_interval(a, b, paired=True)
    diffs = np.array([1.0, 2.0, 1.0, 3.0])
    half = stats.t.ppf(0.975, 3) * diffs.std(ddof=1) / 2.0
    assert (n, d) == (4, pytest.approx(1.75)) and lo == pytest.approx(1.75 - half) and hi == pytest.approx(1.75 + half)
    n, d, lo, hi = difference_interval(a, b, paired=False)
    t = stats.ttest_ind(a, b, equal_var=False)
    ci = t.confidence_interval(0.95)
    assert d == pytest.approx(1.75) and lo == pytest.approx(ci.low) and hi == pytest.approx(ci.high)


def test_anatomy_table_rows():
    sweep = parse_sweep(SWEEP)
    vals = {("t3__literal", "tight-dvl"): [10, 20, 30, 40], ("t3__literal", "loose-dvl"): [100, 100, 100, 100],
            ("t3__propagation", "tight-dvl"): [5, 12, 26, 33], ("t3__propagation", "loose-dvl"): [100, 101, 99, 100],
            ("t3__terrain", "tight-dvl"): [50, 60, 70, 80], ("t3__terrain", "loose-dvl"): [60, 70, 100, 105]}
    table = anatomy_table(fake_runs(sweep, vals), sweep)
    assert list(table["switch"].unique()) == ["propagation", "terrain"]
    r = table[(table["switch"] == "propagation") & (table["method"] == "tight-dvl")].iloc[0]
    assert r["paired"] and r["n"] == 4 and r["diff_mean_m"] == pytest.approx(-6.0)
    assert r["baseline_mean_m"] == pytest.approx(25.0) and r["switched_mean_m"] == pytest.approx(19.0)
    assert r["ci_low_m"] < -6.0 < r["ci_high_m"] < 0  # differences -5, -8, -4, -7: clearly negative
    t = table[(table["switch"] == "terrain") & (table["method"] == "tight-dvl")].iloc[0]
    assert not t["paired"] and t["diff_mean_m"] == pytest.approx(40.0)
    md = anatomy_markdown(table)
    assert "**t3**" in md and "25.0 -> 19.0, -6.0 [" in md and "(unpaired)" in md
    lo = table[(table["switch"] == "terrain") & (table["method"] == "loose-dvl")].iloc[0]
    assert (lo["baseline_lost"], lo["switched_lost"]) == (4, 2)  # 100 x 4 lost; 60, 70, 100, 105: 2 above 75 m
    assert r["baseline_lost"] == 0 and "; 0 -> 0 |" in md


def test_undefined_values_leave_their_pairs_out():
    """A metric undefined for a run (NaN) drops that run's pair; n and the Markdown say how many were left."""
    a = pd.Series([5.0, np.nan, 9.0, 12.0])
    b = pd.Series([4.0, 5.0, 8.0, np.nan])
    n, d, lo, hi = difference_interval(a, b, paired=True)
    assert n == 2 and d == pytest.approx(1.0) and lo == pytest.approx(1.0) and hi == pytest.approx(1.0)
    n, d, _, _ = difference_interval(a, b, paired=False)
    assert n == 3 and d == pytest.approx(26.0 / 3 - 17.0 / 3)
    sweep = parse_sweep(SWEEP)
    vals = {(t, m): [10.0, 20.0, 30.0, 40.0] for t in ("t3__literal", "t3__propagation", "t3__terrain")
            for m in ("tight-dvl", "loose-dvl")}
    runs = fake_runs(sweep, vals)
    runs["ratio"] = np.where(runs["run"] == 1, np.nan, 1.0)
    table = anatomy_table(runs, sweep, column="ratio")
    r = table[(table["switch"] == "propagation") & (table["method"] == "tight-dvl")].iloc[0]
    assert (r["n"], r["runs"]) == (3, 4) and r["diff_mean_m"] == 0.0
    assert "(3 of 4 runs: the others undefined)" in anatomy_markdown(table)
