"""Regression check: is NEW worse than BASELINE, cell by cell and method by method?

Cells are matched by their scenario (every scenario column the two results share, so
results from another tanbench version match as long as the schema does; ``ignore`` names
scenario columns left out of the match, to compare cells that differ only there, e.g. the
two random streams of ``filter.random_numbers``: two cells that then fall on one key are
refused, never averaged into one row). Cells found in only one directory are reported.

Every (cell, method) has a **two-part outcome** (docs/results.md, "Verdicts"), from the
metrics declared for the check (:mod:`tanbench.metrics.declarations`):

* **lost runs**: the lost-run rate (``diverged``, docs/model.md 6.5) with its exact
  interval; tested by McNemar's exact test where the runs share seeds, Fisher's exact test
  otherwise (:func:`tanbench.inference.lost_tests`);
* **accuracy** of the runs not lost (paired: pairs lost in neither directory): the mean and
  the 90th percentile of each accuracy metric (final and time-averaged horizontal error),
  each change with its bootstrap 95 % interval and a one-sided permutation test against a
  margin delta = max(rel * baseline statistic, abs) (:func:`tanbench.inference.permutation_p`).

Each row (one outcome of one cell and method, or of a method pooled over its cells with
``pool="method"``) tests "worse" and "better"; Holm's correction runs over the decisive
rows (the pooled rows when pooling is declared, else the cell rows), separately for worse
and better; the cell rows under pooling form their own family and are shown for
information. A row is **regressed** if its corrected worse-p is below alpha *and* its
printed change exceeds its margin (so a verdict never disagrees in sign with its effect),
**improved** in the mirror case; otherwise **unchanged** if it could have detected a
change (its minimal detectable effect, MDE, at 80 % power is at most twice its margin; for
lost runs at most ``lost_detect``), **underpowered** if not, and **too few runs** below
``min_runs``. Underpowered and too-few-runs decisive rows make ``tanbench check`` fail
unless ``--allow-underpowered``.

Missing data is a failure too: a cell, a method of a matched cell, or a (successful) run
of a matched cell and method found in only one of the directories is listed in
``missing`` and makes ``tanbench check`` exit 1 (``--allow-missing`` compares what the
two share and only reports the rest).
With ``nees`` a further accuracy row compares the per-run fraction of updates whose NEES
lies outside its one-run 95 % chi-square bounds (``nees_above_95 + nees_below_95``), mean
only, with its own absolute margin ``nees_margin_abs`` (a fraction, default 0.05).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from tanbench import inference
from tanbench.errors import TanbenchError
from tanbench.inference import holm  # noqa: F401 - part of this module's interface
from tanbench.metrics.declarations import accuracy_metrics, lost_metric
from tanbench.results import TABLE_SCENARIO_COLUMNS, load, to_markdown
from tanbench.schema import RESULT_COLUMNS

NEES_METRIC = ("nees", "nees_outside_95")
TAIL = "p90"
VERDICT_FAILS = ("regressed", "underpowered", "too few runs")


@dataclass
class CheckOptions:
    margin_rel: float = 0.10
    margin_abs: float = 1.0
    alpha: float = 0.05
    bootstrap: int = 2000
    permutations: int = inference.PERMUTATIONS
    seed: int = 0
    nees: bool = False
    nees_margin_abs: float = 0.05
    ignore: tuple[str, ...] = ()  # scenario columns left out of the cell match
    pool: str = "none"  # "method": decisive rows pool each method over the matched cells
    lost_detect: float = 0.05  # a lost-run row must detect this increase of the rate (5 runs in 100)
    min_runs: int = 10  # fewer runs in a row: "too few runs"
    tail: bool = True  # also test the 90th percentile of each accuracy metric


@dataclass
class CheckResult:
    table: pd.DataFrame  # one row per (scope, method, outcome)
    only_new: list[str]  # cells
    only_baseline: list[str]
    missing_methods: list[str] = field(default_factory=list)  # "<cell>: method m only in NEW"
    missing_runs: list[str] = field(default_factory=list)  # "<cell>, m: runs 3, 4 only in BASELINE"

    @property
    def decisive(self) -> pd.DataFrame:
        return self.table[self.table["role"] == "decisive"]

    @property
    def regressed(self) -> bool:
        return bool((self.decisive["verdict"] == "regressed").any())

    @property
    def underpowered(self) -> bool:
        return bool(self.decisive["verdict"].isin(["underpowered", "too few runs"]).any())

    @property
    def decided(self) -> bool:
        """Every decisive row regressed, improved, or shown within its margin (equivalent)."""
        d = self.decisive
        return bool((d["verdict"].isin(["regressed", "improved"]) | d["equivalent"]).all())

    @property
    def missing(self) -> list[str]:
        """Everything found in only one directory, one line each."""
        return ([f"cell only in NEW: {c}" for c in self.only_new]
                + [f"cell only in BASELINE: {c}" for c in self.only_baseline]
                + self.missing_methods + self.missing_runs)


def _load(directory, nees: bool = False) -> pd.DataFrame:
    runs = load(directory)
    needed = ("method", "run", "seed", "status", lost_metric().name, *(m.name for m in accuracy_metrics()))
    missing = [c for c in needed if c not in runs.columns]
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


def _key_value(v):
    """A scenario value as cells are matched on it: 10.0 is 10, numpy scalars plain."""
    if isinstance(v, (float, np.floating)) and float(v).is_integer():
        return int(v)
    if isinstance(v, np.generic):
        return v.item()
    return v


def _cell_keys(runs: pd.DataFrame, cols: list[str]) -> pd.Series:
    return runs[cols].apply(lambda r: json.dumps([_key_value(v) for v in r], default=str), axis=1)


def _values(runs: pd.DataFrame, col: str) -> set[str]:
    """The values of a scenario column as :func:`_cell_keys` matches them."""
    return {json.dumps(_key_value(v), default=str) for v in runs[col]}


def _label(row: pd.Series) -> str:
    return ", ".join(f"{c}={row[c]:g}" if isinstance(row[c], (int, float, np.number)) else f"{c}={row[c]}"
                     for c in TABLE_SCENARIO_COLUMNS if c in row)


@dataclass
class _Pairs:
    """One method's runs in one scope (a cell, or the pooled cells), ready to compare."""

    lost_new: np.ndarray
    lost_base: np.ndarray
    paired: bool
    values: dict  # column -> (new values, baseline values, normaliser per baseline value or None)


