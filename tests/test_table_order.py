"""Summary tables list rows in the order the sweep file lists its design values, then methods."""

from __future__ import annotations

import numpy as np
import pandas as pd

from tanbench.config import flatten
from tanbench.results import sweep_tables
from tanbench.sweep import parse_sweep

SWEEP = """
name: order
seed: 1
runs: 2
methods: [loose-dvl, tight-dvl]
scenario: {particles: 60, duration_s: 60}
tables:
  resampling: {filter.resampling: [systematic, multinomial]}
  particles: {particles: [80, 60]}
grid:
  noise_m: [2.0, 1.0]
  map_resolution_m: [20, 10]
"""


def _runs(sweep) -> pd.DataFrame:
    """Synthetic runs of every cell, in a shuffled order (as a store listing may return them)."""
    rows = []
    for cell in sweep.cells:
        columns = flatten(cell.scenario.normalized())
        for method in sweep.spec.methods:
            for run in range(sweep.spec.runs):
                rows.append({**columns, "cell_id": cell.cell_id, "method": method, "run": run,
                             "status": "ok", "error": "", "diverged": False,
                             "final_horizontal_error_m": 1.0 + run, "mean_horizontal_error_m": 1.0,
                             "final_heading_error_deg": 0.5})
    runs = pd.DataFrame(rows)
    return runs.iloc[np.random.default_rng(3).permutation(len(runs))].reset_index(drop=True)


def test_rows_follow_the_design_order_then_the_methods():
    sweep = parse_sweep(SWEEP, "order.yaml")
    tables = sweep_tables(_runs(sweep), sweep)
    methods = ["loose-dvl", "tight-dvl"]

    resampling = tables["resampling"]
    assert list(resampling["filter.resampling"]) == ["systematic"] * 2 + ["multinomial"] * 2
    assert list(resampling["method"]) == methods * 2

    particles = tables["particles"]
    assert list(particles["particles"]) == [80, 80, 60, 60]
    assert list(particles["method"]) == methods * 2

    grid = tables["grid"]
    expected = [(n, r, m) for n in (2.0, 1.0) for r in (20.0, 10.0) for m in methods]
    assert list(zip(grid["noise_m"], grid["map_resolution_m"], grid["method"])) == expected
    assert (grid["n_runs"] == 2).all()


MAPPING_SWEEP = """
name: options
seed: 1
runs: 2
methods: [tight-dvl, loose-dvl]
scenario: {particles: 60, duration_s: 60}
tables:
  options:
    method_options: [{tight-dvl: {}}, {tight-dvl: {}, loose-dvl: {}}]
  thinning:
    filter.resampling: [systematic]
    method_options: [{"x.y:run": {k: 1, same: 0}}, {"x.y:run": {k: 2, same: 0}}]
"""


def test_cells_that_differ_only_in_a_mapping_setting_keep_their_own_rows():
    """A design over a mapping (method_options) keys its rows by the flattened options that differ
    between its cells: two cells never pooled into one row (the multibeam study's thinning table did)."""
    sweep = parse_sweep(MAPPING_SWEEP.replace('"x.y:run"', "tight-dvl"), "options.yaml")
    tables = sweep_tables(_runs(sweep), sweep)
    thinning = tables["thinning"]
    assert (thinning["n_runs"] == 2).all() and len(thinning) == 4
    assert list(thinning["method_options.tight-dvl.k"]) == [1, 1, 2, 2]
    assert "method_options.tight-dvl.same" not in thinning.columns  # the same in every cell: no column
