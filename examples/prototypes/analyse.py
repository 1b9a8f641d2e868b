"""The statistics of docs/filters.md section 1 from ``measure.py``'s runs.

    ../../.venv/bin/python analyse.py OUT --worlds A,B --variants tight-dvl,pmf-dvl [--pairs a:b,...] [--summary]

Per world and variant: the per-run statistics (phase ratios, bias share, NEES, ESS, heading
collapse), their means over the converged, not-lost runs with 95 % bootstrap intervals, the
lost runs, and (``--pairs``) paired differences of per-run statistics with 95 % t intervals.
``--summary`` prints the prototype comparison columns only (final error, lost, ratio, wall).
"""

from __future__ import annotations

import argparse
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

LOST_M = 75.0
SETTLE_S = 100.0
BIN_S = 50.0


def load(out, world, variant) -> pd.DataFrame | None:
    files = sorted((Path(out) / world / variant).glob("run-*.parquet"))
    if not files:
        return None
    return pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)


@lru_cache(maxsize=None)
def nav_map(world):
    from measure import scenario_of
    from tanbench.terrain import navigation_map

    _, sc = scenario_of(world, {})
    return navigation_map(sc.terrain, sc.map_resolution_m), sc.particles


def slope_at(world, e, n):
    from tanbench.terrain.stats import gradient

    m, _ = nav_map(world)
    ge, gn = gradient(m, np.asarray(e, float), np.asarray(n, float))
    return np.hypot(ge, gn)


def boot_ci(values, n_boot=2000, seed=0):
    v = np.asarray([x for x in values if np.isfinite(x)], float)
    if v.size == 0:
        return np.nan, np.nan, np.nan
    if v.size == 1:
        return v[0], np.nan, np.nan
    rng = np.random.default_rng(seed)
    means = rng.choice(v, (n_boot, v.size)).mean(axis=1)
    return v.mean(), np.percentile(means, 2.5), np.percentile(means, 97.5)


def t_ci(values):
    v = np.asarray([x for x in values if np.isfinite(x)], float)
    if v.size < 2:
        return (v.mean() if v.size else np.nan), np.nan, np.nan
    half = stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / np.sqrt(v.size)
    return v.mean(), v.mean() - half, v.mean() + half


def rms_ratio(err, pcrb, mask):
    if mask.sum() == 0 or not np.isfinite(pcrb[mask]).all():
        return np.nan
    return float(np.sqrt(np.mean(err[mask] ** 2)) / np.sqrt(np.mean(pcrb[mask] ** 2)))


def correlation_time(t, ee, en):
    """Lag (s) at which the autocorrelation of the error's components (their mean) first drops below 1/e."""
    if t.size < 20:
        return np.nan
    acs = []
    for x in (ee, en):
        x = x - x.mean()
        f = np.fft.rfft(x, 2 * x.size)
        ac = np.fft.irfft(f * np.conj(f))[:x.size]
        acs.append(ac / ac[0])
    ac = np.mean(acs, axis=0)
    below = np.nonzero(ac < np.exp(-1.0))[0]
    return float(below[0] * (t[1] - t[0])) if below.size else np.nan


def run_stats(r: pd.DataFrame, world: str, particles: int) -> dict:
    t = r["t"].to_numpy() - r["t"].iloc[0]
    err = r["horizontal_error_m"].to_numpy()
    ee, en = r["east_error_m"].to_numpy(), r["north_error_m"].to_numpy()
    pcrb = r["pcrb_horizontal_m"].to_numpy()
    tc = r["m_convergence_time_s"].iloc[0]
    final = r["m_final_horizontal_error_m"].iloc[0]
    out = {"run": int(r["run"].iloc[0]), "final": final, "lost": final > LOST_M, "tc": tc,
           "ratio": r["m_rmse_pcrb_ratio"].iloc[0], "wall": r["m_filter_wall_s"].iloc[0],
           "reinit": r["m_reinitialisations"].iloc[0], "heading_final": r["m_final_heading_error_deg"].iloc[0]}
    if not np.isfinite(tc):
        return out
    conv, settle = t < tc, (t >= tc) & (t < tc + SETTLE_S)
    steady = t >= tc + SETTLE_S
    out.update(ratio_conv=rms_ratio(err, pcrb, conv), ratio_settle=rms_ratio(err, pcrb, settle),
               ratio_steady=rms_ratio(err, pcrb, steady), rmse_steady=float(np.sqrt(np.mean(err[steady] ** 2)))
               if steady.any() else np.nan,
               pcrb_steady=float(np.sqrt(np.mean(pcrb[steady] ** 2))) if steady.any() else np.nan,
               steady_n=int(steady.sum()))
    if steady.any():
        b = np.hypot(ee[steady].mean(), en[steady].mean())
        out["bias_share"] = float(b / np.sqrt(np.mean(err[steady] ** 2)))
        out["corr_time_s"] = correlation_time(t[steady], ee[steady], en[steady])
        if "nees" in r:
            out["nees_steady"] = float(np.nanmean(r["nees"].to_numpy()[steady]))
        out["_slope"] = slope_at(world, r["truth_e"].to_numpy()[steady], r["truth_n"].to_numpy()[steady])
        out["_err"], out["_pcrb"] = err[steady], pcrb[steady]
    if "ess" in r and np.isfinite(r["ess"]).any():
        ess = r["ess"].to_numpy() / particles
        for name, mask in (("conv", conv), ("settle", settle), ("steady", steady)):
            out[f"ess_{name}"] = float(np.median(ess[mask])) if mask.any() else np.nan
            out[f"resample_{name}"] = float(np.mean(ess[mask] < 0.5)) if mask.any() else np.nan
    if "var_heading" in r and steady.any():
        sd = np.sqrt(r["var_heading"].to_numpy()[steady])
        he = np.abs(r["heading_error_deg"].to_numpy()[steady])
        out["heading_collapse"] = float(np.mean(sd < he / 3.0))
        with np.errstate(divide="ignore"):
            out["heading_nees"] = float(np.mean(he ** 2 / np.maximum(sd ** 2, 1e-12)))
        out["heading_std_steady"] = float(np.median(sd))
        out["heading_err_steady"] = float(np.sqrt(np.mean(he ** 2)))
        if "pcrb_heading_deg" in r:
            ph = r["pcrb_heading_deg"].to_numpy()[steady]
            out["heading_ratio_steady"] = float(np.sqrt(np.mean(he ** 2)) / np.sqrt(np.mean(ph ** 2)))
    return out


