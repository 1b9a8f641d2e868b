"""The second bound (docs/model.md 9.1): the PCRB whose beams also carry the navigation map's declared error.

It is reported beside the PCRB, never instead of it: ``method_bound``'s ``pcrb_map_horizontal_m``
and the per-run metrics ``pcrb_map_after_convergence_m`` and ``rmse_pcrb_map_ratio``. Results
directories written before it (without those columns) are read, checked and resumed as before.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tanbench.bounds.pcrb import MAP_BOUND_COLUMN, method_bound, ping_information
from tanbench.config import Scenario

ROOT = Path(__file__).resolve().parents[1]
PROTOTYPES = ROOT / "examples" / "prototypes"
NEW = ("pcrb_map_after_convergence_m", "rmse_pcrb_map_ratio")
BOUNDS = [("dvl", "full"), ("sbe", "full"), ("dvl", "position")]
SMALL = dict(area="A", duration_s=120, particles=200)


def test_unit_weights_give_the_same_bits():
    rng = np.random.default_rng(7)
    sens = rng.normal(size=(50, 4, 3))
    for d in (2, 3, 5):
        assert np.array_equal(ping_information(sens, 0.577, d, np.ones((50, 4))), ping_information(sens, 0.577, d))


@pytest.mark.parametrize("bound", BOUNDS)
def test_without_map_error_it_is_the_pcrb_to_the_bit(bound):
    """No node error (terrain.map_error_m 0) and no representation term (filter.map_slope_factor 0): every
    beam's weight is exactly 1, and the two bounds are the same floats."""
    sc = Scenario(**SMALL, terrain={"map_error_m": 0.0}, filter={"map_slope_factor": 0.0, "map_representation": "slope"})
    b = method_bound(sc, bound)
    assert np.isfinite(b["pcrb_horizontal_m"]).all()
    assert np.array_equal(b[MAP_BOUND_COLUMN].to_numpy(), b["pcrb_horizontal_m"].to_numpy())


@pytest.mark.parametrize("bound", BOUNDS)
def test_it_is_never_below_the_pcrb(bound):
    """More variance per beam is less information: J_map <= J at every update, so PCRB_map >= PCRB (to the
    recursion's rounding, 1e-12 relative); with the defaults' 0.4 m node error it is above after the start."""
    b = method_bound(Scenario(**SMALL), bound)
    pcrb, with_map = b["pcrb_horizontal_m"].to_numpy(), b[MAP_BOUND_COLUMN].to_numpy()
    assert (with_map >= pcrb * (1 - 1e-12)).all()
    assert (with_map[10:] > pcrb[10:]).all()


def test_noise_free_ranges_have_neither_bound():
    b = method_bound(Scenario(**SMALL, noise_m=0.0), ("dvl", "full"))
    assert b["pcrb_horizontal_m"].isna().all() and b[MAP_BOUND_COLUMN].isna().all()


@pytest.mark.parametrize("bound", [("dvl", "full"), ("sbe", "full"), ("dvl", "position")])
def test_it_is_the_prototypes_recursion(bound, monkeypatch):
    """examples/prototypes/bound_map.py's ``map_aware_bound`` on the same small world: equal to 1e-12
    relative (the prototype divides the sensitivities by each beam's std, tanbench multiplies them by the
    square root of sigma_r^2 / variance, so the last bits differ)."""
    monkeypatch.syspath_prepend(str(PROTOTYPES))
    for name in ("bound_map", "measure"):
        sys.modules.pop(name, None)
    import bound_map
    import measure

    sc = Scenario(**SMALL)
    monkeypatch.setattr(measure, "scenario_of", lambda world, variant: (0, sc))
    proto = bound_map.map_aware_bound.__wrapped__("small", *bound)
    ours = method_bound(sc, bound)[MAP_BOUND_COLUMN].to_numpy()
    np.testing.assert_allclose(ours, proto, rtol=1e-12, atol=0)


SWEEP = """
name: mapbound
seed: 2424
runs: 3
methods: [tight-dvl, loose-dvl, pmf-dvl]
scenario: {particles: 300, duration_s: 200}
tables:
  map_resolution: {map_resolution_m: [10]}
"""


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    from tanbench.runner.engine import run_sweep
    from tanbench.sweep import parse_sweep

    out = tmp_path_factory.mktemp("mapbound") / "res"
    run_sweep(parse_sweep(SWEEP), out, workers=1, series="none", progress=False, echo=lambda *a, **k: None,
              note=lambda *a, **k: None)
    return out


