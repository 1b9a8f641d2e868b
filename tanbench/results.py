"""Results as pandas: load runs and series, summarise, build the paper-style tables.

``load(DIR)`` returns the tidy runs table (one row per cell, method and run: the
sweep, cell_id, tables, method, run, seeds, every scenario parameter as a flat column,
the metrics, status, error and wall_s); it is exactly ``pd.read_parquet(DIR / "runs")``,
after checking that every file is tanbench's, of this schema. ``load_series(DIR)`` gives
the per-update series (the Monte Carlo summary by default), ``summarize(df, by=...)``
the statistics the tables show. ``build_outputs`` writes ``series/summary.parquet`` and
``tables/`` for a sweep.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from tanbench.errors import TanbenchError
from tanbench import store

# the scenario columns every table shows (the paper's Tables 3-7 columns)
TABLE_SCENARIO_COLUMNS = ["area", "map_resolution_m", "noise_m", "sampling_time_s", "particles"]
SUMMARY_ERRORS = ["horizontal_error_m", "east_error_m", "north_error_m", "heading_error_deg"]
SUMMARY_MEANS = ["est_e", "est_n", "est_heading_deg", "truth_e", "truth_n", "truth_heading_deg",
                 "nav_e", "nav_n", "nav_heading_deg", "nav_horizontal_error_m"]
# the PCRB series (tanbench.bounds.pcrb), the same for every run of a cell: their mean is the bound
SUMMARY_BOUNDS = ["pcrb_horizontal_m", "pcrb_heading_deg"]
PERCENTILES = (5, 50, 95)
BOOTSTRAP_SAMPLES = 2000


def _files(directory: Path, pattern: str) -> list[Path]:
    return sorted(directory.glob(pattern))


def load(directory, status: str | None = None) -> pd.DataFrame:
    """Every stored run of a results directory (``status="ok"`` keeps successful runs)."""
    directory = Path(directory)
    if not directory.is_dir():
        raise TanbenchError(f"{directory}: no such results directory")
    store.check_layout(directory)
    files = store.run_files(directory)
    if not files:
        raise TanbenchError(f"{directory}: no runs stored (expected {directory}/runs/cell_id=<id>/*.parquet)")
    store.check_files(files)
    df = _cell_first(store.read_dataset(directory / "runs"))
    # a kill between writing a cell's merged file and deleting its task files leaves rows twice
    df = df.drop_duplicates(subset=["cell_id", "method", "run"], keep="last").reset_index(drop=True)
    if status is not None:
        df = df[df["status"] == status].reset_index(drop=True)
    return df


def load_series(directory, kind: str = "summary") -> pd.DataFrame:
    """The per-update series: ``"summary"`` (Monte Carlo statistics) or ``"runs"`` (every run)."""
    directory = Path(directory)
    if kind == "summary":
        path = directory / "series" / "summary.parquet"
        if not path.exists():
            raise TanbenchError(f"{directory}: no series summary (was the sweep run with --series none?)")
        return store.read_parquet(path)
    if kind == "runs":
        base = store.series_dir(directory, full=True)
        files = _files(base, "cell_id=*/run-*.parquet")
        if not files:
            raise TanbenchError(f"{directory}: no per-run series (run the sweep with --series full)")
        store.check_files(files)
        return _cell_first(store.read_dataset(base))
    raise TanbenchError(f"unknown series kind {kind!r} (summary or runs)")


def _cell_first(df: pd.DataFrame) -> pd.DataFrame:
    """The partition column ``cell_id`` next to the front (pyarrow appends it last)."""
    cols = list(df.columns)
    cols.remove("cell_id")
    at = 1 if cols and cols[0] == "sweep" else 0
    return df[cols[:at] + ["cell_id"] + cols[at:]]


def bootstrap_ci(values: np.ndarray, level: float = 0.95, samples: int = BOOTSTRAP_SAMPLES,
                 seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap confidence interval of the mean (deterministic for a seed)."""
    values = np.asarray(values, dtype=float)
    values = values[~np.isnan(values)]
    if values.size == 0:
        return (np.nan, np.nan)
    rng = np.random.default_rng(seed)
    means = values[rng.integers(0, values.size, (samples, values.size))].mean(axis=1)
    lo, hi = np.percentile(means, [50 * (1 - level), 100 - 50 * (1 - level)])
    return float(lo), float(hi)