def world_stats(out_dir, world, variant):
    df = load(out_dir, world, variant)
    if df is None:
        return None, None
    _, particles = nav_map(world)
    runs = [run_stats(r, world, particles) for _, r in df.groupby("run")]
    # flat / rough thirds of this variant's pooled steady-phase slopes
    pooled = np.concatenate([s["_slope"] for s in runs if "_slope" in s] or [np.array([np.nan])])
    lo, hi = np.nanpercentile(pooled, [100 / 3, 200 / 3]) if np.isfinite(pooled).any() else (np.nan, np.nan)
    for s in runs:
        if "_slope" in s:
            s["ratio_flat"] = rms_ratio(s["_err"], s["_pcrb"], s["_slope"] <= lo)
            s["ratio_rough"] = rms_ratio(s["_err"], s["_pcrb"], s["_slope"] >= hi)
            for k in ("_slope", "_err", "_pcrb"):
                del s[k]
    return pd.DataFrame(runs), df


def mc_nees_bins(df, n_ok_runs):
    """Fraction of 50 s bins whose Monte Carlo mean NEES (over the not-lost runs) leaves the 95 % band."""
    from tanbench.metrics.consistency import mc_bounds

    if "nees" not in df or not np.isfinite(df["nees"]).any():
        return np.nan, np.nan
    d = df[df["run"].isin(n_ok_runs)].copy()
    d["bin"] = ((d["t"] - d["t"].min()) // BIN_S).astype(int)
    g = d.groupby(["bin", "run"])["nees"].mean().groupby("bin")
    means, counts = g.mean(), g.count()
    lo, hi = mc_bounds(counts.to_numpy())
    outside = (means.to_numpy() < lo) | (means.to_numpy() > hi)
    return float(outside.mean()), float(means.iloc[-5:].mean())


COLUMNS = ["ratio", "ratio_conv", "ratio_settle", "ratio_steady", "ratio_flat", "ratio_rough", "rmse_steady",
           "pcrb_steady", "bias_share", "corr_time_s", "heading_ratio_steady", "nees_steady", "ess_conv", "ess_steady", "resample_conv", "resample_steady",
           "heading_collapse", "heading_nees", "heading_std_steady", "heading_err_steady", "tc", "final", "wall",
           "reinit"]


def fmt(m, lo, hi):
    if not np.isfinite(m):
        return "-"
    if not np.isfinite(lo):
        return f"{m:.3g}"
    return f"{m:.3g} [{lo:.3g}, {hi:.3g}]"


def markdown(frame: pd.DataFrame) -> str:
    head = ["", *map(str, frame.columns)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for idx, row in frame.iterrows():
        lines.append("| " + " | ".join([str(idx), *("" if pd.isna(v) else str(v) for v in row)]) + " |")
    return "\n".join(lines)


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--worlds", required=True)
    p.add_argument("--variants", required=True)
    p.add_argument("--pairs", default="")
    p.add_argument("--columns", default=",".join(COLUMNS))
    p.add_argument("--summary", action="store_true")
    a = p.parse_args(argv)
    cols = ["final", "ratio", "wall", "tc"] if a.summary else a.columns.split(",")
    for world in a.worlds.split(","):
        print(f"\n## {world}\n")
        per = {}
        rows = []
        for v in a.variants.split(","):
            s, df = world_stats(a.out, world, v)
            if s is None:
                continue
            per[v] = s
            ok = s[~s["lost"]]
            row = {"variant": v, "runs": len(s), "lost": int(s["lost"].sum()),
                   "max final": f"{s['final'].max():.1f}"}
            if a.summary:
                row["mean final (all)"] = fmt(*t_ci(s["final"]))
            for c in cols:
                if c in ok:
                    row[c] = fmt(*(t_ci(ok[c]) if c in ("final", "wall") else boot_ci(ok[c])))
            if not a.summary:
                out_frac, end_nees = mc_nees_bins(df, set(ok["run"]))
                row["NEES bins out of band"] = f"{out_frac:.2f}" if np.isfinite(out_frac) else "-"
                row["MC NEES last 250 s"] = f"{end_nees:.3g}" if np.isfinite(end_nees) else "-"
            rows.append(row)
        if rows:
            print(markdown(pd.DataFrame(rows).set_index("variant").T))
        for pair in filter(None, a.pairs.split(",")):
            x, y = pair.split(":")
            if x not in per or y not in per:
                continue
            j = per[x].merge(per[y], on="run", suffixes=("_x", "_y"))
            print(f"\npaired {y} - {x} ({len(j)} runs):")
            for c in ("final", "ratio", "ratio_steady", "rmse_steady", "heading_collapse", "wall"):
                if f"{c}_x" in j:
                    diff = j[f"{c}_y"] - j[f"{c}_x"]
                    print(f"  {c}: {fmt(*t_ci(diff))}")


if __name__ == "__main__":
    main()