def _pairs(nm: pd.DataFrame, bm: pd.DataFrame, columns: list[str]) -> _Pairs:
    """Lost flags and accuracy values of one cell and method (accuracy: runs not lost)."""
    lost = lost_metric().name
    common = nm.index.intersection(bm.index)
    paired = len(common) >= 2 and bool((nm.loc[common, "seed"] == bm.loc[common, "seed"]).all())
    if paired:
        nm, bm = nm.loc[common], bm.loc[common]
    ln, lb = nm[lost].astype(bool).to_numpy(), bm[lost].astype(bool).to_numpy()
    values = {}
    for col in columns:
        x, y = nm[col].to_numpy(float), bm[col].to_numpy(float)
        if paired:
            keep = ~ln & ~lb & np.isfinite(x) & np.isfinite(y)  # NaN metrics (no covariance) are left out
            x, y = x[keep], y[keep]
        else:
            x, y = x[~ln & np.isfinite(x)], y[~lb & np.isfinite(y)]
        values[col] = (x, y)
    return _Pairs(ln, lb, paired, values)


def _margin(opt: CheckOptions, metric: str, base_stat: float) -> float:
    margin_abs = opt.nees_margin_abs if metric == NEES_METRIC[0] else opt.margin_abs
    return max(opt.margin_rel * base_stat, margin_abs)


