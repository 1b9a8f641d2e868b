"""The faster paths around the filters give what the slower ones gave: the same files, the same frames."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from tanbench import store
from tanbench.runner.engine import SeriesWritten, series_table
from tanbench.runner.tasks import TaskResult
from tanbench.schema import SERIES_COLUMNS, rows_table


def _result(k: int = 50, methods=("tight-dvl", "tight-sbe", "loose-dvl")) -> TaskResult:
    rng = np.random.default_rng(3)
    series = {}
    for m in methods:
        s = {c: rng.standard_normal(k).astype(np.float32) for c in SERIES_COLUMNS}
        s[SERIES_COLUMNS[-1]][::7] = np.nan
        series[m] = s
    return TaskResult(cell_id="abc", run=4, rows=[], series=series)


def _pandas_table(result: TaskResult) -> pa.Table:
    frames = [pd.DataFrame({"run": result.run, "method": m, **s}) for m, s in result.series.items()]
    return pa.Table.from_pandas(pd.concat(frames, ignore_index=True), preserve_index=False)


def test_series_table_is_the_table_pandas_made(tmp_path):
    """Built from the arrays, the series table equals the pandas-made one (types, values, nulls), and
    the files written from both are byte for byte the same."""
    result = _result()
    fast, slow = series_table(result), _pandas_table(result)
    assert fast.replace_schema_metadata(None).equals(slow.replace_schema_metadata(None))
    assert fast.column(SERIES_COLUMNS[-1]).null_count == slow.column(SERIES_COLUMNS[-1]).null_count > 0
    meta = {"schema": "x"}
    store.write_table(fast, tmp_path / "fast.parquet", meta)
    store.write_table(slow, tmp_path / "slow.parquet", meta)
    assert (tmp_path / "fast.parquet").read_bytes() == (tmp_path / "slow.parquet").read_bytes()


def test_kept_series_convert_to_the_frame_read_back(tmp_path, monkeypatch):
    """The series summary's input from memory is the frame the file reads back as."""
    monkeypatch.setattr(store, "read_meta", lambda path: {})
    table = series_table(_result())
    path = tmp_path / "run-00004.parquet"
    store.write_table(table, path, {"schema": "x"})
    kept = SeriesWritten()
    kept.keep(path, table)
    pd.testing.assert_frame_equal(kept.tables[path].to_pandas(), store.read_parquet(path), check_exact=True)


def test_series_kept_up_to_a_memory_budget():
    table = series_table(_result())
    kept = SeriesWritten(max_bytes=int(table.nbytes * 1.5))
    kept.keep("a", table)
    kept.keep("b", table)
    assert list(kept.tables) == ["a"]


