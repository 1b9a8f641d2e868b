"""Results files: the compact footer, and compaction rewriting a cell stored in the older format."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from tanbench import store


def frame(n=60):
    rng = np.random.default_rng(3)
    return pd.DataFrame({"method": np.repeat(["tight-dvl", "tight-sbe", "loose-dvl"], n // 3),
                         "run": np.tile(np.arange(n // 3), 3),
                         "final_horizontal_error_m": rng.random(n),
                         "diverged": rng.random(n) > 0.9,
                         **{f"sensors.c{i}": np.full(n, float(i)) for i in range(100)}})


def test_compact_footer_has_only_tanbench_metadata(tmp_path):
    path = tmp_path / "x.parquet"
    store.write_parquet(frame(), path, {"sweep": "s", "schema_version": store.SCHEMA_VERSION})
    assert set(pq.read_metadata(path).metadata) == {store.META_KEY}  # no pandas metadata, no Arrow schema
    assert store.is_compact_format(path) and store.read_meta(path)["sweep"] == "s"
    pd.testing.assert_frame_equal(store.read_parquet(path), frame())


def test_compaction_rewrites_an_older_cell_rows_unchanged(tmp_path):
    out = tmp_path / "res"
    path = store.cell_dir(out / "runs", "abc") / "runs.parquet"
    path.parent.mkdir(parents=True)
    rows = frame().sort_values(["run", "method"], kind="stable").reset_index(drop=True)  # a compacted cell's order
    old = pa.Table.from_pandas(rows, preserve_index=False)  # the older writer: pandas metadata, statistics
    old = old.replace_schema_metadata({**old.schema.metadata, store.META_KEY: json.dumps({"sweep": "s", "schema_version": store.SCHEMA_VERSION}).encode()})
    pq.write_table(old, path, compression="zstd")
    before, size = store.read_parquet(path), path.stat().st_size
    assert not store.is_compact_format(path)
    store.compact_cells(out, ["abc"])
    assert store.is_compact_format(path) and path.stat().st_size < 0.8 * size
    pd.testing.assert_frame_equal(store.read_parquet(path), before)
    assert store.read_meta(path)["sweep"] == "s"
    mtime = path.stat().st_mtime_ns
    store.compact_cells(out, ["abc"])  # already compact: left alone
    assert path.stat().st_mtime_ns == mtime
