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
import pyarrow as pa

from tanbench import store
from tanbench.errors import TanbenchError
from tanbench.inference import clopper_pearson, p90
from tanbench.metrics.consistency import cell_verdict, mc_bounds, nees, whole_run_verdict
from tanbench.metrics.declarations import METRICS

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
        path = store.summary_file(directory)
        if not path.exists():
            raise TanbenchError(f"{directory}: no series summary (was the sweep run with --series none? `tanbench "
                                f"run` of the directory's sweep into it without --series none writes it)")
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
    """Per group: n_runs and the statistics of the final and time-averaged errors, the lost-run
    rate with its exact interval, and the declared summaries of further metrics.

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
            **_two_part_columns(ok),
            **_declared_columns(ok),
            **_consistency_columns(ok),
            **_efficiency_columns(ok),
        })
        extra = {"divergence_rate": float(ok["diverged"].astype(bool).mean()) if f.size else np.nan,
                 "mean_filter_wall_s": float(ok["filter_wall_s"].mean())
                 if f.size and "filter_wall_s" in ok else np.nan}
        rows[-1].update({c: extra[c] for c in columns})
    return pd.DataFrame(rows)


def _two_part_columns(ok: pd.DataFrame) -> dict:
    """The two parts of the outcome (docs/results.md, "Verdicts"): the lost-run rate (``diverged``,
    docs/model.md 6.5) with its exact Clopper-Pearson 95 % interval; the time-averaged error's
    bootstrap 95 % interval; the tail (90th percentile) of the final and time-averaged errors."""
    lost = ok["diverged"].astype(bool).to_numpy() if len(ok) else np.zeros(0, bool)
    lo, hi = clopper_pearson(int(lost.sum()), lost.size)
    ta = ok["mean_horizontal_error_m"].to_numpy(dtype=float) if len(ok) else np.zeros(0)
    f = ok["final_horizontal_error_m"].to_numpy(dtype=float) if len(ok) else np.zeros(0)
    ta_lo, ta_hi = bootstrap_ci(ta)
    return {"lost_rate": float(lost.mean()) if lost.size else np.nan, "lost_ci95_low": lo, "lost_ci95_high": hi,
            "time_avg_ci95_low_m": ta_lo, "time_avg_ci95_high_m": ta_hi,
            "p90_final_error_m": float(p90(f)) if f.size else np.nan,
            "p90_time_avg_error_m": float(p90(ta)) if ta.size else np.nan}


def _declared_columns(ok: pd.DataFrame) -> dict:
    """``mean_<name>`` of every metric declared with ``summary="mean"`` that the runs have."""
    return {f"mean_{m.name}": float(np.nanmean(ok[m.name].to_numpy(dtype=float)))
            if len(ok) and np.isfinite(ok[m.name].to_numpy(dtype=float)).any() else np.nan
            for m in METRICS if m.summary == "mean" and m.name in ok.columns}


def _consistency_columns(ok: pd.DataFrame) -> dict:
    """NEES summaries of a group of runs (results without NEES columns get none)."""
    if "nees_above_95" not in ok.columns:
        return {}
    above = ok["nees_above_95"].to_numpy(dtype=float)
    below = ok["nees_below_95"].to_numpy(dtype=float)
    after = ok["nees_mean_after_convergence"].to_numpy(dtype=float)
    out = {
        # a collapsed cloud's NEES can reach 1e15: the median over runs stays readable
        "median_nees_after_convergence": float(np.nanmedian(after)) if np.isfinite(after).any() else np.nan,
        "nees_above_95": float(np.nanmean(above)) if np.isfinite(above).any() else np.nan,
        "nees_below_95": float(np.nanmean(below)) if np.isfinite(below).any() else np.nan,
        "nees_fraction_verdict": cell_verdict(above, below),
    }
    if "nees_mean_whole_run" not in ok.columns:  # stored before the whole-run verdict: the fraction rule's
        out["nees_verdict"] = out["nees_fraction_verdict"]
        return out
    per_run = ok["nees_mean_whole_run"].to_numpy(dtype=float)
    per_run = per_run[np.isfinite(per_run)]
    below_bound = ok["reported_std_below_bound"].to_numpy(dtype=float)
    share = float(np.nanmean(below_bound)) if np.isfinite(below_bound).any() else np.nan
    anees = float(per_run.mean()) if per_run.size else np.nan
    lo, hi = mc_bounds(per_run.size) if per_run.size else (np.nan, np.nan)
    out.update(anees=anees, anees_band_low=float(lo), anees_band_high=float(hi), below_bound_share=share,
               nees_verdict=whole_run_verdict(anees, per_run.size, share))
    return out


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
        if sub.empty:
            continue
        cols = TABLE_SCENARIO_COLUMNS + _design_columns(design, sub)
        summary = summarize(sub, by=cols + ["method"], columns=getattr(sweep.spec, "table_columns", ()))
        summary.insert(0, "table", table)
        # rows in the order the sweep file lists the design's values (a mapping's flattened columns: in the
        # order of the table's cells), then its methods
        ranks = []
        cell_order = sub["cell_id"].map({c.cell_id: i for i, c in enumerate(cells)})
        for p in [*(p for p in design if p in summary.columns),
                  *(c for c in cols[len(TABLE_SCENARIO_COLUMNS):] if c not in design)]:
            flat = p not in design
            values = list(dict.fromkeys(sub[p].astype(str)[cell_order.sort_values(kind="stable").index])) if flat \
                else design[p]
            ranks.append(f"_rank_{p}")
            summary[ranks[-1]] = summary[p].map(lambda v, values=values, flat=flat: _design_rank(
                values, str(v) if flat else v))
        summary["_m"] = summary["method"].map(method_order)
        summary = summary.sort_values(ranks + ["_m"], kind="stable").drop(columns=ranks + ["_m"])
        out[table] = summary.reset_index(drop=True)
    return out


def _design_columns(design: dict, runs: pd.DataFrame) -> list[str]:
    """The runs' columns that key a table's rows besides the scenario's: each setting the design
    varies, and for a setting whose values are mappings (``method_options``, a terrain) the
    flattened columns (``method_options.tight-mbe.selection``) that differ between its cells, so
    two cells of a table never share a row."""
    cols = []
    for p in design:
        if p in TABLE_SCENARIO_COLUMNS:
            continue
        if p in runs.columns:
            cols.append(p)
            continue
        cols += [c for c in runs.columns if c.startswith(p + ".") and runs[c].astype(str).nunique() > 1]
    return cols


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
    out["nees_mc_low"], out["nees_mc_high"] = mc_bounds(out["n_runs"].to_numpy())
    floats = [c for c in out.columns if c not in ("cell_id", "method", "n_runs")]
    return out.astype({c: "float32" for c in floats})


def _series_frames(files, written: dict) -> list[pd.DataFrame]:
    """The runs' series frames with their ``cell_id``, in the order of ``files`` ((cell, name), path):
    read from the files, except those the session ``written`` (Arrow tables), of which each run of
    consecutive ones with one schema is converted to pandas together, as one frame of the same rows
    in the same order (one conversion instead of one per file)."""
    frames, group = [], []

    def convert_group():
        if group:
            tables = [t.append_column("cell_id", pa.array([cell] * t.num_rows, pa.string())) for cell, t in group]
            frames.append(pa.concat_tables(tables).to_pandas())
            group.clear()

    for (cell, _), path in files:
        table = written.get(path)
        if table is not None and group and table.schema != group[0][1].schema:
            convert_group()
        if table is not None:
            group.append((cell, table))
            continue
        convert_group()
        frames.append(store.read_parquet(path).assign(cell_id=cell))
    convert_group()
    return frames


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
        frames = _series_frames(sorted(files.items()), written)
        summary_path = store.summary_file(out)
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
