"""The synthetic maps tanbench ships: the paper's reference map and the vehicle-run map.

``paper``: 3000 m east x 1200 m north, depths in [-120.9, 0] m, median -83.3 m
(Section 4.1), with a rough region around the area-A run and a flat one around the
area-B run; each region is calibrated so that the seafloor under the default run,
sampled once a second, has the paper's statistics (A: mean -74.7 m, std 13.2 m;
B: mean -84.2 m, std 4.7 m; Section 4.2). A shoal in the north-west corner reaches
the 0 m limit, as the paper's depth range implies.

``vehicle-run``: the analog of the paper's vehicle test (Tables 8-9), which used its
own terrain: 3000 m x 1200 m around the start (1000, 3500); flat (std 2 m) under the
first 240 s of the run, rough (the area-A statistics) from there on.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from tanbench.paperdata import scenario_facts
from tanbench.terrain.synthetic import Layout, Region
from tanbench.vehicle.trajectory import paper_plan, sample_path, vehicle_run_plan

ROUGH = dict(hurst=1.5, corner_m=350.0, peak_cap_sigma=1.5)
FLAT = dict(hurst=1.5, corner_m=1500.0)
VEHICLE_FLAT_UNTIL_S = 240.0


def _nadir_points(plan, t_from=0.0, t_to=None, period=1.0):
    t, pos = sample_path(plan, period)
    keep = (t >= t_from) & (t <= (t_to if t_to is not None else t[-1]))
    return pos[keep, :2]


@lru_cache(maxsize=None)
def layout(name: str) -> Layout:
    """The named synthetic layout ("paper" or "vehicle-run")."""
    facts = scenario_facts()
    if name == "paper":
        ref = facts["reference_map"]
        a, b = facts["areas"]["A"], facts["areas"]["B"]
        track_a = _nadir_points(paper_plan(tuple(a["start_enu_m"])))
        track_b = _nadir_points(paper_plan(tuple(b["start_enu_m"])))
        return Layout(
            name="paper",
            e_range=(0.0, float(ref["extent_m"]["east"])),
            n_range=(0.0, float(ref["extent_m"]["north"])),
            background=Region("background", (0, 0), (0, 0), hurst=0.9, corner_m=800.0,
                              mean_m=-92.0, std_m=8.0),
            regions=(
                Region("A", *_box(track_a, 150.0), **ROUGH, taper_m=300.0,
                       mean_m=a["measured_depth_mean_m"], std_m=a["measured_depth_std_m"],
                       calibration=track_a),
                Region("B", *_box(track_b, 150.0), **FLAT, taper_m=300.0,
                       mean_m=b["measured_depth_mean_m"], std_m=b["measured_depth_std_m"],
                       calibration=track_b),
            ),
            depth_limits_m=(float(ref["depth_range_m"][0]), float(ref["depth_range_m"][1])),
            median_m=float(ref["depth_median_m"]),
            shoal=(0.0, 1200.0, 350.0, 250.0, 150.0),
        )
    if name == "vehicle-run":
        a = facts["areas"]["A"]
        v = facts["vehicle_test"]
        plan = vehicle_run_plan(start_enu=tuple(v["start_enu_m"]) + (0.0,),
                                duration_s=float(v["duration_s"]))
        flat_pts = _nadir_points(plan, 0.0, VEHICLE_FLAT_UNTIL_S - 40.0)
        rough_pts = _nadir_points(plan, VEHICLE_FLAT_UNTIL_S + 40.0)
        boundary_e = float(_nadir_points(plan, VEHICLE_FLAT_UNTIL_S, VEHICLE_FLAT_UNTIL_S)[0, 0])
        start_e, start_n = v["start_enu_m"]
        return Layout(
            name="vehicle-run",
            e_range=(0.0, 3000.0),
            n_range=(start_n - 600.0, start_n + 600.0),
            background=Region("background", (0, 0), (0, 0), hurst=0.9, corner_m=800.0,
                              mean_m=-85.0, std_m=4.0),
            regions=(
                Region("flat", (-1e9, boundary_e - 60.0), (-1e9, 1e9), **FLAT,
                       mean_m=-85.0, std_m=2.0, taper_m=120.0, calibration=flat_pts),
                Region("rough", (boundary_e + 60.0, 1e9), (-1e9, 1e9), **ROUGH,
                       mean_m=a["measured_depth_mean_m"], std_m=a["measured_depth_std_m"],
                       taper_m=120.0, calibration=rough_pts),
            ),
            depth_limits_m=(-150.0, 0.0),
        )
    raise KeyError(name)


def _box(points: np.ndarray, margin: float):
    return ((float(points[:, 0].min() - margin), float(points[:, 0].max() + margin)),
            (float(points[:, 1].min() - margin), float(points[:, 1].max() + margin)))
