"""The PCRB with the map's declared error as beam noise (a proposal, docs/filters.md section 4.4).

tanbench's bound (docs/model.md 9.1) charges each beam the sonar's range variance only. The
filters' map-aware likelihood charges sigma_r^2 + m(p), m the navigation map's variance grid
at the footprint p (representation error c^2 |grad h|^2 res^2 plus the declared node error,
terrain/representation.py). This is the same recursion with that per-beam variance: what any
estimator could do with this map if its errors were independent between pings (they are
not, which only makes the problem harder), so it is still optimistic.

    ../../.venv/bin/python bound_map.py OUT --worlds A --variants tight-dvl,pt-dvl/B-F0
"""

from __future__ import annotations

import argparse
import json
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


@lru_cache(maxsize=None)
def map_aware_bound(world: str, sensor: str, states: str = "full") -> np.ndarray:
    from measure import scenario_of
    from tanbench.bounds.pcrb import (model_for, pcrb_recursion, range_sensitivities, transition,
                                      true_tracks)
    from tanbench.terrain import navigation_map
    from tanbench.terrain.grid import Map
    from tanbench.terrain.representation import filter_map_variance
    from tanbench.terrain.stats import gradient
    from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

    _, sc = scenario_of(world, {})
    tracks, beams = true_tracks(sc, sensor)
    tr = tracks[0]
    nmap = navigation_map(sc.terrain, sc.map_resolution_m)
    f = sc.filter
    mvar = filter_map_variance(f, nmap)
    vmap = Map(mvar, nmap.e0, nmap.n0, nmap.res_e, nmap.res_n)
    model = model_for(sc, states)
    c = dcm_body_to_nav_numpy(tr.pitch, tr.roll, tr.yaw)
    b_nav = np.einsum("kij,bj->kbi", c, beams)
    foot = tr.pos[:, None, :] + tr.ranges[..., None] * b_nav
    ge, gn = gradient(nmap, foot[..., 0], foot[..., 1])
    sens = range_sensitivities(ge, gn, b_nav, tr.ranges)
    var = model.range_std_m ** 2 + np.nan_to_num(vmap.elevation(foot[..., 0], foot[..., 1]), nan=0.0)
    d = len(model.state_names)
    s = sens[..., : min(d, 3)] / np.sqrt(var)[..., None]
    info3 = np.einsum("kbi,kbj->kij", s, s)
    info = np.zeros((info3.shape[0], d, d))
    info[:, : info3.shape[1], : info3.shape[2]] = info3
    F, Q = transition(tr.increments, model)
    P = pcrb_recursion(model.prior_information(), F, Q, info)
    return np.sqrt(P[:, 0, 0] + P[:, 1, 1])


def main(argv=None):
    from analyse import boot_ci, fmt, load

    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--worlds", required=True)
    p.add_argument("--variants", required=True)
    a = p.parse_args(argv)
    print("| world | method | runs | RMSE/PCRB (tanbench's) | RMSE/PCRB with the map's error | bound after convergence, "
          "both (m) |")
    print("|---|---|---|---|---|---|")
    for world in a.worlds.split(","):
        for v in a.variants.split(","):
            df = load(a.out, world, v)
            if df is None:
                continue
            sensor = "sbe" if "sbe" in v else "dvl"
            states = "position" if ("loose" in v or v.startswith("pl/")) else "full"
            pm = map_aware_bound(world, sensor, states)
            ratios, old, b_old, b_new = [], [], [], []
            for _, r in df.groupby("run"):
                tc = r["m_convergence_time_s"].iloc[0]
                if not np.isfinite(tc) or r["m_final_horizontal_error_m"].iloc[0] > 75:
                    continue
                t = r["t"].to_numpy() - r["t"].iloc[0]
                after = t >= tc
                rmse = r["m_rmse_after_convergence_m"].iloc[0]
                ratios.append(rmse / np.sqrt(np.mean(pm[after] ** 2)))
                old.append(r["m_rmse_pcrb_ratio"].iloc[0])
                b_old.append(np.sqrt(np.mean(r["pcrb_horizontal_m"].to_numpy()[after] ** 2)))
                b_new.append(np.sqrt(np.mean(pm[after] ** 2)))
            print(f"| {world} | {v} | {len(ratios)} | {fmt(*boot_ci(old))} | {fmt(*boot_ci(ratios))} | "
                  f"{np.mean(b_old):.2f}, {np.mean(b_new):.2f} |")


if __name__ == "__main__":
    main()
