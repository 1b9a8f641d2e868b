"""The sweep engine through the CLI: outputs, shared cells, determinism, plan/validate/tables, reuse, failures.

Every sweep here is tiny (60-80 particles, 60 s runs, 3 runs per cell) and runs through
``python -m tanbench.cli`` in a subprocess, as a user would run it. The base sweep has 2 worker
processes (1 worker and a Dask cluster must reproduce it); the tests about reuse, --force, --runs
and failures run their sweeps with 1 worker process (a worker's start-up is most of a tiny
sweep's cost, and none of them is about how tasks are spread over workers).
"""

from __future__ import annotations

import io
import json
import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
import yaml

from sweep_support import (
    counted,
    METHODS, ROOT, RUN_COLUMNS, TABLE_COLUMNS, assert_same_runs, cli, load_tables, sweep_dict, write_sweep,
)
from tanbench import results
from tanbench import store
from tanbench.sweep import load_sweep, parse_sweep

N_CELLS = 3  # map_resolution {10, 20} x particles {60, 80}, the (10, 60) cell shared
RUNS = 3
N_TASKS = N_CELLS * RUNS
PROVENANCE_KEYS = {"schema_version", "sweep", "sweep_yaml", "root_seed", "tanbench_version", "numpy_version",
                   "numba_version", "created"}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """The tiny sweep run once with 2 workers: (sweep file, results directory, completed process)."""
    root = tmp_path_factory.mktemp("base")
    sweep = write_sweep(root / "tiny.yaml", sweep_dict())
    out = root / "out"
    proc = cli("run", sweep, "--out", out, "--workers", 2, "-q")
    assert proc.returncode == 0, proc.stderr
    return sweep, out, proc


def run_indices(runs: pd.DataFrame) -> set[tuple]:
    """The distinct sorted run indices over (cell, method) groups."""
    return {tuple(sorted(g)) for _, g in runs.groupby(["cell_id", "method"])["run"]}


def load_sweep_text(data):
    """A Sweep parsed from a dict (no file)."""
    return parse_sweep(yaml.safe_dump(data))


def copy_results(base, tmp_path):
    """A private copy of the base sweep file and results (for tests that change them)."""
    sweep, out, _ = base
    new_sweep = shutil.copy(sweep, tmp_path / sweep.name)
    new_out = tmp_path / "out"
    shutil.copytree(out, new_out)
    return new_sweep, new_out


def test_run_writes_pandas_readable_results(base):
    """A CLI run writes runs/, series/summary.parquet and tables/*.parquet|.md, each one pandas line."""
    sweep, out, proc = base
    assert f"{counted(N_TASKS)} run, {counted(0)} already done" in proc.stdout
    runs = pd.read_parquet(out / "runs")
    assert set(RUN_COLUMNS) <= set(runs.columns)
    assert len(runs) == N_CELLS * len(METHODS) * RUNS
    assert (runs["status"] == "ok").all() and (runs["error"] == "").all()
    assert run_indices(runs) == {(0, 1, 2)}
    assert runs["cell_id"].nunique() == N_CELLS  # the Hive partition becomes a column
    loaded = results.load(out)
    pd.testing.assert_frame_equal(loaded, runs.astype({"cell_id": str})[loaded.columns])

    summary = pd.read_parquet(out / "series" / "summary.parquet")
    assert {"cell_id", "method", "t", "n_runs", "horizontal_error_m_mean"} <= set(summary.columns)
    assert set(summary["cell_id"]) == set(runs["cell_id"])
    assert (summary["n_runs"] == RUNS).all()

    tables = load_tables(out)
    assert set(tables) == {"map_resolution", "particles"}
    for name, varied in (("map_resolution", "map_resolution_m"), ("particles", "particles")):
        table = tables[name]
        assert set(TABLE_COLUMNS) | {varied} <= set(table.columns)
        assert len(table) == 2 * len(METHODS) and (table["n_runs"] == RUNS).all()
        assert (out / "tables" / f"{name}.md").read_text().startswith(f"### {name}")