def _pool(parts: list[_Pairs], opt: CheckOptions, labels: dict) -> _Pairs:
    """One method's cells as one sample: accuracy values divided by each cell's margin scale
    (max(baseline mean, abs margin / rel margin)), so the pooled margin is ``margin_rel`` of
    every cell's baseline mean; lost flags concatenated. Paired only if every cell is."""
    values = {}
    for col in parts[0].values:
        xs, ys = [], []
        for p in parts:
            x, y = p.values[col]
            if y.size == 0:
                continue
            m_abs = opt.nees_margin_abs if labels[col] == NEES_METRIC[0] else opt.margin_abs
            scale = max(float(np.mean(y)), m_abs / opt.margin_rel if opt.margin_rel > 0 else 0.0) or 1.0
            xs.append(x / scale)
            ys.append(y / scale)
        values[col] = (np.concatenate(xs) if xs else np.zeros(0), np.concatenate(ys) if ys else np.zeros(0))
    return _Pairs(np.concatenate([p.lost_new for p in parts]), np.concatenate([p.lost_base for p in parts]),
                  all(p.paired for p in parts), values)


def _rows(scope: dict, pairs: _Pairs, labels: dict, opt: CheckOptions, pooled: bool, seed: int) -> list[dict]:
    """The lost-run row and the accuracy rows of one scope and method (tests, intervals, no verdicts)."""
    out = []
    ln, lb = pairs.lost_new, pairs.lost_base
    kn, kb = int(ln.sum()), int(lb.sum())
    p_worse, p_better = inference.lost_tests(ln, lb, pairs.paired)
    lo_n, hi_n = inference.clopper_pearson(kn, ln.size)
    lo_b, hi_b = inference.clopper_pearson(kb, lb.size)
    rate_n, rate_b = kn / max(ln.size, 1), kb / max(lb.size, 1)
    if pairs.paired:  # runs lost only in NEW / only in BASELINE: the discordant pairs
        b, c = int(np.sum(ln & ~lb)), int(np.sum(lb & ~ln))
        # the change is (b - c) / n: exact bounds of b / n and c / n combined (conservative)
        lo_bn, hi_bn = inference.clopper_pearson(b, ln.size)
        lo_cn, hi_cn = inference.clopper_pearson(c, ln.size)
        change_lo, change_hi = lo_bn - hi_cn, hi_bn - lo_cn
        equivalent_lost = change_hi < opt.lost_detect
    else:
        change_lo, change_hi = lo_n - hi_b, hi_n - lo_b
        equivalent_lost = change_hi < opt.lost_detect
    out.append({**scope, "metric": "lost", "statistic": "rate", "paired": pairs.paired,
                "n_new": int(ln.size), "n_baseline": int(lb.size), "baseline": rate_b, "new": rate_n,
                "change": rate_n - rate_b, "ci95_low": change_lo, "ci95_high": change_hi,
                "baseline_ci95": f"{kb}/{lb.size} [{lo_b:.3f}, {hi_b:.3f}]",
                "new_ci95": f"{kn}/{ln.size} [{lo_n:.3f}, {hi_n:.3f}]",
                "margin": 0.0, "detect": opt.lost_detect,
                "p_worse": p_worse, "p_better": p_better, "equivalent": bool(equivalent_lost),
                "_kind": "lost", "_rate_base": rate_b,
                "_reshuffled": int(np.sum(lb & ~ln)) if pairs.paired else -1})
    for col, (x, y) in pairs.values.items():
        label = labels[col]
        stats = ["mean"] + ([TAIL] if opt.tail and label != NEES_METRIC[0] else [])
        for k, stat in enumerate(stats):
            if x.size == 0 or y.size == 0:
                continue
            f = inference.STATISTICS[stat]
            base_stat, new_stat = float(f(y)), float(f(x))
            margin = opt.margin_rel if pooled else _margin(opt, label, base_stat)
            s = seed + 7919 * k
            lo, hi = inference.bootstrap_change_ci(x, y, pairs.paired, stat, n=opt.bootstrap, seed=s)
            if pairs.paired and x.size >= 2:  # the noise of these pairs: bootstrap spread of the change
                rng = np.random.default_rng(s + 1)
                idx = rng.integers(0, x.size, (opt.bootstrap, x.size))
                se = float(np.std(f(x[idx], axis=1) - f(y[idx], axis=1), ddof=1))
            else:  # reseeded runs: the baseline's own spread
                se = inference.reseed_se(y, stat, x.size)
            out.append({**scope, "metric": label if stat == "mean" else f"{label} {stat}", "statistic": stat,
                        "paired": pairs.paired, "n_new": int(x.size), "n_baseline": int(y.size),
                        "baseline": base_stat, "new": new_stat, "change": new_stat - base_stat,
                        "ci95_low": lo, "ci95_high": hi, "baseline_ci95": "", "new_ci95": "",
                        "margin": margin, "detect": 2.0 * margin,
                        "p_worse": inference.permutation_p(x, y, margin, pairs.paired, stat, opt.permutations, s),
                        "p_better": inference.permutation_p(y, x, margin, pairs.paired, stat, opt.permutations, s),
                        "equivalent": False, "_p_noninf":
                            inference.permutation_p(y, x, -margin, pairs.paired, stat, opt.permutations, s),
                        "_kind": "accuracy", "_se": se})
    return out


