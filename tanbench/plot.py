"""Figures for a results directory (matplotlib, the ``plot`` extra).

For one cell per area by default (the first of the sweep in each area, i.e. its default
cell), or for the cells asked for (``--cell ID``, ``--cell all``), the analogs of the
paper's Figures 4-7 (area A), 8-11 (area B) and 14-15 (vehicle run): east, north and
horizontal position and error against time, heading against time, the Monte Carlo mean
of each method with the truth in black; and the tracks over the map's contours (Figures
2-3, 6, 10). Written as PNG under ``DIR/figures/``: ``<area>_<figure>.png`` for the
default cell of an area, ``<area>_<cell id>_<figure>.png`` for any other cell. Every
figure's title names its cell (id and the values its tables vary).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.metrics.consistency import anees_of_series, mc_bounds, whole_run_verdict
from tanbench.methods.registry import get
from tanbench.results import load, load_series
from tanbench.sweep import load_results_sweep
from tanbench.terrain import navigation_map

# colours for methods whose record names none (user methods), in order of appearance, after those no plotted
# method's record takes (the built-ins take tab:blue, red, orange, green, purple, brown, olive and gray)
SPARE_COLORS = ("tab:pink", "tab:cyan", "black", "gold", "teal", "navy", "magenta", "lime", "tab:green",
                "tab:orange", "tab:brown", "tab:olive", "tab:gray")


def _records(methods) -> dict:
    """Each method's registry record, or None where it cannot be imported here."""
    records = {}
    for m in methods:
        try:
            records[m] = get(m)
        except TanbenchError:
            records[m] = None
    return records


def method_styles(methods) -> dict[str, tuple[str, str]]:
    """(line style, colour) per method: the registry's plot style, spare colours for the rest
    (and for a user method that cannot be imported where the figures are drawn), never one that
    a plotted method's record takes while an untaken one is left."""
    records = _records(methods)
    taken = {r.color for r in records.values() if r is not None and r.color}
    spare = iter([c for c in SPARE_COLORS if c not in taken] + list(SPARE_COLORS) * 4)
    return {m: ((r.linestyle, r.color) if r is not None and r.color else (r.linestyle if r else "-", next(spare)))
            for m, r in records.items()}


def unstyled_methods(directory) -> list[str]:
    """The methods of ``directory``'s sweep that cannot be imported here: the figures draw them in a spare
    colour, not in their record's style (``tanbench plot`` says so)."""
    try:
        methods = load_results_sweep(Path(directory)).spec.methods
    except TanbenchError:  # --frontier draws from the runs alone: so do its notes
        methods = sorted(set(load(directory)["method"]))
    return [m for m, record in _records(methods).items() if record is None]