def test_clopper_pearson_is_scipy_stats_beta_ppf_to_the_bit():
    """The tables' intervals come from scipy.stats.beta.ppf's own ufunc (no scipy.stats import)."""
    from scipy import stats

    from tanbench.inference import clopper_pearson

    a = (1.0 - 0.95) / 2.0  # as clopper_pearson computes it at its default level
    for n in (1, 2, 3, 7, 30, 80, 90, 240, 1650):
        for k in sorted({0, 1, 2, n // 3, n // 2, n - 1, n} & set(range(n + 1))):
            lo, hi = clopper_pearson(k, n)
            assert lo == (0.0 if k == 0 else float(stats.beta.ppf(a, k, n - k + 1)))
            assert hi == (1.0 if k == n else float(stats.beta.ppf(1 - a, k + 1, n - k)))


def test_tables_and_runner_import_without_scipy_stats():
    """scipy.stats (about a second of a sweep's start-up) is imported only by the verdicts."""
    import subprocess
    import sys

    code = ("import sys, tanbench.cli, tanbench.runner.engine, tanbench.results, tanbench.runner.tasks; "
            "print('scipy.stats' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip() == "False"


def test_task_seeds_are_the_seed_functions():
    """A worker's keys computed once per cell give the seeds of vehicle_seed and filter_seed."""
    from tanbench.config import Scenario
    from tanbench.runner.seeds import filter_seed, keyed_filter_seed, keyed_vehicle_seed, vehicle_seed
    from tanbench.runner.tasks import cell_scenario
    from tanbench.methods.registry import get

    text = Scenario(map_resolution_m=20, sampling_time_s=5).model_dump_json()
    scenario, pairing_key, cell_key = cell_scenario(text)
    assert cell_scenario(text)[0] is scenario
    for run in (0, 7):
        assert keyed_vehicle_seed(424242, pairing_key, run).spawn_key == vehicle_seed(424242, scenario, run).spawn_key
        for method in ("tight-dvl", "loose-dvl"):
            got = keyed_filter_seed(424242, cell_key, get(method).seed_id, run)
            assert got.spawn_key == filter_seed(424242, scenario, method, run).spawn_key


def test_yardstick_is_timed_from_its_file_or_skipped(tmp_path):
    """`make bench` times tight-dvl against the yardstick file's measure() in the same process;
    a missing file is skipped (None), never an error."""
    from tanbench.bench import yardstick_ns

    assert yardstick_ns(tmp_path / "absent.py") is None
    stick = tmp_path / "stick.py"
    stick.write_text("def measure(M=3000, steps=1190, seed=0):\n    return 1000.0 / M\n")
    assert yardstick_ns(stick, particles=500) == 2.0


def _task_rows(run: int, extra: bool) -> list[dict]:
    rows = []
    for i, method in enumerate(("tight-dvl", "tight-sbe", "loose-dvl")):
        row = {"sweep": "s", "noise_m": 1.0, "method": method, "run": run, "seed": 10 + run, "filter_seed": i,
               "final_horizontal_error_m": float("nan") if i == 2 else 1.5 * run + i, "status": "ok",
               "error": "", "wall_s": 0.25, "sensors.beam_azimuths_deg": [45.0, 135.0]}
        if extra:  # a column outside the known ones (inferred): another schema
            row["method_options.tight-dvl.k"] = 3
        rows.append(row)
    return rows


def test_cells_merged_from_kept_rows_are_the_files_merged(tmp_path, monkeypatch):
    """A cell's task files merged from the rows this session kept (compact_cells' ``kept``) give the
    merged file that reading them back gives, byte for byte; a file not kept is read."""
    meta = {"schema_version": store.SCHEMA_VERSION, store.CODE_META: {"user.mod:f": "1"}}
    merged, reads = [], []
    read_table = store.pq.read_table
    monkeypatch.setattr(store.pq, "read_table", lambda path, *a, **k: reads.append(path) or read_table(path, *a, **k))
    for name, keep in (("files", False), ("kept", True)):
        out = tmp_path / name
        written = SeriesWritten()
        for run in range(5):
            rows = _task_rows(run, extra=run in (2, 3))
            path = store.run_file(out, "abc", run)
            store.write_table(rows_table(rows), path, meta, **store.TASK_ROWS)
            if keep and run != 4:
                written.keep_rows(path, rows, meta)
        reads.clear()
        store.compact_cells(out, ["abc"], written.runs if keep else None)
        assert len(reads) == (1 if keep else 5)
        merged.append((store.cell_dir(out / "runs", "abc") / store.MERGED_RUNS).read_bytes())
        assert not list(store.cell_dir(out / "runs", "abc").glob("run-*.parquet"))
    assert merged[0] == merged[1]


def test_kept_series_converted_together_are_the_files_read_back(tmp_path, monkeypatch):
    """The series summary's frames: the session's tables converted together (results._series_frames)
    give, concatenated, the frame of every file read back with its cell_id, row for row."""
    from tanbench.results import _series_frames

    monkeypatch.setattr(store, "read_meta", lambda path: {})
    files, kept = [], SeriesWritten()
    for i, (cell, methods) in enumerate([("a", ("tight-dvl", "loose-dvl")), ("a", ("tight-dvl", "loose-dvl")),
                                         ("b", ("tight-sbe",)), ("b", ("tight-dvl", "loose-dvl"))]):
        result = _result(k=20 + i, methods=methods)
        table = series_table(result)
        path = tmp_path / f"{cell}-run-{i:05d}.parquet"
        store.write_table(table, path, {"schema": "x"}, **store.TASK_SERIES)
        if i != 2:  # one file read back between kept ones
            kept.keep(path, table)
        files.append(((cell, path.name), path))
    together = pd.concat(_series_frames(files, kept.tables), ignore_index=True)
    read = pd.concat([store.read_parquet(p).assign(cell_id=c) for (c, _), p in files], ignore_index=True)
    pd.testing.assert_frame_equal(together, read, check_exact=True)