def test_a_sweeps_run_table_carries_both_bounds(swept):
    import tanbench.results as tr

    runs = tr.load(swept, status="ok")
    assert set(NEW) <= set(runs.columns)
    with_bound = runs[runs["method"] != "pmf-dvl"]
    converged = with_bound[with_bound["rmse_after_convergence_m"].notna()]
    assert len(converged) >= 4
    assert (converged["pcrb_map_after_convergence_m"] >= converged["pcrb_after_convergence_m"]).all()
    np.testing.assert_array_equal(converged["rmse_pcrb_map_ratio"],
                                  converged["rmse_after_convergence_m"] / converged["pcrb_map_after_convergence_m"])
    assert (converged["rmse_pcrb_map_ratio"] <= converged["rmse_pcrb_ratio"]).all()
    assert runs.loc[runs["method"] == "pmf-dvl", list(NEW)].isna().all().all()  # no bound model: NaN, as the PCRB's


def _as_before(out: Path) -> None:
    """Rewrite every run file of ``out`` without the new columns, metadata kept: a directory written before."""
    from tanbench import store

    for path in store.run_files(out):
        table = pq.read_table(path)
        meta = store.read_meta(path)
        store.write_table(table.drop_columns([c for c in NEW if c in table.column_names]), path, meta)


def test_a_directory_written_before_is_read_checked_and_resumed(swept, tmp_path):
    import shutil

    import tanbench.results as tr
    from tanbench.check import CheckOptions, compare
    from tanbench.runner.engine import run_sweep
    from tanbench.sweep import load_results_sweep, parse_sweep

    old = tmp_path / "old"
    shutil.copytree(swept, old)
    _as_before(old)
    runs = tr.load(old)
    assert not set(NEW) & set(runs.columns)
    tables = tr.sweep_tables(runs, load_results_sweep(old))
    assert tables["map_resolution"]["n_runs"].eq(3).all()
    result = compare(swept, old, CheckOptions(margin_abs=0.0, min_runs=1))  # new against old: the same runs
    assert len(result.table) and not result.regressed and not result.missing_runs
    # resume: the stored runs are reused (their columns are what the code makes now), the new run carries both
    report = run_sweep(parse_sweep(SWEEP.replace("runs: 3", "runs: 4")), old, workers=1, series="none",
                       progress=False, echo=lambda *a, **k: None, note=lambda *a, **k: None)
    assert report.finished == 1 and not report.errors
    after = tr.load(old, status="ok")
    fresh = tr.load(swept, status="ok")
    assert after.groupby("method")["run"].nunique().eq(4).all()
    kept = after[after["run"] < 3].sort_values(["method", "run"]).reset_index(drop=True)
    assert kept[list(NEW)].isna().all().all()
    same = ["final_horizontal_error_m", "rmse_after_convergence_m", "pcrb_after_convergence_m", "rmse_pcrb_ratio"]
    np.testing.assert_array_equal(kept[same], fresh.sort_values(["method", "run"]).reset_index(drop=True)[same])
    new_run = after[(after["run"] == 3) & (after["method"] != "pmf-dvl")]
    assert new_run["pcrb_map_after_convergence_m"].notna().any()


def test_merging_an_older_task_file_after_newer_ones_keeps_the_new_columns(tmp_path):
    """A session killed before its cell was merged leaves task files without the new columns; a later session's
    files, merged with them, keep their values whatever the files' order (the old rows read as null)."""
    from tanbench import store
    from tanbench.schema import rows_table

    meta = store.provenance("name: s\n", "s", 1)
    row = {"sweep": "s", "method": "tight-dvl", "seed": 1, "filter_seed": 2, "status": "ok",
           "final_horizontal_error_m": 1.5, "pcrb_map_after_convergence_m": 0.8, "rmse_pcrb_map_ratio": 1.3}
    new = rows_table([{**row, "run": 0}])
    old = rows_table([{**row, "run": 1}])
    store.write_table(new, store.run_file(tmp_path, "c0", 0), meta)
    store.write_table(old.drop_columns(list(NEW)), store.run_file(tmp_path, "c0", 1), meta)
    store.compact_cells(tmp_path, ["c0"])
    merged = store.read_parquet(store.cell_dir(tmp_path / "runs", "c0") / store.MERGED_RUNS)
    assert merged["final_horizontal_error_m"].tolist() == [1.5, 1.5]
    assert merged["pcrb_map_after_convergence_m"].iloc[0] == 0.8 and np.isnan(merged["rmse_pcrb_map_ratio"].iloc[1])
