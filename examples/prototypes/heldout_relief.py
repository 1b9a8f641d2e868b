"""Held-out real relief from another DEM (docs/filters.md section 8): windows and sweep files.

Reads matplotlib's sample DEM `jacksboro_fault_dem.npz` (USGS 3 arc-second, Jacksboro fault,
Tennessee) from the installed matplotlib, cuts four 2400 m windows at fixed fractions of its
extent at two horizontal scales (J1-J4 the DEM's own spacing, J5-J8 its nodes read as 24 m
apart), writes each window as an `.npz` in the Map convention (row 0 south) and one sweep file
per world. Everything after the window (resampling to 8 m, rescaling to -180..-60 m, the 24 m
map, the survey) is tanbench's own options.

    .venv/bin/python examples/prototypes/heldout_relief.py OUT_DIR            # J1-J8
    .venv/bin/python examples/prototypes/heldout_relief.py OUT_DIR --second   # J9-J16
    .venv/bin/python examples/prototypes/heldout_relief.py OUT_DIR --third    # J17-J24 (40 m second scale)
    .venv/bin/python examples/prototypes/heldout_relief.py OUT_DIR --all      # J1-J24
    .venv/bin/python examples/prototypes/heldout_relief.py OUT_DIR --unseen   # J25-J40 (section 10's test worlds)
    .venv/bin/python examples/prototypes/heldout_relief.py OUT_DIR --section-17   # J41-J56 (section 17's)
    .venv/bin/python examples/prototypes/heldout_relief.py OUT_DIR --section-18   # J57-J72 (section 18's)
    .venv/bin/python examples/prototypes/heldout_relief.py OUT_DIR --topobathy    # J73-J80: another DEM (section 25)
    .venv/bin/tanbench run OUT_DIR/J1.yaml --out OUT_DIR/J1 --quiet --series none
    .venv/bin/python examples/prototypes/heldout_relief.py --summary RESULTS_DIR   # a table of RESULTS_DIR/J*/

`make heldout-relief` does all of it (worlds under .cache/heldout-relief, runs under
results/heldout-relief, the table in its SUMMARY.md).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import yaml

WINDOW_M = 2400.0
CENTRES = ((0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75))
# the second held-out set (docs/filters.md 8.3), fixed after J1-J8 had become development worlds
SECOND_CENTRES = ((0.5, 0.5), (0.5, 0.15), (0.15, 0.5), (0.85, 0.85))
# the third (docs/filters.md 8.4), fixed after J9-J16 had become development worlds: other centres, and a 40 m scale
THIRD_CENTRES = ((0.2, 0.8), (0.8, 0.2), (0.4, 0.6), (0.6, 0.4))
EARTH_R = 6_371_000.0
SETS = {  # name -> (first world number, centres, the second scale's node spacing (m), root seeds)
    "first": (1, CENTRES, 24.0, range(24240011, 24240019)),
    "second": (9, SECOND_CENTRES, 24.0, range(24240019, 24240027)),
    "third": (17, THIRD_CENTRES, 40.0, range(24240027, 24240035)),
}
# the test worlds of docs/filters.md section 10 (global recovery), fixed before any run on them: other centres,
# and two more scales (32 m and 16 m); `--unseen` builds them, `--all` (make heldout-relief) does not
UNSEEN_SETS = {
    "fourth": (25, ((0.35, 0.15), (0.65, 0.85), (0.12, 0.35), (0.88, 0.62)), 32.0, range(24240035, 24240043)),
    "fifth": (33, ((0.45, 0.3), (0.55, 0.7), (0.3, 0.45), (0.7, 0.55)), 16.0, range(24240043, 24240051)),
}
# the test worlds of docs/filters.md section 17 (the second search square), fixed before any run on them: other
# centres and two more scales (20 m and 28 m); `--section-17` builds them
SECTION_17_SETS = {
    "sixth": (41, ((0.4, 0.2), (0.6, 0.8), (0.2, 0.6), (0.8, 0.4)), 20.0, range(24240051, 24240059)),
    "seventh": (49, ((0.35, 0.65), (0.65, 0.35), (0.45, 0.85), (0.55, 0.2)), 28.0, range(24240059, 24240067)),
}
# the test worlds of docs/filters.md section 18 (the second square only beyond the first), fixed before any run on
# them: other centres and two more scales (12 m and 36 m); `--section-18` builds them
SECTION_18_SETS = {
    "eighth": (57, ((0.3, 0.3), (0.7, 0.7), (0.3, 0.7), (0.7, 0.3)), 12.0, range(24240067, 24240075)),
    "ninth": (65, ((0.5, 0.4), (0.5, 0.6), (0.4, 0.5), (0.6, 0.5)), 36.0, range(24240075, 24240083)),
}
# a second DEM (docs/filters.md section 25), fixed before any run on it: matplotlib's sample `topobathy.npz`
# (topography and bathymetry around 48-50 N, 122-126 W; 120 x 91 nodes about 2.4 km apart). A 2400 m window
# holds only 1-2 of its nodes at their own spacing, so each set reads them closer, at one scale
TOPOBATHY_SETS = {
    "tenth": (73, ((0.35, 0.45), (0.65, 0.55), (0.45, 0.58), (0.55, 0.42)), 32.0, range(24240083, 24240087)),
    "eleventh": (77, ((0.3, 0.35), (0.7, 0.35), (0.3, 0.65), (0.7, 0.65)), 40.0, range(24240087, 24240091)),
}


def read_topobathy() -> tuple[np.ndarray, float, float]:
    """matplotlib's sample topography-bathymetry grid with row 0 south, and its node spacing east and north in
    metres at its middle latitude."""
    import matplotlib.cbook as cbook

    d = cbook.get_sample_data("topobathy.npz")
    lat, lon = np.asarray(d["latitude"], float), np.asarray(d["longitude"], float)
    if not lat[1] > lat[0]:
        raise SystemExit("topobathy.npz: the latitudes are not south to north")
    dx = math.radians(lon[1] - lon[0]) * EARTH_R * math.cos(math.radians(0.5 * (lat[0] + lat[-1])))
    dy = math.radians(lat[1] - lat[0]) * EARTH_R
    return np.asarray(d["topo"], float), dx, dy


def read_dem() -> tuple[np.ndarray, float, float]:
    """The DEM with row 0 south, and its node spacing east and north in metres."""
    import matplotlib.cbook as cbook

    d = np.load(cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False))
    z = d["elevation"].astype(float)
    lat_mid = math.radians(0.5 * (float(d["ymin"]) + float(d["ymax"])))
    dx = math.radians(float(d["dx"])) * EARTH_R * math.cos(lat_mid)
    dy = math.radians(float(d["dy"])) * EARTH_R
    # the file's first row is at ymin = 36.733, the northern edge (ymax = 36.446 is south of it)
    return z[::-1].copy(), dx, dy


def window(z: np.ndarray, res_e: float, res_n: float, fe: float, fn: float) -> np.ndarray:
    """The nodes of a WINDOW_M square centred at fractions (fe, fn) of the grid's extent."""
    ne = int(round(WINDOW_M / res_e)) + 1
    nn = int(round(WINDOW_M / res_n)) + 1
    ce = int(round(fe * (z.shape[1] - 1)))
    cn = int(round(fn * (z.shape[0] - 1)))
    e0, n0 = ce - ne // 2, cn - nn // 2
    return z[n0:n0 + nn, e0:e0 + ne].copy()