def _verdicts(table: pd.DataFrame, opt: CheckOptions, alpha: float) -> pd.DataFrame:
    """Holm over each family (decisive rows; information rows), MDEs, verdicts, in place."""
    table["p_worse_holm"] = np.nan
    table["p_better_holm"] = np.nan
    table["mde"] = np.nan
    for role in ("decisive", "info"):
        fam = table["role"] == role
        if not fam.any():
            continue
        table.loc[fam, "p_worse_holm"] = holm(table.loc[fam, "p_worse"].to_numpy())
        table.loc[fam, "p_better_holm"] = holm(table.loc[fam, "p_better"].to_numpy())
        level = alpha / int(fam.sum())  # Bonferroni: the level Holm's first step uses, a safe bound
        for i in table.index[fam]:
            r = table.loc[i]
            if r["_kind"] == "lost":
                mde = (inference.mde_lost_paired(int(r["n_new"]), int(r["_reshuffled"]), level) if r["paired"] else
                       inference.mde_lost(r["_rate_base"], int(r["n_new"]), int(r["n_baseline"]), level))
            else:
                mde = inference.mde_shift(r["margin"], r["_se"], level)
                noninf = r["_p_noninf"] * int(fam.sum())  # equivalence (below the margin) at the same level
                table.loc[i, "equivalent"] = bool(noninf < alpha and r["change"] < r["margin"])
            table.loc[i, "mde"] = mde
    worse = (table["p_worse_holm"] < alpha) & (table["change"] > table["margin"])
    better = (table["p_better_holm"] < alpha) & (table["change"] < -table["margin"])
    few = np.minimum(table["n_new"], table["n_baseline"]) < opt.min_runs
    weak = table["mde"] > table["detect"]
    table["verdict"] = np.select([worse, better, few, weak], ["regressed", "improved", "too few runs", "underpowered"],
                                 "unchanged")
    table["equivalent"] = table["equivalent"].astype(bool) & ~worse & ~better
    return table.drop(columns=[c for c in table.columns if c.startswith("_")])


