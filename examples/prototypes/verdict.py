"""The proposed whole-run NEES verdict (docs/filters.md section 2) beside the current one.

    ../../.venv/bin/python verdict.py OUT --worlds A,B --variants tight-dvl,pmf-dvl
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def anees_verdict(runs):
    """(ANEES, band low, band high, share of runs whose reported std is below the bound, verdict) of a cell;
    ``runs`` is a list of per-run frames with ``nees`` and, for the bound rule, ``var_e``, ``var_n``,
    ``pcrb_horizontal_m``."""
    from tanbench.metrics.consistency import mc_bounds

    per_run = [float(np.nanmean(r["nees"])) for r in runs if np.isfinite(r["nees"]).any()]
    if not per_run:
        return np.nan, np.nan, np.nan, np.nan, "-"
    n = len(per_run)
    anees = float(np.mean(per_run))
    lo, hi = (float(v) for v in mc_bounds(n))
    below = []
    for r in runs:
        if "pcrb_horizontal_m" in r and np.isfinite(r["pcrb_horizontal_m"]).all():
            below.append(np.sqrt(np.mean(r["var_e"] + r["var_n"])) < np.sqrt(np.mean(r["pcrb_horizontal_m"] ** 2)))
    share = float(np.mean(below)) if below else np.nan
    if anees > hi:
        verdict = "over-confident"
    elif below and share > 0.5:
        verdict = "over-confident (below the bound)"
    elif anees < lo:
        verdict = "under-confident"
    else:
        verdict = "consistent"
    return anees, lo, hi, share, verdict


def main(argv=None):
    from analyse import load
    from tanbench.metrics.consistency import cell_verdict

    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--worlds", required=True)
    p.add_argument("--variants", required=True)
    a = p.parse_args(argv)
    print("| world | method | runs | current verdict (above 95 % share) | ANEES [band] | std below bound (runs) | "
          "proposed verdict |")
    print("|---|---|---|---|---|---|---|")
    for world in a.worlds.split(","):
        for v in a.variants.split(","):
            df = load(a.out, world, v)
            if df is None:
                continue
            runs = [r for _, r in df.groupby("run")]
            above = np.array([r["m_nees_above_95"].iloc[0] for r in runs])
            below = np.array([r["m_nees_below_95"].iloc[0] for r in runs])
            anees, lo, hi, share, verdict = anees_verdict(runs)
            print(f"| {world} | {v} | {len(runs)} | {cell_verdict(above, below)} ({np.nanmean(above):.2f}) | "
                  f"{anees:.3g} [{lo:.2f}, {hi:.2f}] | {share:.2f} | {verdict} |")


if __name__ == "__main__":
    main()