SUMMARY_EXTRA_COLUMNS = ("divergence_rate", "mean_filter_wall_s")


def summarize(df: pd.DataFrame, by=("cell_id", "method"), columns=()) -> pd.DataFrame:
    """Per group: n_runs and the statistics of the final and time-averaged errors.

    ``columns``: further columns of :data:`SUMMARY_EXTRA_COLUMNS` (a sweep's ``table_columns``):
    ``divergence_rate`` (n_diverged / n_runs) and ``mean_filter_wall_s`` (the filter's wall
    time per run, s).

    Failed runs are counted in ``n_failed`` and left out of the statistics.
    """
    by = list(by)
    rows = []
    for key, g in df.groupby(by, sort=False, dropna=False):
        ok = g[g["status"] == "ok"]
        f = ok["final_horizontal_error_m"].to_numpy(dtype=float)
        lo, hi = bootstrap_ci(f)
        rows.append({
            **dict(zip(by, key if isinstance(key, tuple) else (key,))),
            "n_runs": int(len(ok)),
            "mean_final_error_m": float(np.mean(f)) if f.size else np.nan,
            "min_final_error_m": float(np.min(f)) if f.size else np.nan,
            "max_final_error_m": float(np.max(f)) if f.size else np.nan,
            "std_final_error_m": float(np.std(f, ddof=1)) if f.size > 1 else np.nan,
            "median_final_error_m": float(np.median(f)) if f.size else np.nan,
            "ci95_low_m": lo,
            "ci95_high_m": hi,
            "mean_time_avg_error_m": float(ok["mean_horizontal_error_m"].mean()) if f.size else np.nan,
            "min_time_avg_error_m": float(ok["mean_horizontal_error_m"].min()) if f.size else np.nan,
            "max_time_avg_error_m": float(ok["mean_horizontal_error_m"].max()) if f.size else np.nan,
            "mean_final_heading_error_deg": float(ok["final_heading_error_deg"].mean()) if f.size else np.nan,
            "n_diverged": int(ok["diverged"].astype(bool).sum()),
            "n_failed": int((g["status"] != "ok").sum()),
            **_consistency_columns(ok),
            **_efficiency_columns(ok),
        })
        extra = {"divergence_rate": float(ok["diverged"].astype(bool).mean()) if f.size else np.nan,
                 "mean_filter_wall_s": float(ok["filter_wall_s"].mean())
                 if f.size and "filter_wall_s" in ok else np.nan}
        rows[-1].update({c: extra[c] for c in columns})
    return pd.DataFrame(rows)


def _consistency_columns(ok: pd.DataFrame) -> dict:
    """NEES summaries of a group of runs (results without NEES columns get none)."""
    from tanbench.metrics.consistency import cell_verdict

    if "nees_above_95" not in ok.columns:
        return {}
    above = ok["nees_above_95"].to_numpy(dtype=float)
    below = ok["nees_below_95"].to_numpy(dtype=float)
    after = ok["nees_mean_after_convergence"].to_numpy(dtype=float)
    return {
        # a collapsed cloud's NEES can reach 1e15: the median over runs stays readable
        "median_nees_after_convergence": float(np.nanmedian(after)) if np.isfinite(after).any() else np.nan,
        "nees_above_95": float(np.nanmean(above)) if np.isfinite(above).any() else np.nan,
        "nees_below_95": float(np.nanmean(below)) if np.isfinite(below).any() else np.nan,
        "nees_verdict": cell_verdict(above, below),
    }


