"""Prediction checked against outcome: do the suitability measure and the PCRB rank the errors?

For every (results directory, cell, method) of one or more results directories:

* **predictors**, computed from the scenario alone (no run is looked at):
  ``suitability_std_m``, the mean along the cell's true track (1 Hz) of the terrain
  suitability's predicted position std after ``PINGS`` pings (``tanbench.suitability``;
  the method's sensor, the cell's navigation map and range noise, the track's median
  altitude); ``information_per_ping``, the mean along the track of trace(J_ping); and
  ``pcrb_mean_m``, the time average of the method's PCRB (``bounds.pcrb``);
* **outcomes**, from the stored runs: the mean final and time-averaged horizontal errors.

Spearman rank correlations between each predictor and each outcome, per method and
over all methods pooled, go into ``prediction.md`` / ``prediction.parquet``; a scatter
figure ``prediction.png`` shows each predictor against the time-averaged error. A good
predictor has a large positive rho for the stds and the bound (more uncertainty, more
error) and a negative one for the information.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from tanbench.errors import TanbenchError
from tanbench import store
from tanbench.bounds.pcrb import method_bound
from tanbench.methods import get
from tanbench.plot import method_styles, pyplot
from tanbench.results import load, summarize, to_markdown
from tanbench.simulation import motion_plan
from tanbench.suitability import sensor_beams, suitability
from tanbench.sweep import load_results_sweep
from tanbench.terrain import navigation_map, truth_map
from tanbench.vehicle.trajectory import sample_path

PINGS = 10
PREDICTORS = ("suitability_std_m", "information_per_ping", "pcrb_mean_m")
OUTCOMES = ("mean_time_avg_error_m", "mean_final_error_m")


def cell_table(directory) -> pd.DataFrame:
    """Predictors and outcomes of every (cell, method) with successful runs in ``directory``."""
    directory = Path(directory)
    sweep = load_results_sweep(directory)
    runs = load(directory, status="ok")
    summary = summarize(runs, by=("cell_id", "method")).set_index(["cell_id", "method"])
    rows = []
    cache: dict[str, dict] = {}
    for cell in sweep.cells:
        sc = cell.scenario
        for method in sweep.spec.methods:
            spec = get(method).bound if (cell.cell_id, method) in summary.index else None
            if spec is None:
                continue
            sensor = spec[0]
            key = json.dumps([sc.world_key(), sc.map_resolution_m, sc.noise_m, sc.filter.initial_area_m, sensor])
            if key not in cache:
                cache[key] = _track_suitability(sc, sensor)
            bound = method_bound(sc, spec)
            s = summary.loc[(cell.cell_id, method)]
            rows.append({
                "results": directory.name, "cell_id": cell.cell_id, "area": sc.area,
                "map_resolution_m": sc.map_resolution_m, "noise_m": sc.noise_m,
                "sampling_time_s": sc.sampling_time_s, "particles": sc.particles, "method": method,
                "n_runs": int(s["n_runs"]), **cache[key],
                "pcrb_mean_m": float(np.nanmean(bound["pcrb_horizontal_m"])),
                **{o: float(s[o]) for o in OUTCOMES},
            })
    return pd.DataFrame(rows)


def _track_suitability(sc, sensor: str) -> dict:
    """Mean predicted std and information per ping along ``sc``'s true track."""
    _, pos = sample_path(motion_plan(sc), 1.0)
    altitude = float(np.nanmedian(pos[:, 2] - truth_map(sc.terrain).elevation(pos[:, 0], pos[:, 1])))
    if sc.noise_m <= 0:
        return {"suitability_std_m": np.nan, "information_per_ping": np.nan}
    result = suitability(navigation_map(sc.terrain, sc.map_resolution_m), sensor_beams(sensor, sc), altitude,
                         sc.noise_m / np.sqrt(3.0), PINGS, sc.filter.initial_area_m, sensor=sensor)
    along = result.along(pos[:, 0], pos[:, 1])
    return {"suitability_std_m": float(np.nanmean(along["predicted_std_m"])),
            "information_per_ping": float(np.nanmean(along["information_per_ping"]))}


def correlations(cells: pd.DataFrame) -> pd.DataFrame:
    """Spearman rho (and its p-value) of each predictor with each outcome, per method and pooled."""
    rows = []
    groups = [(m, g) for m, g in cells.groupby("method", sort=False)] + [("all", cells)]
    for method, g in groups:
        for p in PREDICTORS:
            for o in OUTCOMES:
                ok = g[[p, o]].dropna()
                if len(ok) >= 3 and ok[p].nunique() > 1 and ok[o].nunique() > 1:
                    rho, pval = stats.spearmanr(ok[p], ok[o])
                else:
                    rho = pval = np.nan
                rows.append({"method": method, "predictor": p, "outcome": o, "n_cells": int(len(ok)),
                             "spearman_rho": float(rho), "p_value": float(pval)})
    return pd.DataFrame(rows)


def plot_prediction(cells: pd.DataFrame, path: Path) -> None:
    plt = pyplot()
    style = method_styles(sorted(set(cells["method"])))
    fig, axes = plt.subplots(1, len(PREDICTORS), figsize=(13, 4.2))
    markers = {"A": "o", "B": "s", "vehicle": "^", "custom": "D"}
    for ax, p in zip(axes, PREDICTORS):
        for (method, area), g in cells.groupby(["method", "area"]):
            ax.scatter(g[p], g["mean_time_avg_error_m"], color=style[method][1],
                       marker=markers.get(area, "x"), s=28, alpha=0.8, label=f"{method}, {area}")
        ax.set(xscale="log", yscale="log", xlabel=p, ylabel="mean time-averaged error (m)")
        ax.grid(alpha=0.3, which="both")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="upper center", ncol=min(len(labels), 6))
    fig.tight_layout(rect=(0, 0, 1, 0.88))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_prediction(directories, out) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The cells table, the correlations, and their files under ``out``."""
    frames = [cell_table(d) for d in directories]
    cells = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    if cells.empty:
        raise TanbenchError("no cell with successful runs of a built-in method in the results given")
    corr = correlations(cells)
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TanbenchError(f"cannot create {out}: {exc.strerror or exc}") from None
    store.write_parquet(cells, out / "prediction_cells.parquet", {"kind": "prediction"})
    store.write_parquet(corr, out / "prediction.parquet", {"kind": "prediction"})
    text = (to_markdown(corr, title="Spearman rank correlation of predictors with the errors")
            + "\n" + to_markdown(cells.drop(columns=["cell_id"]), title="cells"))
    store.write_text(text, out / "prediction.md")
    plot_prediction(cells, out / "prediction.png")
    return cells, corr