def test_provenance_in_every_parquet_schema(base):
    """Run, series and table files carry the sweep YAML, root seed and versions under b"tanbench"."""
    sweep, out, _ = base
    files = [*sorted((out / "runs").glob("*/*.parquet"))[:2], out / "series" / "summary.parquet",
             *sorted((out / "tables").glob("*.parquet"))]
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    for path in files:
        meta = json.loads(pq.read_schema(path).metadata[b"tanbench"])
        assert PROVENANCE_KEYS <= set(meta), path
        assert meta["sweep_yaml"] == sweep.read_text()
        assert meta["root_seed"] == sweep_dict()["seed"] and meta["sweep"] == "tiny"
        assert meta["numpy_version"] == np.__version__ and meta["numba_version"]
        assert re.match(r"\d{4}-\d\d-\d\dT", meta["created"])
        if head:  # the code's git revision, from a git checkout (a fresh clone is one)
            assert meta["git_revision"].split("-")[0] == head, (meta["git_revision"], head)


def test_cells_shared_by_tables_run_once(base):
    """A cell reached from two tables is one cell, run once, listing both tables."""
    sweep, out, _ = base
    plan = cli("plan", sweep, "--out", out)
    assert f"{N_CELLS} cell(s) x 3 method(s) x {RUNS} run(s) = {N_CELLS * 3 * RUNS} runs in {N_TASKS} task(s)" \
        in plan.stdout
    from tanbench.runner.plan import build_tasks
    from tanbench.runner.resume import ResumeState

    swept = load_sweep(sweep)
    assert len(ResumeState.read(swept, out).done(build_tasks(swept, False), need_series=True)) == N_TASKS
    # when the session ended, each cell's task files were merged into one file
    assert len(list((out / "runs").glob("*/runs.parquet"))) == N_CELLS
    assert not list((out / "runs").glob("*/run-*.parquet"))
    runs = results.load(out)
    shared = runs[(runs["map_resolution_m"] == 10) & (runs["particles"] == 60)]
    assert shared["cell_id"].nunique() == 1 and len(shared) == len(METHODS) * RUNS
    assert set(shared["tables"]) == {"map_resolution,particles"}
    tables = load_tables(out)
    row = ["method", "n_runs", "mean_final_error_m", "min_final_error_m", "max_final_error_m"]
    a = tables["map_resolution"].query("map_resolution_m == 10")[row].reset_index(drop=True)
    b = tables["particles"].query("particles == 60")[row].reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b)


@pytest.mark.parametrize("how", [["--workers", "1"], ["--scheduler", "local-dask", "--workers", "2"]],
                         ids=["1-worker", "dask-local-cluster"])
def test_results_do_not_depend_on_workers_or_executor(base, tmp_path, how):
    """1 worker and a Dask LocalCluster give the 2-worker results exactly (wall times aside)."""
    sweep, out, _ = base
    other = tmp_path / "out"
    proc = cli("run", sweep, "--out", other, "-q", *how)
    assert proc.returncode == 0, proc.stderr
    assert_same_runs(results.load(other), results.load(out))
    for name, table in load_tables(out).items():
        pd.testing.assert_frame_equal(load_tables(other)[name], table)
    pd.testing.assert_frame_equal(pd.read_parquet(other / "series" / "summary.parquet"),
                                  pd.read_parquet(out / "series" / "summary.parquet"))


def test_plan_shows_cells_progress_and_estimate(base, tmp_path):
    """`plan` lists cells x methods x runs, 0/N done before a run and N/N after, and a time estimate."""
    sweep, out, _ = base
    before = cli("plan", sweep, "--out", tmp_path / "fresh", "--workers", 2)
    assert before.returncode == 0, before.stderr
    assert before.stdout.count(f"0/{RUNS} done") == N_CELLS
    assert re.search(rf"to do: {N_TASKS} tasks \({N_TASKS * 3} runs\), about \d+ s on 2 worker", before.stdout)
    after = cli("plan", sweep, "--out", out)
    assert after.stdout.count(f"{RUNS}/{RUNS} done") == N_CELLS
    assert "to do: nothing, every task is stored in" in after.stdout
    assert not (tmp_path / "fresh").exists()  # planning writes nothing