def sweep_path(npz: Path) -> str:
    """The window's path as its sweep file names it: relative to the working directory (where tanbench
    runs) when the window lies below it, so that the cell keys, and with them the seeds, do not depend
    on where the project is checked out; absolute otherwise."""
    try:
        return str(npz.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(npz.resolve())


def sweep(name: str, seed: int, npz: Path | str, centre: tuple[float, float]) -> dict:
    return {
        "name": name,
        "description": f"held-out real relief {name} (docs/filters.md {25 if int(name[1:]) >= 73 else 8}): tight-dvl, "
                       f"tight-sbe, loose-dvl",
        "seed": seed, "runs": 10, "methods": ["tight-dvl", "tight-sbe", "loose-dvl"],
        "scenario": {
            "terrain": {"kind": "file", "path": str(npz), "resample_m": 8, "depth_range_m": [-180, -60]},
            "area": "custom",
            "trajectory": {"kind": "survey", "centre_en_m": list(centre), "heading_deg": 0.0,
                           "leg_length_m": 1400.0, "leg_spacing_m": 250.0, "legs": 3, "depth_m": 20.0},
            "map_resolution_m": 24, "noise_m": 1.0, "sampling_time_s": 1, "particles": 2000,
        },
    }


# the flags that build a group of sets, and every set by name
GROUPS = {"--all": SETS, "--unseen": UNSEEN_SETS, "--section-17": SECTION_17_SETS, "--section-18": SECTION_18_SETS,
          "--topobathy": TOPOBATHY_SETS}
ALL_SETS = {name: spec for group in GROUPS.values() for name, spec in group.items()}


def main(out: Path, which: str = "first") -> None:
    out.mkdir(parents=True, exist_ok=True)
    first, centres, spacing, seed_range = ALL_SETS[which]
    if which in TOPOBATHY_SETS:  # its own spacing holds no window: the set's one scale
        z, dx, dy = read_topobathy()
        scales = ((spacing, spacing),)
    else:
        z, dx, dy = read_dem()
        scales = ((dx, dy), (spacing, spacing))
    seeds = iter(seed_range)
    k = first - 1
    for res_e, res_n in scales:
        for fe, fn in centres:
            k += 1
            name = f"J{k}"
            w = window(z, res_e, res_n, fe, fn)
            if w.shape != (int(round(WINDOW_M / res_n)) + 1, int(round(WINDOW_M / res_e)) + 1):
                raise SystemExit(f"{name}: the window at {fe}, {fn} does not fit in the DEM at {res_e:.1f} m")
            npz = out / f"{name}.npz"
            np.savez(npz, z=w, e0=0.0, n0=0.0, res_e=res_e, res_n=res_n)
            centre = (0.5 * (w.shape[1] - 1) * res_e, 0.5 * (w.shape[0] - 1) * res_n)
            (out / f"{name}.yaml").write_text(yaml.safe_dump(sweep(name, next(seeds), sweep_path(npz), centre),
                                                             sort_keys=False))
            print(f"{name}: {w.shape[1]} x {w.shape[0]} nodes at {res_e:.1f} x {res_n:.1f} m, "
                  f"relief {w.max() - w.min():.0f} m before rescaling, survey centre {centre[0]:.0f}, {centre[1]:.0f}")


# issue 24's targets on real relief (docs/filters.md 6.1 item 3): most lost runs of 10 per method, largest final error
TARGETS = {"tight-dvl": 0, "tight-sbe": 1, "loose-dvl": 2}
MAX_FINAL_M = 200.0


def summary(results: Path) -> str:
    """A Markdown table of every world's run table under ``results`` (J*/): lost runs and the largest
    final error per method, each cell marked where it misses issue 24's target."""
    import pandas as pd

    worlds = sorted((d for d in results.glob("J*") if d.name[1:].isdigit() and (d / "runs").is_dir()),
                    key=lambda d: int(d.name[1:]))
    if not worlds:
        raise SystemExit(f"no world results (J*/runs) under {results}")
    rows, misses = [], {}
    methods = list(TARGETS)
    for d in worlds:
        df = pd.concat([pd.read_parquet(f) for f in sorted((d / "runs").rglob("*.parquet"))])
        cells = []
        for m in methods:
            g = df[df["method"] == m]
            if g.empty:
                cells.append("-")
                continue
            lost, worst = int(g["diverged"].sum()), float(g["final_horizontal_error_m"].max())
            miss = lost > TARGETS[m] or worst > MAX_FINAL_M
            misses[m] = misses.get(m, 0) + int(miss)
            cells.append(f"{'**' if miss else ''}{lost} of {len(g)} ({worst:.1f} m){'**' if miss else ''}")
        rows.append(f"| {d.name} | " + " | ".join(cells) + " |")
    head = ["# Held-out real relief (docs/filters.md section 8; `make heldout-relief`)", "",
            "Lost runs (final error above 75 m) and the largest final error per world and method; in bold where "
            f"issue 24's target is missed (at most {', '.join(f'{m} {k}' for m, k in TARGETS.items())} lost, no final "
            f"error above {MAX_FINAL_M:g} m).", "",
            "| world | " + " | ".join(methods) + " |", "|---|" + "---|" * len(methods)]
    tail = ["", "Worlds missing the target: " + ", ".join(f"{m} {misses.get(m, 0)} of {len(worlds)}" for m in methods)
            + "."]
    return "\n".join(head + rows + tail) + "\n"


if __name__ == "__main__":
    args = sys.argv[1:]
    if len(args) == 2 and args[0] == "--summary":
        print(summary(Path(args[1])), end="")
    elif len(args) == 2 and args[1] in GROUPS:  # a flag naming a group of sets: each of them
        for which in GROUPS[args[1]]:
            main(Path(args[0]), which)
    elif len(args) in (1, 2) and (len(args) == 1 or args[1] in ("--second", "--third")):
        main(Path(args[0]), args[1][2:] if len(args) == 2 else "first")
    else:
        raise SystemExit(__doc__)
