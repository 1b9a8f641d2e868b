"""Numbers the paper report states from another committed file agree with it."""

from __future__ import annotations

import re
from pathlib import Path

from tanbench.report import FAITHFUL_CELL_PASS

ROOT = Path(__file__).resolve().parents[1]


def test_faithful_cell_pass_range_is_criterion_md_s():
    """REPORT.md's "a faithful copy passes a cell with probability A-B" is the range of the last column of
    results/criterion/CRITERION.md's cells table (each cell's smallest pass probability over the scenarios)."""
    text = (ROOT / "results" / "criterion" / "CRITERION.md").read_text()
    section = text.split("## Cells: pass probability of a faithful copy", 1)[1]
    rows = re.findall(r"^\|[^|\n]+\|[^|\n]+\|[^|\n]+\| [0-9.]+ \| [0-9.]+ \| ([0-9.]+) \|$", section, re.M)
    assert len(rows) >= 27
    cells = [float(v) for v in rows]
    assert (min(cells), max(cells)) == FAITHFUL_CELL_PASS
