"""Shared by the regression check's tests (test_check.py, test_verdicts.py): a writable copy of the
committed CI baseline and a way to rewrite its stored runs."""

from __future__ import annotations

import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tanbench import store

BASELINE = Path(__file__).resolve().parents[1] / "results" / "ci-baseline"


@pytest.fixture()
def copy_of_baseline(tmp_path) -> Path:
    """A writable copy of the committed CI baseline."""
    dst = tmp_path / "new"
    shutil.copytree(BASELINE, dst, ignore=shutil.ignore_patterns(".work"))
    return dst


def rewrite_runs(directory: Path, fn) -> None:
    """Apply ``fn(df, cell_id)`` to every stored runs file's rows, keeping its metadata (a file left
    without rows is removed)."""
    for path in store.run_files(directory):
        meta = store.read_meta(path)
        df = fn(pq.read_table(path).to_pandas(), store.cell_of(path))
        if len(df):
            store.write_parquet(df, path, meta)
        else:
            path.unlink()