def pyplot():
    """matplotlib.pyplot on the Agg backend; one clear error line when matplotlib is missing."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise TanbenchError("plotting needs matplotlib: pip install 'tanbench[plot]'") from None
    return plt


def representative_cells(sweep) -> list:
    """The first cell of the sweep in each area (its defaults there)."""
    seen, out = set(), []
    for cell in sweep.cells:
        if cell.scenario.area not in seen:
            seen.add(cell.scenario.area)
            out.append(cell)
    return out


def cell_title(cell) -> str:
    """How a figure names its cell: area, id and the values its tables vary."""
    varied = ", ".join(f"{k}={v}" for k, v in cell.varied.items() if k != "area") or "defaults"
    return f"area {cell.scenario.area}, cell {cell.cell_id} ({varied})"


def select_cells(sweep, stored: set, wanted: list[str] | None) -> list:
    """The cells to draw: the default cell of each area, every cell (``["all"]``) or the ids
    (or unique id prefixes) in ``wanted``; only cells whose series are stored."""
    with_series = [c for c in sweep.cells if c.cell_id in stored]
    if not wanted:
        return [c for c in representative_cells(sweep) if c.cell_id in stored]
    if "all" in wanted:
        return with_series
    chosen = []
    for want in wanted:
        found = [c for c in with_series if c.cell_id.startswith(want)]
        if len(found) != 1:
            known = "; ".join(cell_title(c) for c in with_series)
            raise TanbenchError(f"--cell {want}: {'no' if not found else 'more than one'} cell with stored series "
                                f"has this id (cells: {known}; or --cell all)")
        if found[0] not in chosen:
            chosen.append(found[0])
    return chosen


def plot_results(directory, cells: list[str] | None = None) -> list[Path]:
    """Write the figures of ``directory`` for the cells asked for (see :func:`select_cells`);
    returns the files written."""
    plt = pyplot()
    directory = Path(directory)
    sweep = load_results_sweep(directory)
    series = load_series(directory)
    below = below_bound_shares(directory)
    figdir = directory / "figures"
    chosen = select_cells(sweep, set(series["cell_id"]), cells)
    try:
        figdir.mkdir(parents=True, exist_ok=True)
        return _draw(sweep, chosen, series, figdir, plt, below)
    except OSError as exc:
        raise TanbenchError(f"cannot write the figures under {figdir} ({exc.strerror or exc}); "
                            f"plot a writable copy of {directory}") from None


def _draw(sweep, cells, series, figdir: Path, plt, below=None) -> list[Path]:
    written = []
    defaults = {c.cell_id for c in representative_cells(sweep)}
    for cell in cells:
        s = series[series["cell_id"] == cell.cell_id]
        label = cell.scenario.area if cell.cell_id in defaults else f"{cell.scenario.area}_{cell.cell_id}"
        title = cell_title(cell)
        methods = [m for m in sweep.spec.methods if m in set(s["method"])]
        style = method_styles(methods)
        first = s[s["method"] == methods[0]]
        t = first["t"].to_numpy()
        for comp, name in (("e", "east"), ("n", "north")):
            fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
            ax1.plot(t, first[f"truth_{comp}"], "k-", lw=1.5, label="truth")
            for m in methods:
                sm = s[s["method"] == m]
                ax1.plot(sm["t"], sm[f"est_{comp}"], style[m][0], color=style[m][1], label=m)
                ax2.plot(sm["t"], sm[f"{name}_error_m_mean"], style[m][0], color=style[m][1], label=m)
            ax1.set_ylabel(f"relative {name} (m)")
            ax2.set_ylabel(f"{name} error (m)")
            ax2.set_xlabel("time (s)")
            ax1.legend(fontsize=8)
            ax1.set_title(f"{title}\n{name} position and error, Monte Carlo mean", fontsize=10)
            written.append(_save(fig, figdir / f"{label}_{name}.png", plt))
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 5))
        nmap = navigation_map(cell.scenario.terrain, cell.scenario.map_resolution_m)
        _contours(ax1, nmap, first, margin=200.0)
        ax1.plot(first["truth_e"], first["truth_n"], "k-", lw=1.5, label="truth")
        for m in methods:
            sm = s[s["method"] == m]
            ax1.plot(sm["est_e"], sm["est_n"], style[m][0], color=style[m][1], label=m)
            ax2.plot(sm["t"], sm["horizontal_error_m_mean"], style[m][0], color=style[m][1], label=m)
            ax2.fill_between(sm["t"], sm["horizontal_error_m_p05"], sm["horizontal_error_m_p95"],
                             color=style[m][1], alpha=0.12)
        ax1.set_xlabel("east (m)")
        ax1.set_ylabel("north (m)")
        ax1.legend(fontsize=8)
        ax1.set_title("horizontal position (MC mean)", fontsize=10)
        ax2.set_xlabel("time (s)")
        ax2.set_ylabel("horizontal error (m)")
        ax2.set_title("horizontal error: MC mean, 5-95 % band", fontsize=10)
        fig.suptitle(title, fontsize=11)
        written.append(_save(fig, figdir / f"{label}_horizontal.png", plt))
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
        # unwrapped so a track through north does not jump between 0 and 360 deg
        truth_heading = np.degrees(np.unwrap(np.radians(first["truth_heading_deg"].to_numpy())))
        ax1.plot(t, truth_heading, "k-", lw=1.5, label="truth")
        for m in methods:
            sm = s[s["method"] == m]
            est = truth_heading[: len(sm)] + sm["heading_error_deg_mean"].to_numpy()
            ax1.plot(sm["t"], est, style[m][0], color=style[m][1], label=m)
            ax2.plot(sm["t"], sm["heading_error_deg_abs_mean"], style[m][0], color=style[m][1], label=m)
        ax1.set_ylabel("heading (deg)")
        ax2.set_ylabel("|heading error| (deg)")
        ax2.set_xlabel("time (s)")
        ax1.legend(fontsize=8)
        ax1.set_title(f"{title}\nheading, Monte Carlo mean", fontsize=10)
        written.append(_save(fig, figdir / f"{label}_heading.png", plt))
        if "pcrb_horizontal_m" in s.columns:
            written.append(_bound_and_nees(s, methods, style, label, title, figdir, plt, below or {}))
    written += _track_maps(cells, series, figdir, plt, by_group=not {c.cell_id for c in cells} <= defaults)
    return written


def below_bound_shares(directory) -> dict:
    """(cell_id, method) -> the share of its ok runs whose reported std is below the bound (the
    verdict's second input, metrics.consistency.whole_run_verdict); empty for older results."""
    runs = load(directory, status="ok")
    if "reported_std_below_bound" not in runs.columns:
        return {}
    g = runs.groupby(["cell_id", "method"])["reported_std_below_bound"].mean()
    return {k: float(v) for k, v in g.items()}


def figure_verdict(sm, below_share=float("nan")) -> tuple[float, str, tuple[float, float]]:
    """(ANEES, verdict, band) of one method's summary series ``sm``, read off the figure's curve
    (the time average of the Monte Carlo mean NEES) with the table's function."""
    n = int(sm["n_runs"].max()) if len(sm) else 0
    anees = anees_of_series(sm["nees_mean"])
    band = tuple(float(b) for b in mc_bounds(n)) if n else (float("nan"), float("nan"))
    return anees, whole_run_verdict(anees, n, below_share), band


def _bound_and_nees(s, methods, style, label, title, figdir, plt, below) -> Path:
    """RMS error beside each method's PCRB; the Monte Carlo mean NEES with its chi-square bounds,
    each method's whole-run ANEES as a horizontal line, the band of the verdict shaded and the
    verdict in the legend (the table's verdict, from the same function)."""
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for m in methods:
        sm = s[s["method"] == m]
        ax1.plot(sm["t"], sm["horizontal_error_m_rms"], style[m][0], color=style[m][1], label=f"{m} RMSE")
        if sm["pcrb_horizontal_m"].notna().any():
            ax1.plot(sm["t"], sm["pcrb_horizontal_m"], "-", color=style[m][1], lw=0.8, alpha=0.7,
                     label=f"{m} PCRB")
        if sm["nees_mean"].notna().any():
            cell = sm["cell_id"].iloc[0]
            anees, verdict, band = figure_verdict(sm, below.get((cell, m), float("nan")))
            ax2.plot(sm["t"], sm["nees_mean"], style[m][0], color=style[m][1], lw=0.8)
            ax2.axhline(anees, color=style[m][1], lw=2.0, alpha=0.8,
                        label=f"{m}: ANEES {anees:.3g}, {verdict}")
    first = s[s["method"] == methods[0]]
    ax2.fill_between(first["t"], first["nees_mc_low"], first["nees_mc_high"], color="gray", alpha=0.25,
                     label="95 % band of the mean NEES and of ANEES (consistent filter)")
    ax1.set(yscale="log", ylabel="horizontal RMSE and PCRB (m)",
            title=f"{title}\nRMS error over runs beside the posterior Cramér-Rao bound")
    ax2.set(yscale="log", ylabel="mean NEES", xlabel="time (s)",
            title="consistency: Monte Carlo mean NEES; lines: whole-run ANEES and verdict (docs/model.md 9.2)")
    ax1.legend(fontsize=7, ncol=2)
    ax2.legend(fontsize=7)
    return _save(fig, figdir / f"{label}_bound_nees.png", plt)


def _contours(ax, nmap, first, margin):
    e, n = nmap.node_coords()
    lo_e, hi_e = first["truth_e"].min() - margin, first["truth_e"].max() + margin
    lo_n, hi_n = first["truth_n"].min() - margin, first["truth_n"].max() + margin
    je = (e >= lo_e) & (e <= hi_e)
    jn = (n >= lo_n) & (n <= hi_n)
    cs = ax.contour(e[je], n[jn], nmap.z[np.ix_(jn, je)], levels=15, cmap="viridis", linewidths=0.6)
    ax.clabel(cs, fontsize=6, fmt="%.0f")
    ax.set_aspect("equal")


def _track_maps(cells, series, figdir, plt, by_group: bool = False) -> list[Path]:
    """Tracks over the contours of each terrain (Figures 2-3): ``tracks.png``, ``tracks_2.png``, ...
    for the default cells, ``tracks_<first cell id>.png`` for others (``by_group``)."""
    out = []
    by_terrain = {}
    for cell in cells:
        key = (cell.scenario.terrain.model_dump_json(), cell.scenario.map_resolution_m)
        by_terrain.setdefault(key, []).append(cell)
    for k, group in enumerate(by_terrain.values()):
        sc = group[0].scenario
        nmap = navigation_map(sc.terrain, sc.map_resolution_m)
        fig, ax = plt.subplots(figsize=(12, 5.5))
        e, n = nmap.node_coords()
        cs = ax.contourf(e, n, nmap.z, levels=25, cmap="viridis")
        fig.colorbar(cs, ax=ax, label="elevation (m)")
        for cell in group:
            s = series[series["cell_id"] == cell.cell_id]
            first = s[s["method"] == s["method"].iloc[0]]
            ax.plot(first["truth_e"], first["truth_n"], "r-", lw=1.2)
            ax.annotate(f"area {cell.scenario.area}, cell {cell.cell_id}", (first["truth_e"].iloc[0], first["truth_n"].iloc[0]),
                        color="w", fontsize=9, xytext=(5, -12), textcoords="offset points")
        ax.set_aspect("equal")
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        ax.set_title(f"tracks over the {sc.map_resolution_m:g} m navigation map ({nmap.name}); "
                     f"cell{'s' if len(group) > 1 else ''} {', '.join(c.cell_id for c in group)}", fontsize=10)
        name = f"tracks_{group[0].cell_id}.png" if by_group else ("tracks.png" if k == 0 else f"tracks_{k + 1}.png")
        out.append(_save(fig, figdir / name, plt))
    return out


def _save(fig, path: Path, plt) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def frontier_points(runs):
    """Per (world, method, cell): mean final error, mean filter wall time per run, divergence rate.

    The world is the area, or "file map <name>" for a custom area on a bathymetry file.
    """
    ok = runs[runs["status"] == "ok"].copy()
    stem = ok["terrain.path"].astype(str).str.extract(r"([A-Za-z]+)[^/]*$")[0].fillna("") \
        if "terrain.path" in ok else ""
    ok["world"] = np.where(ok["area"] == "custom", "file map " + stem, "area " + ok["area"].astype(str))
    g = ok.groupby(["world", "method", "cell_id"], sort=False)
    return g.agg(mean_final_error_m=("final_horizontal_error_m", "mean"),
                 mean_filter_wall_s=("filter_wall_s", "mean"),
                 divergence_rate=("diverged", "mean"), n_runs=("run", "size")).reset_index()


def plot_frontier(directory, cells=None) -> Path:
    """Accuracy against cost: mean final error against mean filter wall time per run, one panel per
    world, one line per method through its cells (budgets) in order of cost. ``cells``: only these
    cell ids (default: the cells of the tables named ``budget-*``, else all)."""
    plt = pyplot()
    directory = Path(directory)
    runs = load(directory)
    if cells is None:
        budget = runs["tables"].astype(str).map(lambda t: any(x.startswith("budget-") for x in t.split(",")))
        cells = set(runs.loc[budget, "cell_id"]) if budget.any() else set(runs["cell_id"])
    pts = frontier_points(runs[runs["cell_id"].isin(set(cells))])
    worlds = sorted(dict.fromkeys(pts["world"]))
    styles = method_styles(list(dict.fromkeys(pts["method"])))
    fig, axes = plt.subplots(1, len(worlds), figsize=(5.5 * len(worlds), 4.8), squeeze=False)
    for ax, world in zip(axes[0], worlds):
        sub = pts[pts["world"] == world]
        for method in dict.fromkeys(sub["method"]):
            sm = sub[sub["method"] == method].sort_values("mean_filter_wall_s")
            ls, color = styles[method]
            ax.plot(sm["mean_filter_wall_s"], sm["mean_final_error_m"], marker="o", ls=ls, color=color, label=method)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("filter wall time per run (s)")
        ax.set_ylabel("mean final horizontal error (m)")
        ax.set_title(f"{world}: accuracy against cost")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].legend(fontsize=7)
    figdir = directory / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    return _save(fig, figdir / "accuracy_cost.png", plt)
