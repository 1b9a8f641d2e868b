"""The anatomy of a profile: the effect of switching one mechanism at a time, with intervals.

An anatomy sweep (``configs/zhou2017-anatomy.yaml``) names its tables
``<cell>__<switch>``: ``<cell>__literal`` is the baseline of a key cell, every other
``<cell>__<switch>`` is the same cell with one mechanism switched. For each key cell,
switch and method, :func:`anatomy_table` gives the mean final horizontal error of both
and the mean difference (switched minus baseline) with a 95 % t interval:

* paired by run where the two cells share their vehicle data (same world key: every
  filter switch, so each run's difference removes the run-to-run variation of the
  vehicle data);
* unpaired (Welch) where the switch changes the world (the terrain).

Beside the statistic (fixed in docs/model.md section 10.1), each row counts the runs
that ended lost (the run's ``diverged`` flag: final error above the sweep's divergence
threshold) in both cells, since a few lost runs carry most means here.

Any ablation sweep laid out the same way is read alike: ``baseline`` names its baseline tables
(``<cell>__<baseline>``; ``configs/tempering.yaml`` uses ``off``) and ``column`` the per-run
metric compared (the final horizontal error unless given).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

BASELINE = "literal"
SEPARATOR = "__"
LEVEL = 0.95
ANATOMY_COLUMNS = ("cell", "switch", "method", "n", "baseline_mean_m", "switched_mean_m", "diff_mean_m",
                   "ci_low_m", "ci_high_m", "paired", "baseline_lost", "switched_lost", "runs")


def difference_interval(switched: pd.Series, baseline: pd.Series, paired: bool, level: float = LEVEL):
    """(n, mean difference, low, high): paired t on common runs, or Welch's t on all runs; a run whose value
    is missing (NaN: a metric undefined for it) is left out, with its pair when paired, and n counts what is left."""
    switched, baseline = switched.astype(float), baseline.astype(float)
    if paired:
        a, b = switched.align(baseline, join="inner")
        d = (a - b).to_numpy(float)
        d = d[~np.isnan(d)]
        n = d.size
        if n < 2:
            return n, float(d.mean()) if n else np.nan, np.nan, np.nan
        half = stats.t.ppf(0.5 + level / 2, n - 1) * d.std(ddof=1) / np.sqrt(n)
        return n, float(d.mean()), float(d.mean() - half), float(d.mean() + half)
    a, b = switched.dropna().to_numpy(float), baseline.dropna().to_numpy(float)
    n = min(a.size, b.size)
    if a.size < 2 or b.size < 2:
        return n, float(a.mean() - b.mean()) if n else np.nan, np.nan, np.nan
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    se = np.sqrt(va + vb)
    dof = (va + vb) ** 2 / (va**2 / (a.size - 1) + vb**2 / (b.size - 1)) if se > 0 else 1.0
    diff = float(a.mean() - b.mean())
    half = stats.t.ppf(0.5 + level / 2, dof) * se
    return n, diff, float(diff - half), float(diff + half)


def anatomy_table(runs: pd.DataFrame, sweep, column: str = "final_horizontal_error_m",
                  baseline: str = BASELINE) -> pd.DataFrame:
    """One row per (key cell, switch, method): ``column``'s means and their difference; see the module
    docstring. ``baseline``: the switch the others are compared with."""
    cell_of = {}
    for cell in sweep.cells:
        for t in cell.tables:
            cell_of[t] = cell
    ok = runs[runs["status"] == "ok"]
    rows = []
    for table in sweep.table_designs:
        if SEPARATOR not in table:
            continue
        name, switch = table.split(SEPARATOR, 1)
        base_table = f"{name}{SEPARATOR}{baseline}"
        if switch == baseline or base_table not in cell_of:
            continue
        base, other = cell_of[base_table], cell_of[table]
        paired = base.scenario.world_key() == other.scenario.world_key()
        for method in sweep.spec.methods:
            def rows_of(cell):
                return ok[(ok["cell_id"] == cell.cell_id) & (ok["method"] == method)].set_index("run").sort_index()

            def lost(sel):
                return int(sel["diverged"].astype(bool).sum()) if "diverged" in sel else -1

            rb, rs = rows_of(base), rows_of(other)
            b, s = rb[column], rs[column]
            n, diff, lo, hi = difference_interval(s, b, paired)
            rows.append(dict(cell=name, switch=switch, method=method, n=n, baseline_mean_m=float(b.mean()),
                             switched_mean_m=float(s.mean()), diff_mean_m=diff, ci_low_m=lo, ci_high_m=hi,
                             paired=paired, baseline_lost=lost(rb), switched_lost=lost(rs), runs=min(len(rb), len(rs))))
    return pd.DataFrame(rows, columns=list(ANATOMY_COLUMNS))


def anatomy_markdown(table: pd.DataFrame, baseline: str = BASELINE, switch_to: str = "switch to recommended",
                     unit: str = "m", digits: int = 1) -> str:
    """The anatomy as one Markdown table per key cell: methods side by side; ``baseline`` and
    ``switch_to`` word the header, ``unit`` the column's; ``digits`` after the point."""
    out = []
    for cell, part in table.groupby("cell", sort=False):
        methods = list(dict.fromkeys(part["method"]))
        out += [f"**{cell}**", "",
                f"| {switch_to} | " + " | ".join(f"{m}: {baseline} -> switched, diff [95 % CI] ({unit}); "
                                                         f"lost runs"
                                                         for m in methods) + " |",
                "|---|" + "---|" * len(methods)]
        for switch, rows in part.groupby("switch", sort=False):
            cells = []
            for m in methods:
                r = rows[rows["method"] == m].iloc[0]
                ci = "" if np.isnan(r["ci_low_m"]) else f" [{r['ci_low_m']:+.{digits}f}, {r['ci_high_m']:+.{digits}f}]"
                lost = "" if r["baseline_lost"] < 0 else f"; {r['baseline_lost']} -> {r['switched_lost']}"
                left_out = f" ({r['n']} of {r['runs']} runs: the others undefined)" if r["n"] < r["runs"] else ""
                cells.append(f"{r['baseline_mean_m']:.{digits}f} -> {r['switched_mean_m']:.{digits}f}, "
                             f"{r['diff_mean_m']:+.{digits}f}{ci}{'' if r['paired'] else ' (unpaired)'}{left_out}{lost}")
            out.append(f"| {switch} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)