def _efficiency_columns(ok: pd.DataFrame) -> dict:
    """RMSE / PCRB after convergence: mean over converged runs with its bootstrap 95 % CI."""
    if "rmse_pcrb_ratio" not in ok.columns:
        return {}
    ratio = ok["rmse_pcrb_ratio"].to_numpy(dtype=float)
    ratio = ratio[np.isfinite(ratio)]
    lo, hi = bootstrap_ci(ratio)
    bound = ok["pcrb_after_convergence_m"].to_numpy(dtype=float)
    return {
        "mean_pcrb_after_convergence_m": float(np.nanmean(bound)) if np.isfinite(bound).any() else np.nan,
        "rmse_pcrb_ratio": float(ratio.mean()) if ratio.size else np.nan,
        "rmse_pcrb_ratio_ci95_low": lo,
        "rmse_pcrb_ratio_ci95_high": hi,
    }


def sweep_tables(runs: pd.DataFrame, sweep) -> dict[str, pd.DataFrame]:
    """One summary table per design of ``sweep``, from its current cells only."""
    ids = {c.cell_id for c in sweep.cells}
    runs = runs[runs["cell_id"].isin(ids)]
    out = {}
    method_order = {m: i for i, m in enumerate(sweep.spec.methods)}
    for table, design in sweep.table_designs.items():
        cells = [c for c in sweep.cells if table in c.tables]
        if not cells:
            continue
        sub = runs[runs["cell_id"].isin({c.cell_id for c in cells})]
        extra = [p for p in design if p not in TABLE_SCENARIO_COLUMNS]
        cols = TABLE_SCENARIO_COLUMNS + [p for p in extra if p in sub.columns]
        if sub.empty:
            continue
        summary = summarize(sub, by=cols + ["method"], columns=getattr(sweep.spec, "table_columns", ()))
        summary.insert(0, "table", table)
        # rows in the order the sweep file lists the design's values, then its methods
        ranks = []
        for p, values in design.items():
            if p in summary.columns:
                ranks.append(f"_rank_{p}")
                summary[ranks[-1]] = summary[p].map(lambda v, values=values: _design_rank(values, v))
        summary["_m"] = summary["method"].map(method_order)
        summary = summary.sort_values(ranks + ["_m"], kind="stable").drop(columns=ranks + ["_m"])
        out[table] = summary.reset_index(drop=True)
    return out


def _design_rank(values: list, value) -> int:
    """Position of ``value`` in a design's list of values (unlisted values go last)."""
    return values.index(value) if value in values else len(values)


def series_summary(frames: list[pd.DataFrame]) -> pd.DataFrame:
    """Monte Carlo statistics over runs, per (cell, method, t).

    For each error: the mean, the mean of its absolute value (``_abs_mean``; the same as
    the mean for the horizontal error) and the 5th/50th/95th percentiles; for positions
    and headings: the mean; ``filter_std_m_mean``: the mean of the filter's horizontal
    spread sqrt(var_e + var_n). ``n_runs`` counts the runs at each time.
    """
    from tanbench.metrics.consistency import nees

    allruns = pd.concat(frames, ignore_index=True)
    allruns = allruns.assign(**{f"{c}_abs": allruns[c].abs() for c in SUMMARY_ERRORS},
                             filter_std_m=np.sqrt(allruns["var_e"] + allruns["var_n"]),
                             horizontal_error_m_sq=allruns["horizontal_error_m"] ** 2,
                             nees=nees(allruns["east_error_m"], allruns["north_error_m"], allruns["var_e"],
                                       allruns["var_n"], allruns["cov_en"] if "cov_en" in allruns else None))
    grouped = allruns.groupby(["cell_id", "method", "t"], sort=True)
    parts = [grouped[SUMMARY_MEANS].mean(), grouped["t"].size().rename("n_runs"),
             grouped["filter_std_m"].mean().rename("filter_std_m_mean"),
             np.sqrt(grouped["horizontal_error_m_sq"].mean()).rename("horizontal_error_m_rms"),
             grouped["nees"].mean().rename("nees_mean")]
    bound_cols = [c for c in SUMMARY_BOUNDS if c in allruns.columns]
    if bound_cols:
        parts.append(grouped[bound_cols].mean())
    for col in SUMMARY_ERRORS:
        g = grouped[col]
        stats = {f"{col}_mean": g.mean(), f"{col}_abs_mean": grouped[f"{col}_abs"].mean()}
        stats.update({f"{col}_p{p:02d}": g.quantile(p / 100.0) for p in PERCENTILES})
        parts.append(pd.DataFrame(stats))
    out = pd.concat(parts, axis=1).reset_index()
    from tanbench.metrics.consistency import mc_bounds

    out["nees_mc_low"], out["nees_mc_high"] = mc_bounds(out["n_runs"].to_numpy())
    floats = [c for c in out.columns if c not in ("cell_id", "method", "n_runs")]
    return out.astype({c: "float32" for c in floats})