def test_validate_accepts_a_good_file(base):
    """`validate` says ok (cells, methods, runs) on a good sweep file."""
    sweep, _, _ = base
    proc = cli("validate", sweep)
    assert proc.returncode == 0 and proc.stderr == ""
    assert f"ok ({N_CELLS} cell(s), 3 method(s), {RUNS} run(s) per cell)" in proc.stdout


def test_tables_command_prints_csv_and_markdown(base):
    """`tables DIR --format csv` is one parseable CSV of every table; `--format md` prints each table."""
    _, out, _ = base
    csv = cli("tables", out, "--format", "csv")
    assert csv.returncode == 0, csv.stderr
    df = pd.read_csv(io.StringIO(csv.stdout))
    stored = pd.concat(load_tables(out).values(), ignore_index=True)
    assert len(df) == len(stored) and set(df["table"]) == {"map_resolution", "particles"}
    np.testing.assert_allclose(df["mean_final_error_m"], stored["mean_final_error_m"], rtol=1e-9)
    md = cli("tables", out, "--format", "md")
    assert md.returncode == 0, md.stderr
    assert "### map_resolution" in md.stdout and "### particles" in md.stdout
    assert md.stdout.count("| tight-sbe |") == 4


def test_changed_cell_gets_new_id_and_old_results_leave_the_tables(base, tmp_path):
    """Editing a table's value computes a new cell (run afresh); the old cell's runs leave the tables."""
    sweep, out = copy_results(base, tmp_path)
    old_ids = set(results.load(out)["cell_id"])
    edited = sweep_dict(tables={"map_resolution": {"map_resolution_m": [10, 30]}, "particles": {"particles": [60, 80]}})
    write_sweep(sweep, edited)
    new_ids = {c.cell_id for c in load_sweep(sweep).cells}
    assert len(new_ids - old_ids) == 1
    plan = cli("plan", sweep, "--out", out)
    assert plan.stdout.count(f"0/{RUNS} done") == 1 and plan.stdout.count(f"{RUNS}/{RUNS} done") == 2
    proc = cli("run", sweep, "--out", out, "--workers", 1, "-q")
    assert proc.returncode == 0, proc.stderr
    assert f"{counted(RUNS)} run, {counted(N_TASKS - RUNS)} already done" in proc.stdout
    tables = load_tables(out)
    assert set(tables["map_resolution"]["map_resolution_m"]) == {10.0, 30.0}
    assert (tables["map_resolution"]["n_runs"] == RUNS).all()


def test_changing_a_hidden_setting_reruns_every_cell(base, tmp_path):
    """A filter setting that no table shows still changes every cell id: nothing stale is reused."""
    sweep, out = copy_results(base, tmp_path)
    before = load_tables(out)["map_resolution"]
    write_sweep(sweep, sweep_dict(scenario={"filter": {"ess_threshold": 0.3}}))
    proc = cli("run", sweep, "--out", out, "--workers", 1, "-q")
    assert proc.returncode == 0, proc.stderr
    assert f"{counted(N_TASKS)} run, {counted(0)} already done" in proc.stdout
    after = load_tables(out)["map_resolution"]
    assert (after["n_runs"] == RUNS).all()  # only the new cells' runs, not old + new
    assert not np.allclose(after["mean_final_error_m"], before["mean_final_error_m"])


def test_force_recomputes_identically(base, tmp_path):
    """`--force` recomputes every task (files rewritten) and gets the same results."""
    sweep, out = copy_results(base, tmp_path)
    before = results.load(out)
    some_file = sorted((out / "runs").glob("*/runs.parquet"))[0]
    stamp = some_file.stat().st_mtime_ns
    proc = cli("run", sweep, "--out", out, "--workers", 1, "-q", "--force")
    assert proc.returncode == 0, proc.stderr
    assert f"{counted(N_TASKS)} run, {counted(0)} already done" in proc.stdout
    assert some_file.stat().st_mtime_ns != stamp
    assert_same_runs(results.load(out), before)