def compare(new_dir, base_dir, options: CheckOptions | None = None, alpha: float | None = None) -> CheckResult:
    """Compare two results directories; see the module docstring. ``alpha`` overrides the
    options' level (the sequential check spends it over its looks)."""
    opt = options or CheckOptions()
    if opt.pool not in ("none", "method"):
        raise TanbenchError(f"--pool {opt.pool}: use none or method")
    new, base = _load(new_dir, opt.nees), _load(base_dir, opt.nees)
    labels = {m.name: m.label for m in accuracy_metrics()}
    if opt.nees:
        labels[NEES_METRIC[1]] = NEES_METRIC[0]
    columns = list(labels)
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
    for name, df in (("NEW", new), ("BASELINE", base)):
        merged = df.groupby("_cell")["cell_id"].nunique()
        if (merged > 1).any():
            ids = sorted(df.loc[df["_cell"] == merged[merged > 1].index[0], "cell_id"].unique())
            raise TanbenchError(f"--ignore {', '.join(opt.ignore)} makes cells {', '.join(ids)} of {name} one cell; "
                                f"check compares cell with cell and never averages two: ignore fewer columns")
    cells_new, cells_base = set(new["_cell"]), set(base["_cell"])

    def describe(keys, df):
        firsts = df.drop_duplicates("_cell").set_index("_cell")
        return [f"{firsts.loc[k, 'cell_id']} ({_label(firsts.loc[k])})" for k in sorted(keys)]

    pooling = opt.pool == "method"
    rows, missing_methods, missing_runs, by_method = [], [], [], {}
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
            pairs = _pairs(nm, bm, columns)
            by_method.setdefault(method, []).append(pairs)
            scope = {"role": "info" if pooling else "decisive", "scope": "cell", "cell_id": nm["cell_id"].iloc[0],
                     "cell": _label(nm.iloc[0]), "method": method}
            rows += _rows(scope, pairs, labels, opt, False, opt.seed + len(rows))
    if pooling:
        for method, parts in sorted(by_method.items()):
            scope = {"role": "decisive", "scope": "pooled", "cell_id": f"{len(parts)} cells",
                     "cell": f"pooled over {len(parts)} cells (values / cell baseline mean)", "method": method}
            rows += _rows(scope, _pool(parts, opt, labels), labels, opt, True, opt.seed + len(rows))
    table = pd.DataFrame(rows)
    if table.empty:
        if cells_new & cells_base:
            raise TanbenchError(f"{new_dir} and {base_dir} have no method in common in their common cells")
        differ = [c for c in cols if _values(new, c) != _values(base, c)]
        hint = (f": their cells differ in {', '.join(differ[:5])}{' and more' if len(differ) > 5 else ''}; to "
                f"compare across that, give " + " ".join(f"--ignore {c}" for c in differ[:5])) if differ else ""
        raise TanbenchError(f"{new_dir} and {base_dir} have no cell in common{hint}")
    table = _verdicts(table, opt, opt.alpha if alpha is None else alpha)
    return CheckResult(table=table, only_new=describe(cells_new - cells_base, new),
                       only_baseline=describe(cells_base - cells_new, base),
                       missing_methods=missing_methods, missing_runs=missing_runs)


def _runs_text(runs) -> str:
    """'run 3' or 'runs 0, 1, 4' (at most 10 listed)."""
    runs = [int(r) for r in runs]
    shown = ", ".join(str(r) for r in runs[:10]) + (f", ... ({len(runs)} in all)" if len(runs) > 10 else "")
    return f"run{'s' if len(runs) > 1 else ''} {shown}"


def _num(v: float, rate: bool) -> str:
    if not np.isfinite(v):
        return "inf" if v > 0 else "-"
    return f"{v:.3f}" if rate else f"{v:.2f}"