def build_outputs(out: Path, sweep, series: str, written: dict | None = None) -> dict[str, pd.DataFrame]:
    """Write series/summary.parquet (if series are kept) and tables/ for ``sweep``.

    ``written``: series tables (Arrow) by file path, as the running session wrote them (those
    files are not read back; :class:`tanbench.runner.engine.SeriesWritten`)."""
    written = written or {}
    meta = store.provenance(sweep.text, sweep.name, sweep.spec.seed)
    ids = {c.cell_id for c in sweep.cells}
    if series != "none":
        # each run's series file, from either series directory (this mode's first); a cell
        # with none here keeps its rows of the summary already written (a clone of committed
        # results holds the summary only), so that no cell drops out of it
        files = {}
        for full in (series != "full", series == "full"):
            for f in _files(store.series_dir(out, full), "cell_id=*/run-*.parquet"):
                if store.cell_of(f) in ids:
                    files[(store.cell_of(f), f.name)] = f
        frames = [(written[f].to_pandas() if f in written else store.read_parquet(f)).assign(cell_id=cell)
                  for (cell, _), f in sorted(files.items())]
        summary_path = out / "series" / "summary.parquet"
        if frames and summary_path.exists():
            kept = store.read_parquet(summary_path)
            kept = kept[kept["cell_id"].isin(ids - {cell for cell, _ in files})]
            summary = pd.concat([series_summary(frames), kept], ignore_index=True) if len(kept) else \
                series_summary(frames)
            store.write_parquet(summary.sort_values(["cell_id", "method", "t"], kind="stable")
                                .reset_index(drop=True), summary_path, meta)
        elif frames:
            store.write_parquet(series_summary(frames), summary_path, meta)
    try:
        runs = load(out)
    except TanbenchError:
        return {}
    tables = sweep_tables(runs, sweep)
    for name, table in tables.items():
        store.write_parquet(table, out / "tables" / f"{name}.parquet", meta)
        store.write_text(to_markdown(table, title=name), out / "tables" / f"{name}.md")
    # tables/ shows the current sweep: drop the tables (ours only) of designs it no longer has
    for f in _files(out / "tables", "*.parquet"):
        if f.stem not in tables and store.is_tanbench_file(f):
            f.unlink(missing_ok=True)
            f.with_suffix(".md").unlink(missing_ok=True)
    return tables


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        if np.isnan(v):
            return "-"
        return f"{v:.1f}" if abs(v) >= 0.1 or v == 0 else f"{v:.3g}"
    return str(v)


def _fmt_ratio(v) -> str:
    """Ratios (ours / paper) with two decimals, so 0.30 and 0.04 stay comparable."""
    if isinstance(v, (float, np.floating)) and not np.isnan(v):
        return f"{v:.2f}"
    return _fmt(v)


def to_markdown(df: pd.DataFrame, title: str | None = None) -> str:
    """A plain GitHub-flavoured Markdown table (no extra dependency)."""
    lines = [f"### {title}", ""] if title else []
    cols = list(df.columns)
    lines.append("| " + " | ".join(cols) + " |")
    lines.append("|" + "|".join("---" for _ in cols) + "|")
    for _, row in df.iterrows():
        lines.append("| " + " | ".join(_fmt_ratio(row[c]) if c.startswith("ratio") or c.endswith(("_rho", "_ratio")) else _fmt(row[c])
                                       for c in cols) + " |")
    return "\n".join(lines) + "\n"
