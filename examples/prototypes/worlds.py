"""The worlds the prototypes are measured on, and the real-relief test world.

Each world is a scenario (as a sweep's ``scenario:`` section) and the root seed of its
sweep. A, B: ``configs/methods.yaml``'s ``budget-default`` cells (seed 14140014); M20, M30:
``configs/monterey.yaml`` (seed 367900); so the built-in methods' runs here are the runs those
sweeps make. R1, R2: the real-relief worlds built by :func:`build_relief` (issue 24's hidden
world, remade from what we have: a real DEM rescaled to -180..-60 m on 8 m truth cells, a 24 m
navigation map, survey legs, 2000 particles). R1 was used while developing; R2 (the DEM
transposed, legs east-west) was held out until the end.

Paths are absolute (``MONTEREY``, ``RELIEF_DIR``): run from anywhere.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the project root (this worktree)
MONTEREY = str((ROOT / ".." / "shared" / "data" / "monterey" / "MontereyBay.R_*.tif").resolve())
RELIEF_DIR = Path("/tmp/gap/worlds")

AREA = {"terrain": {"kind": "synthetic", "seed": 1}, "map_resolution_m": 10, "noise_m": 1.0,
        "sampling_time_s": 1, "particles": 3000}
MONTEREY_SCENARIO = {
    "terrain": {"kind": "file", "path": MONTEREY, "rows": "south_to_north"}, "area": "custom",
    "trajectory": {"kind": "survey", "centre_en_m": [1000.0, 1150.0], "heading_deg": 0.0, "leg_length_m": 600.0,
                   "leg_spacing_m": 150.0, "legs": 3, "depth_m": 10.0},
    "sensors": {"max_range_m": 300.0}, "noise_m": 1.0, "sampling_time_s": 1, "particles": 3000}


def _relief(name, heading_deg, centre):
    return {"terrain": {"kind": "file", "path": str(RELIEF_DIR / f"{name}.npz")}, "area": "custom",
            "trajectory": {"kind": "survey", "centre_en_m": list(centre), "heading_deg": heading_deg,
                           "leg_length_m": 1400.0, "leg_spacing_m": 250.0, "legs": 3, "depth_m": 20.0},
            "map_resolution_m": 24, "noise_m": 1.0, "sampling_time_s": 1, "particles": 2000}


WORLDS = {
    "A": (14140014, {**AREA, "area": "A"}),
    "B": (14140014, {**AREA, "area": "B"}),
    # area A with a map that is the truth (2.5 m nodes, no node errors): the gap left is the filter's own
    # and the navigation system's unmodelled errors'
    "A-exactmap": (14140014, {**AREA, "area": "A", "map_resolution_m": 2.5,
                              "terrain": {"kind": "synthetic", "seed": 1, "map_error_m": 0.0}}),
    # ... and without the DVL scale error and the gyros' in-run bias drift (the filter models neither)
    "A-exactmap-nav": (14140014, {**AREA, "area": "A", "map_resolution_m": 2.5,
                                  "terrain": {"kind": "synthetic", "seed": 1, "map_error_m": 0.0},
                                  "sensors": {"dvl_scale_error": 0.0, "gyro_bias_instability_deg_h": 0.0}}),
    # area A's 10 m map without its 0.4 m node errors (docs/filters.md 7.2: how much of the gap is node error)
    "A-nodeerr0": (14140014, {**AREA, "area": "A", "terrain": {"kind": "synthetic", "seed": 1, "map_error_m": 0.0}}),
    # configs/quick.yaml's default cell (the example of a verdict the figure contradicts)
    "Q": (20261123, {**AREA, "area": "A", "particles": 2000}),
    "M20": (367900, {**MONTEREY_SCENARIO, "map_resolution_m": 20}),
    "M30": (367900, {**MONTEREY_SCENARIO, "map_resolution_m": 30}),
    "R1": (24240001, _relief("relief-r1", 0.0, (930.0, 1160.0))),
    # R1 with a map that is the truth (its 8 m nodes, no node errors): is the drift the map's or the filter's?
    "R1-exactmap": (24240001, {**_relief("relief-r1", 0.0, (930.0, 1160.0)), "map_resolution_m": 8,
                               "terrain": {"kind": "file", "path": str(RELIEF_DIR / "relief-r1.npz"),
                                           "map_error_m": 0.0}}),
    "R2": (24240002, _relief("relief-r2", 90.0, (1160.0, 930.0))),
    # added after R2 had been looked at (docs/filters.md 4.3): R1's DEM mirrored east-west, legs at 30 deg
    "R3": (24240003, {**_relief("relief-r3", 30.0, (930.0, 1160.0)), "trajectory": {
        "kind": "survey", "centre_en_m": [930.0, 1160.0], "heading_deg": 30.0, "leg_length_m": 1200.0,
        "leg_spacing_m": 250.0, "legs": 3, "depth_m": 20.0}}),
}


def world(name: str) -> tuple[int, dict]:
    seed, sc = WORLDS[name]
    return seed, copy.deepcopy(sc)


def build_relief(out_dir: Path = RELIEF_DIR) -> None:
    """Write relief-r1.npz and relief-r2.npz: the Monterey Canyon head DEM (the four tiles, read in
    place) resampled bilinearly onto 8 m nodes and rescaled linearly to -180..-60 m; r2 is r1
    transposed (east and north swapped: another layout of the same relief), r3 r1 mirrored east-west."""
    from tanbench.terrain.files import read_tiles

    paths = sorted(Path(MONTEREY).parent.glob("MontereyBay.R_*.tif"))
    m, _ = read_tiles(paths, crs="epsg3857", rows="south_to_north")
    res = 8.0
    e = np.arange(0.0, m.e_max - m.e0 + 1e-9, res)
    n = np.arange(0.0, m.n_max - m.n0 + 1e-9, res)
    ee, nn = np.meshgrid(m.e0 + e, m.n0 + n)
    z = m.elevation(ee.ravel(), nn.ravel()).reshape(ee.shape)
    if np.isnan(z).any():
        raise SystemExit("the resampled DEM has holes")
    z = -180.0 + (z - z.min()) / (z.max() - z.min()) * 120.0
    out_dir.mkdir(parents=True, exist_ok=True)
    for name, grid in (("relief-r1", z), ("relief-r2", z.T.copy()), ("relief-r3", z[:, ::-1].copy())):
        np.savez(out_dir / f"{name}.npz", z=grid, e0=0.0, n0=0.0, res_e=res, res_n=res)
        print(f"{name}: {grid.shape[1]} x {grid.shape[0]} nodes at {res:g} m, "
              f"{grid.min():.1f}..{grid.max():.1f} m")


if __name__ == "__main__":
    build_relief()