def render(result: CheckResult) -> str:
    """The compact text table `tanbench check` prints: decisive rows first."""
    t = result.table
    w = max([10, *(len(m) for m in t["method"])])  # a plug-in's long name widens the column, not the row
    lines = [f"{'verdict':13s} {'method':{w}s} {'metric':13s} {'baseline':>9s} {'new':>9s} {'change':>8s} "
             f"{'95% CI':>17s} {'margin':>7s} {'MDE':>7s} {'p(worse)':>9s} {'p(better)':>9s}  scope"]
    for role in ("decisive", "info"):
        part = t[t["role"] == role]
        if part.empty:
            continue
        if role == "info":
            lines.append("-- per cell, for information (pooling declared; own Holm family, not counted):")
        for _, r in part.iterrows():
            rate = r["statistic"] == "rate"
            ci = f"[{_num(r['ci95_low'], rate):>7s},{_num(r['ci95_high'], rate):>7s}]"
            lines.append(f"{r['verdict']:13s} {r['method']:{w}s} {r['metric']:13s} {_num(r['baseline'], rate):>9s} "
                         f"{_num(r['new'], rate):>9s} {('+' if r['change'] >= 0 else '') + _num(r['change'], rate):>8s} "
                         f"{ci:>17s} {_num(r['margin'], rate):>7s} {_num(r['mde'], rate):>7s} "
                         f"{r['p_worse_holm']:9.2g} {r['p_better_holm']:9.2g}  {r['cell']}"
                         f"{'' if r['paired'] else ' (unpaired)'}")
    for line in result.missing:
        lines.append(f"missing: {line}")
    counts = result.decisive["verdict"].value_counts()
    lines.append(f"{counts.get('regressed', 0)} regressed, {counts.get('improved', 0)} improved, "
                 f"{counts.get('unchanged', 0)} unchanged, {counts.get('underpowered', 0)} underpowered, "
                 f"{counts.get('too few runs', 0)} with too few runs (decisive rows, Holm-corrected; "
                 f"lost: rate of lost runs, exact tests; other metrics: runs not lost, permutation tests "
                 f"against the margin; MDE: change detected with 80 % power); "
                 f"{len(result.missing)} missing (cells, methods or runs in only one directory)")
    return "\n".join(lines)


REPORT_SUFFIXES = (".parquet", ".md", ".json")


def check_report_path(path: Path) -> None:
    """Refuse a ``--report`` path the comparison could not be written to, before any work: its suffix must be one
    of REPORT_SUFFIXES, it must not be a directory, and its directory must exist."""
    path = Path(path)
    if path.suffix.lower() not in REPORT_SUFFIXES:
        raise TanbenchError(f"--report {path}: use a .parquet, .md or .json file name")
    if path.is_dir():
        raise TanbenchError(f"--report {path}: is a directory; give a file name")
    if not path.parent.is_dir():
        raise TanbenchError(f"--report {path}: its directory {path.parent} does not exist")


def write_report(result: CheckResult, path: Path) -> None:
    """Write the comparison as .parquet, .md or .json (by extension)."""
    path = Path(path)
    check_report_path(path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".parquet":
            result.table.to_parquet(path, index=False)
        elif suffix == ".md":
            extra = "".join(f"\n* missing: {line}" for line in result.missing)
            shown = result.table.copy()  # 4 significant digits (a lost rate of 0.450 is not 0.5)
            for c in shown.columns[shown.dtypes.apply(lambda t: t.kind == "f")]:
                shown[c] = [("-" if np.isnan(v) else f"{v:.4g}") for v in shown[c]]
            path.write_text(to_markdown(shown, title="tanbench check") + extra + "\n")
        elif suffix == ".json":
            path.write_text(json.dumps({"rows": json.loads(result.table.to_json(orient="records")),
                                        "only_new": result.only_new, "only_baseline": result.only_baseline,
                                        "missing": result.missing, "regressed": result.regressed,
                                        "underpowered": result.underpowered}, indent=1))
    except OSError as exc:
        raise TanbenchError(f"cannot write {path}: {exc.strerror or exc}") from None


def looks(start: int, batch: int, cap: int) -> list[int]:
    """Run counts at which the sequential check looks: start, start + batch, ..., cap."""
    if batch < 1 or cap < start:
        raise TanbenchError(f"--batch {batch} / --cap {cap}: need batch >= 1 and cap >= the runs stored ({start})")
    counts = list(range(start, cap, batch)) + [cap]
    return sorted(set(counts))


def spend(alpha: float, n_looks: int) -> float:
    """The level of each look: alpha spent evenly over the planned looks (Bonferroni over looks,
    valid whatever the stopping rule, since the chance of any false verdict at any look is at
    most the sum of the looks' levels)."""
    return alpha / max(n_looks, 1)