def test_runs_option_overrides_the_file(base, tmp_path):
    """`--runs 5` adds runs 3 and 4 to every cell, reusing runs 0-2."""
    sweep, out = copy_results(base, tmp_path)
    before = results.load(out)
    plan = cli("plan", sweep, "--out", out, "--runs", 5)
    assert f"x 5 run(s) = {N_CELLS * 3 * 5} runs in {N_CELLS * 5} task(s)" in plan.stdout
    proc = cli("run", sweep, "--out", out, "--workers", 1, "-q", "--runs", 5)
    assert proc.returncode == 0, proc.stderr
    assert f"{counted(N_CELLS * 2)} run, {counted(N_TASKS)} already done" in proc.stdout
    runs = results.load(out)
    assert run_indices(runs) == {(0, 1, 2, 3, 4)}
    assert_same_runs(runs[runs["run"] < RUNS], before)
    assert (load_tables(out)["particles"]["n_runs"] == 5).all()


# A failure injected into the worker processes: ``sitecustomize`` is imported at start-up
# by every Python process that has its directory on PYTHONPATH: the CLI, so its forked workers too (or
# spawned ones, which import it themselves).
FAULT = '''
import tanbench.methods as _run

_real = _run.run_method


def _failing(scenario, method, vehicle, seed):
    if scenario.particles == 80 and method == "tight-sbe":
        raise RuntimeError("injected failure for the test")
    return _real(scenario, method, vehicle, seed)


_run.run_method = _failing
'''


def test_failed_run_is_recorded_and_the_rest_finish(tmp_path):
    """A method failing in the workers is stored as status "error" with its text; the rest finish; exit 1."""
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(FAULT)
    sweep = write_sweep(tmp_path / "tiny.yaml", sweep_dict())
    out = tmp_path / "out"
    proc = cli("run", sweep, "--out", out, "--workers", 1, "-q", extra_path=hook)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert f"{RUNS} run(s) failed (recorded with their errors; rerun to retry)" in proc.stderr
    assert "injected failure for the test" in proc.stderr
    runs = pd.read_parquet(out / "runs")
    bad = runs[runs["status"] == "error"]
    assert len(bad) == RUNS and set(bad["method"]) == {"tight-sbe"} and (bad["particles"] == 80).all()
    assert bad["error"].str.contains("RuntimeError: injected failure for the test").all()
    assert bad["final_horizontal_error_m"].isna().all()
    good = runs[runs["status"] == "ok"]
    assert len(good) == N_CELLS * len(METHODS) * RUNS - RUNS and good["final_horizontal_error_m"].notna().all()
    table = load_tables(out)["particles"].set_index(["particles", "method"])
    assert table.loc[(80, "tight-sbe"), "n_failed"] == RUNS and table.loc[(80, "tight-sbe"), "n_runs"] == 0
    assert table.loc[(80, "tight-dvl"), "n_runs"] == RUNS

    retry = cli("run", sweep, "--out", out, "--workers", 1, "-q")  # no fault now: the failed tasks rerun
    assert retry.returncode == 0, retry.stderr
    assert f"{counted(RUNS)} run, {counted(N_TASKS - RUNS)} already done" in retry.stdout
    assert (results.load(out)["status"] == "ok").all()


def test_execute_turns_exceptions_into_error_rows(monkeypatch):
    """`tasks.execute` never raises: a failing method gives an error row, the other methods still run."""
    import tanbench.methods as run_module
    from tanbench.runner.tasks import Task, execute

    sweep = load_sweep_text(sweep_dict(tables={}))
    cell = sweep.cells[0]
    task = Task(cell.cell_id, json.dumps(cell.scenario.normalized()), 0, tuple(METHODS), 1, False)
    real = run_module.run_method

    def failing(scenario, method, vehicle, seed):
        if method == "loose-dvl":
            raise ValueError("boom")
        return real(scenario, method, vehicle, seed)

    monkeypatch.setattr("tanbench.runner.tasks.run_method", failing)  # imported at the top there
    result = execute(task)
    status = {r["method"]: (r["status"], r["error"]) for r in result.rows}
    assert status["tight-dvl"] == ("ok", "") and status["tight-sbe"] == ("ok", "")
    assert status["loose-dvl"][0] == "error" and status["loose-dvl"][1].startswith("ValueError: boom")
