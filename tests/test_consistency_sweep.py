"""NEES and the PCRB through a sweep: runs, series, tables and `tanbench check --nees`.

The over-confident setting and the verdict rule are fixed in docs/model.md (section 9.2)
before this test was run: a measurement noise of 0.05 m (the filter's Table 2 value is
1 m; the range noise is uniform +-1 m) must be flagged over-confident, the default not.
"""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from mutation_support import LATER_NEUTRAL  # the later defaults' neutral values, as YAML
from tanbench.check import CheckOptions, compare
from tanbench import store

SWEEP = """
name: overconfidence
seed: 15150
runs: 8
methods: [tight-dvl]
# the plain likelihood, where filter.measurement_noise_altitude_m is the whole beam variance (the
# recommended map-aware one adds the map's representation and node errors to it)
# (loose_reopen_heading: navigation and loose_reopen_position: prior keep the cell keys, and so the seeds, this test
# was written with: the defaults since docs/filters.md 14.2 and 15.1 are loose-dvl options, but every cell key holds them)
# (measured 4 December 2026, thirteenth session: on these keys the 1 m cell stays consistent at 40 runs, ANEES 2.27
# inside the band's 1.43-2.67; on today's default keys it is consistent at 8 runs and over-confident at 40, ANEES 4.08:
# this cell's verdict moves with the seeds, so the test checks the rule on the pinned realisation, not the filter)
scenario: {particles: 2000, duration_s: 300, filter: {map_aware_likelihood: false, likelihood: gaussian,
                                                      loose_reopen_heading: navigation, loose_reopen_position: prior,
                                                      """ + LATER_NEUTRAL + """}}
tables:
  noise_model: {filter.measurement_noise_altitude_m: [1.0, 0.05]}
"""


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    from tanbench.runner.engine import run_sweep
    from tanbench.sweep import parse_sweep

    out = tmp_path_factory.mktemp("overconfidence") / "res"
    run_sweep(parse_sweep(SWEEP), out, workers=1, progress=False, echo=lambda *a, **k: None)
    return out


def test_overconfident_setting_is_flagged(results):
    import tanbench.results as tr

    table = pd.read_parquet(results / "tables" / "noise_model.parquet").set_index(
        "filter.measurement_noise_altitude_m")
    assert table.loc[1.0, "nees_verdict"] == "consistent"
    # the whole-run verdict (docs/model.md 9.2): a reported std below the bound is over-confidence too
    assert table.loc[0.05, "nees_verdict"].startswith("over-confident")
    assert table.loc[0.05, "nees_above_95"] > 0.5 > table.loc[1.0, "nees_above_95"]
    # the bound describes the data, not the filter's tuning: both cells share it
    runs = tr.load(results, status="ok")
    default = runs[runs["filter.measurement_noise_altitude_m"] == 1.0]
    assert default["rmse_pcrb_ratio"].notna().all()
    lo, hi = table.loc[1.0, ["rmse_pcrb_ratio_ci95_low", "rmse_pcrb_ratio_ci95_high"]]
    assert 1.0 < lo <= table.loc[1.0, "rmse_pcrb_ratio"] <= hi  # no filter beats the bound


def test_series_carry_nees_and_the_bound(results):
    import tanbench.results as tr

    s = tr.load_series(results)
    for col in ("horizontal_error_m_rms", "nees_mean", "nees_mc_low", "nees_mc_high", "pcrb_horizontal_m"):
        assert col in s.columns
    per_cell = s.groupby("cell_id")["pcrb_horizontal_m"].apply(lambda v: v.to_numpy())
    a, b = per_cell.iloc[0], per_cell.iloc[1]
    np.testing.assert_array_equal(a, b)
    assert (s["nees_mc_low"] < 2).all() and (s["nees_mc_high"] > 2).all()


def test_check_regresses_on_nees(results, tmp_path):
    same = compare(results, results, CheckOptions(nees=True))
    assert set(same.table["metric"]) == {"lost", "final", "final p90", "time-avg", "time-avg p90", "nees"}
    assert not same.regressed
    worse = tmp_path / "worse"
    shutil.copytree(results, worse, ignore=shutil.ignore_patterns(".work"))
    for path in store.run_files(worse):
        meta = store.read_meta(path)
        df = pq.read_table(path).to_pandas()
        df["nees_above_95"] = np.minimum(df["nees_above_95"] + 0.3, 1.0)
        store.write_parquet(df, path, meta)
    # a few runs per cell: the tails left out so that Holm's family (lost, final, time-avg, nees per
    # cell and method) leaves the paired permutation test room to reach alpha
    result = compare(worse, results, CheckOptions(nees=True, tail=False))
    t = result.table
    assert (t[t["metric"] != "nees"]["verdict"] != "regressed").all()
    assert result.regressed and set(t[t["verdict"] == "regressed"]["metric"]) == {"nees"}
    assert not compare(worse, results).regressed  # without --nees the errors alone did not change


def test_report_section_shows_the_ratio(results):
    from tanbench.report import efficiency_section

    table = pd.read_parquet(results / "tables" / "noise_model.parquet")
    text = efficiency_section({"table3": table})
    row = table[table["filter.measurement_noise_altitude_m"] == 1.0].iloc[0]
    assert f"{row['rmse_pcrb_ratio']:.2f} times the bound" in text
    assert "over-confident" in text and "consistent" in text
    assert efficiency_section({"table3": table.drop(columns=["rmse_pcrb_ratio"])}) == ""


def test_plot_draws_the_bound_and_nees(results):
    pytest.importorskip("matplotlib")
    from tanbench.plot import plot_results

    written = plot_results(results)
    assert any(p.name.endswith("_bound_nees.png") and p.stat().st_size > 0 for p in written)
