"""`tanbench tables --compare-paper`: our committed tables beside the paper's published values.

The paper's numbers are package data copied from ``../shared/paper`` (checked here when
that folder is present); the side-by-side must carry them unchanged, matched row by row,
with the ratio ours / paper.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sweep_support import cli
from tanbench.paperdata import tables_3_7

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "zhou2017"
SHARED = ROOT.parent / "shared" / "paper"
PACKAGE = ROOT / "tanbench" / "paperdata"


@pytest.mark.parametrize("name", ["zhou2017_tables_3_7.csv", "zhou2017_table_9.csv", "zhou2017_scenario.yaml"])
def test_package_data_is_the_shared_copy(name):
    if not (SHARED / name).exists():
        pytest.skip(f"{SHARED} absent (the shared paper folder sits beside the project)")
    assert (PACKAGE / name).read_bytes() == (SHARED / name).read_bytes()


def test_compare_paper_matches_every_published_row():
    proc = cli("tables", RESULTS, "--compare-paper", "--format", "csv")
    assert proc.returncode == 0, proc.stderr
    side = pd.read_csv(io.StringIO(proc.stdout))
    keys = ["map_resolution_m", "noise_m", "sampling_time_s", "particles", "method"]
    paper = tables_3_7().assign(table=lambda d: "table" + d["table"].astype(str))
    merged = side.merge(paper, on=["table", *keys], suffixes=("", "_published"))
    assert len(merged) == len(paper) == 39  # 13 rows of Tables 3-7 x 3 methods, every one matched
    for stat in ("mean", "min", "max"):
        np.testing.assert_array_equal(merged[f"paper_{stat}_final_error_m"], merged[f"{stat}_final_error_m_published"])
    np.testing.assert_allclose(merged["ratio_final"], merged["mean_final_error_m"] / merged["paper_mean_final_error_m"])
    md = cli("tables", RESULTS, "--compare-paper").stdout
    assert "| table3 | A | 10.0 | 1.0 | 1.0 | 3000 | tight-dvl |" in md and "| 9.7 | 0.3 | 20.6 |" in md
