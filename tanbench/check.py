"""Regression check of error statistics: is NEW worse than BASELINE, cell by cell?

Cells are matched by their scenario (every scenario column the two results share, so
results from another tanbench version match as long as the schema does; ``ignore`` names
scenario columns left out of the match, to compare cells that differ only there, e.g. the
two random streams of ``filter.random_numbers``); cells found in only one directory are
reported. For each matched (cell, method) and metric (final and
time-averaged horizontal error):

* the change in the mean with a bootstrap 95 % confidence interval (runs resampled
  jointly when paired);
* one-sided tests against a margin delta = max(rel * baseline mean, abs): "worse" tests
  NEW - BASELINE > delta, "better" tests BASELINE - NEW > delta. Where the runs share
  seeds (the same vehicle data) the test is paired (Wilcoxon signed-rank on the
  per-run differences), otherwise unpaired (Mann-Whitney U);
* Holm's correction over all comparisons, separately for "worse" and "better".

A row is "regressed" if its corrected worse-p is below alpha, "improved" if its
corrected better-p is, "unchanged" otherwise.

Missing data is a failure too: a cell, a method of a matched cell, or a (successful) run
of a matched cell and method found in only one of the directories is listed in
``missing`` and makes ``tanbench check`` exit 1 (``--allow-missing`` compares what the
two share and only reports the rest).
With ``nees`` (``tanbench check --nees``) a third metric joins: the per-run fraction of
updates whose NEES lies outside its one-run 95 % chi-square bounds
(``nees_above_95 + nees_below_95``, nominally 0.05; docs/model.md, section 9.2), with its
own absolute margin ``nees_margin_abs`` (a fraction, default 0.05): a filter whose
reported covariance stops describing its errors regresses even if its errors do not.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from tanbench.errors import TanbenchError
from tanbench.results import TABLE_SCENARIO_COLUMNS
from tanbench.schema import RESULT_COLUMNS

METRICS = {"final": "final_horizontal_error_m", "time-avg": "mean_horizontal_error_m"}
NEES_METRIC = ("nees", "nees_outside_95")


@dataclass
class CheckOptions:
    margin_rel: float = 0.10
    margin_abs: float = 1.0
    alpha: float = 0.05
    bootstrap: int = 2000
    seed: int = 0
    nees: bool = False
    nees_margin_abs: float = 0.05
    ignore: tuple[str, ...] = ()  # scenario columns left out of the cell match


@dataclass
class CheckResult:
    table: pd.DataFrame  # one row per (cell, method, metric)
    only_new: list[str]  # cells
    only_baseline: list[str]
    missing_methods: list[str] = field(default_factory=list)  # "<cell>: method m only in NEW"
    missing_runs: list[str] = field(default_factory=list)  # "<cell>, m: runs 3, 4 only in BASELINE"

    @property
    def regressed(self) -> bool:
        return bool((self.table["verdict"] == "regressed").any())

    @property
    def missing(self) -> list[str]:
        """Everything found in only one directory, one line each."""
        return ([f"cell only in NEW: {c}" for c in self.only_new]
                + [f"cell only in BASELINE: {c}" for c in self.only_baseline]
                + self.missing_methods + self.missing_runs)


def holm(p: np.ndarray) -> np.ndarray:
    """Holm-Bonferroni adjusted p-values."""
    p = np.asarray(p, dtype=float)
    m = p.size
    order = np.argsort(p)
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, (m - rank) * p[i])
        adj[i] = min(1.0, running)
    return adj


def _load(directory, nees: bool = False) -> pd.DataFrame:
    from tanbench.results import load

    runs = load(directory)
    missing = [c for c in ("method", "run", "seed", "status", *METRICS.values()) if c not in runs.columns]
    if missing:
        raise TanbenchError(f"{directory}: results lack column(s) {', '.join(missing)}; not comparable")
    if nees:
        if "nees_above_95" not in runs.columns:
            raise TanbenchError(f"{directory}: results have no NEES columns (written before tanbench stored "
                                f"them); rerun the sweep or drop --nees")
        runs = runs.assign(**{NEES_METRIC[1]: runs["nees_above_95"] + runs["nees_below_95"]})
    return runs[runs["status"] == "ok"]


def _scenario_columns(a: pd.DataFrame, b: pd.DataFrame) -> list[str]:
    return sorted((set(a.columns) & set(b.columns)) - RESULT_COLUMNS - {NEES_METRIC[1]})


def _cell_keys(runs: pd.DataFrame, cols: list[str]) -> pd.Series:
    def norm(v):
        if isinstance(v, (float, np.floating)) and float(v).is_integer():
            return int(v)
        if isinstance(v, np.generic):
            return v.item()
        return v

    return runs[cols].apply(lambda r: json.dumps([norm(v) for v in r], default=str), axis=1)


def _label(row: pd.Series) -> str:
    return ", ".join(f"{c}={row[c]:g}" if isinstance(row[c], (int, float, np.number)) else f"{c}={row[c]}"
                     for c in TABLE_SCENARIO_COLUMNS if c in row)


def _bootstrap_diff(new: np.ndarray, base: np.ndarray, paired: bool, n: int, rng) -> tuple[float, float]:
    if paired:
        d = new - base
        means = d[rng.integers(0, d.size, (n, d.size))].mean(axis=1)
    else:
        means = (new[rng.integers(0, new.size, (n, new.size))].mean(axis=1)
                 - base[rng.integers(0, base.size, (n, base.size))].mean(axis=1))
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(lo), float(hi)


def _one_sided(x: np.ndarray, y: np.ndarray, shift: float, paired: bool) -> float:
    """p-value that x - y exceeds ``shift`` (one-sided)."""
    if paired:
        d = x - y - shift
        if not np.any(d):
            return 1.0
        return float(stats.wilcoxon(d, alternative="greater", zero_method="zsplit").pvalue)
    if x.size < 2 or y.size < 2:
        return 1.0
    return float(stats.mannwhitneyu(x - shift, y, alternative="greater").pvalue)


def compare(new_dir, base_dir, options: CheckOptions | None = None) -> CheckResult:
    """Compare two results directories; see the module docstring."""
    opt = options or CheckOptions()
    new, base = _load(new_dir, opt.nees), _load(base_dir, opt.nees)
    metrics = {**METRICS, **(dict([NEES_METRIC]) if opt.nees else {})}
    cols = _scenario_columns(new, base)
    unknown = sorted(set(opt.ignore) - set(cols))
    if unknown:
        raise TanbenchError(f"--ignore {', '.join(unknown)}: not a scenario column of both directories "
                            f"(scenario columns are named as in the sweep file, e.g. filter.random_numbers)")
    cols = [c for c in cols if c not in opt.ignore]
    if not cols:
        raise TanbenchError(f"{new_dir} and {base_dir} share no scenario columns; not comparable")
    new = new.assign(_cell=_cell_keys(new, cols))
    base = base.assign(_cell=_cell_keys(base, cols))
    cells_new, cells_base = set(new["_cell"]), set(base["_cell"])

    def describe(keys, df):
        firsts = df.drop_duplicates("_cell").set_index("_cell")
        return [f"{firsts.loc[k, 'cell_id']} ({_label(firsts.loc[k])})" for k in sorted(keys)]

    rng = np.random.default_rng(opt.seed)
    rows, missing_methods, missing_runs = [], [], []
    for key in sorted(cells_new & cells_base):
        n_cell, b_cell = new[new["_cell"] == key], base[base["_cell"] == key]
        cell = f"{n_cell['cell_id'].iloc[0]} ({_label(n_cell.iloc[0])})"
        methods_new, methods_base = set(n_cell["method"]), set(b_cell["method"])
        missing_methods += [f"method {m} only in NEW: cell {cell}" for m in sorted(methods_new - methods_base)]
        missing_methods += [f"method {m} only in BASELINE: cell {cell}" for m in sorted(methods_base - methods_new)]
        for method in sorted(methods_new & methods_base):
            nm = n_cell[n_cell["method"] == method].set_index("run").sort_index()
            bm = b_cell[b_cell["method"] == method].set_index("run").sort_index()
            for side, extra in (("NEW", nm.index.difference(bm.index)), ("BASELINE", bm.index.difference(nm.index))):
                if len(extra):
                    missing_runs.append(f"{_runs_text(extra)} of {method} only in {side} (ok runs): cell {cell}")
            common = nm.index.intersection(bm.index)
            paired = len(common) >= 5 and bool((nm.loc[common, "seed"] == bm.loc[common, "seed"]).all())
            for metric, column in metrics.items():
                if paired:
                    x, y = nm.loc[common, column].to_numpy(float), bm.loc[common, column].to_numpy(float)
                else:
                    x, y = nm[column].to_numpy(float), bm[column].to_numpy(float)
                if paired:  # NaN metrics (a run without a covariance) are left out
                    keep = np.isfinite(x) & np.isfinite(y)
                    x, y = x[keep], y[keep]
                else:
                    x, y = x[np.isfinite(x)], y[np.isfinite(y)]
                if x.size == 0 or y.size == 0:
                    continue
                margin_abs = opt.nees_margin_abs if metric == NEES_METRIC[0] else opt.margin_abs
                delta = max(opt.margin_rel * float(np.mean(y)), margin_abs)
                lo, hi = _bootstrap_diff(x, y, paired, opt.bootstrap, rng)
                rows.append({
                    "cell_id": nm["cell_id"].iloc[0], "cell": _label(nm.iloc[0]), "method": method,
                    "metric": metric, "paired": paired, "n_new": int(x.size), "n_baseline": int(y.size),
                    "baseline_mean_m": float(np.mean(y)), "new_mean_m": float(np.mean(x)),
                    "change_m": float(np.mean(x) - np.mean(y)), "ci95_low_m": lo, "ci95_high_m": hi,
                    "margin_m": delta,
                    "p_worse": _one_sided(x, y, delta, paired), "p_better": _one_sided(y, x, delta, paired),
                })
    table = pd.DataFrame(rows)
    if table.empty:
        raise TanbenchError(f"{new_dir} and {base_dir} have no cell and method in common")
    table["p_worse_holm"] = holm(table["p_worse"].to_numpy())
    table["p_better_holm"] = holm(table["p_better"].to_numpy())
    table["verdict"] = np.where(table["p_worse_holm"] < opt.alpha, "regressed",
                                np.where(table["p_better_holm"] < opt.alpha, "improved", "unchanged"))
    return CheckResult(table=table, only_new=describe(cells_new - cells_base, new),
                       only_baseline=describe(cells_base - cells_new, base),
                       missing_methods=missing_methods, missing_runs=missing_runs)


def _runs_text(runs) -> str:
    """'run 3' or 'runs 0, 1, 4' (at most 10 listed)."""
    runs = [int(r) for r in runs]
    shown = ", ".join(str(r) for r in runs[:10]) + (f", ... ({len(runs)} in all)" if len(runs) > 10 else "")
    return f"run{'s' if len(runs) > 1 else ''} {shown}"


def render(result: CheckResult) -> str:
    """The compact text table `tanbench check` prints."""
    t = result.table
    lines = [f"{'verdict':10s} {'method':10s} {'metric':8s} {'baseline':>9s} {'new':>9s} {'change':>8s} "
             f"{'95% CI':>17s} {'margin':>7s} {'p(worse)':>9s} {'p(better)':>9s}  cell"]
    for _, r in t.iterrows():
        lines.append(f"{r['verdict']:10s} {r['method']:10s} {r['metric']:8s} {r['baseline_mean_m']:9.2f} "
                     f"{r['new_mean_m']:9.2f} {r['change_m']:+8.2f} [{r['ci95_low_m']:+7.2f},{r['ci95_high_m']:+7.2f}] "
                     f"{r['margin_m']:7.2f} {r['p_worse_holm']:9.2g} {r['p_better_holm']:9.2g}  {r['cell']}"
                     f"{'' if r['paired'] else ' (unpaired)'}")
    for line in result.missing:
        lines.append(f"missing: {line}")
    counts = t["verdict"].value_counts()
    lines.append(f"{counts.get('regressed', 0)} regressed, {counts.get('improved', 0)} improved, "
                 f"{counts.get('unchanged', 0)} unchanged (Holm-corrected p-values); "
                 f"{len(result.missing)} missing (cells, methods or runs in only one directory)")
    return "\n".join(lines)


def write_report(result: CheckResult, path: Path) -> None:
    """Write the comparison as .parquet, .md or .json (by extension)."""
    from tanbench.results import to_markdown

    path = Path(path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".parquet":
            result.table.to_parquet(path, index=False)
        elif suffix == ".md":
            extra = "".join(f"\n* missing: {line}" for line in result.missing)
            path.write_text(to_markdown(result.table, title="tanbench check") + extra + "\n")
        elif suffix == ".json":
            path.write_text(json.dumps({"rows": json.loads(result.table.to_json(orient="records")),
                                        "only_new": result.only_new, "only_baseline": result.only_baseline,
                                        "missing": result.missing,
                                        "regressed": result.regressed}, indent=1))
        else:
            raise TanbenchError(f"--report {path}: use a .parquet, .md or .json file name")
    except OSError as exc:
        raise TanbenchError(f"cannot write {path}: {exc.strerror or exc}") from None
