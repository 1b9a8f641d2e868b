"""The multibeam study's pre-registered comparisons (docs/multibeam.md, section 5), from results/multibeam.

    python examples/multibeam_comparisons.py results/multibeam > results/multibeam/COMPARISONS.md

Fixed before the study ran: the statistic is the paired mean difference of the final horizontal
error over the runs where neither method diverged (diverged runs are counted apart, never in a
mean), with its two-sided 95 % t interval; an effect is claimed only when the interval excludes
zero. Each line also gives the interval's half-width: the smallest difference the comparison
could have detected at its run count.

* C1, per world: tight-mbe at 64 beams over a 120-degree fan against tight-dvl (the 4-beam DVL),
  on the same runs (the cell of ``budget-beams`` / ``budget-beams-monterey`` at 64 beams);
* C2, per world: pmf-mbe at 64 beams against tight-mbe at 64 beams, same cell;
* C3, area A, 256 beams thinned to 16: ``selection: information`` against ``every-kth``, per
  method (the two cells of ``thinning``; the cells share their vehicle data, run by run).
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd
from scipy import stats

from tanbench.results import load


def world(row) -> str:
    return "Monterey" if row["area"] == "custom" else f"area {row['area']}"


def paired(a: pd.DataFrame, b: pd.DataFrame, label: str) -> str:
    """``label``: mean of a - b (final horizontal error) over runs where neither diverged, 95 % t interval."""
    cols = ["final_horizontal_error_m", "diverged"]
    m = a.set_index("run")[cols].add_suffix("_a").join(b.set_index("run")[cols].add_suffix("_b"), how="inner")
    lost_a, lost_b = int(m["diverged_a"].sum()), int(m["diverged_b"].sum())
    ok = m[~m["diverged_a"].astype(bool) & ~m["diverged_b"].astype(bool)]
    d = (ok["final_horizontal_error_m_a"] - ok["final_horizontal_error_m_b"]).to_numpy()
    n = d.size
    if n < 2:
        return f"| {label} | {n} | {lost_a} / {lost_b} | n/a | n/a | n/a | too few paired runs |"
    mean = float(d.mean())
    half = float(stats.t.ppf(0.975, n - 1) * d.std(ddof=1) / np.sqrt(n))
    verdict = "no effect shown (interval includes 0)" if mean - half <= 0 <= mean + half else \
        ("first lower" if mean < 0 else "first higher")
    return (f"| {label} | {n} | {lost_a} / {lost_b} | {mean:+.2f} | [{mean - half:+.2f}, {mean + half:+.2f}] | "
            f"{half:.2f} | {verdict} |")


def main(directory: str) -> None:
    runs = load(directory)
    runs = runs[runs["status"] == "ok"].copy()
    runs["world"] = runs.apply(world, axis=1)
    print("# Multibeam study: the pre-registered comparisons (docs/multibeam.md, section 5)\n")
    print("Paired mean difference of the final horizontal error (m), first minus second, over the runs where "
          "neither diverged; diverged runs (first / second) are counted apart. Effect only when the 95 % t "
          "interval excludes 0; the half-width is what the comparison could detect at its run count.\n")
    print("| comparison | paired runs | diverged | mean difference (m) | 95 % interval | half-width | verdict |")
    print("|---|---|---|---|---|---|---|")
    budget = runs[runs["tables"].astype(str).str.contains("budget-beams")]
    at64 = budget[(budget["sensors.multibeam_beams"] == 64) & (budget["sensors.multibeam_swath_deg"] == 120.0)]
    for w in sorted(at64["world"].unique()):
        cell = at64[at64["world"] == w]
        mbe, dvl, pmf = (cell[cell["method"] == m] for m in ("tight-mbe", "tight-dvl", "pmf-mbe"))
        print(paired(mbe, dvl, f"C1 {w}: tight-mbe (64 beams) - tight-dvl"))
        print(paired(pmf, mbe, f"C2 {w}: pmf-mbe (64 beams) - tight-mbe (64 beams)"))
    thin = runs[runs["tables"].astype(str).str.contains("thinning")]
    if not thin.empty:
        for method in ("tight-mbe", "pmf-mbe"):
            pick = thin[f"method_options.{method}.selection"].astype(str) == "information"
            info = thin[pick & (thin["method"] == method)]
            kth = thin[~pick & (thin["method"] == method)]
            print(paired(info, kth, f"C3 area A, {method}, 16 of 256 beams: information - every-kth"))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "results/multibeam")
