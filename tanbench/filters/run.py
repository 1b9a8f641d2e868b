"""One method on one simulated run: set up the filter, run it, score it against the truth.

``run_method`` is what the sweep engine calls. It takes the run's shared
:class:`~tanbench.simulation.VehicleData` (common random numbers across methods) and the
method's own filter seed, and returns the per-run metrics and the per-update series.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from tanbench.config import Scenario
from tanbench.errors import TanbenchError
from tanbench.filters import METHODS
from tanbench.filters.loose import init_loose, loose_filter_loop
from tanbench.filters.propagate import DIST_NAVIGATION, DIST_NONE, DIST_PARTICLE, position_noise
from tanbench.filters.resample import REGULARISATIONS, SCHEMES
from tanbench.filters.state import N_LOOSE, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.tight import REGULARISED_STATES, init_tight, tight_filter_loop
from tanbench.navigation.increments import compute_increments
from tanbench.sensors.imu import DEG_PER_H, DEG_PER_SQRT_H
from tanbench.simulation import VehicleData
from tanbench.terrain import navigation_map
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy, wrap_pi, yaw_to_heading_deg

DIST_MODES = {"particle": DIST_PARTICLE, "navigation": DIST_NAVIGATION, "none": DIST_NONE}

# per-run metric names, in the order results tables show them
METRIC_COLUMNS = (
    "final_horizontal_error_m", "mean_horizontal_error_m", "rmse_after_convergence_m",
    "final_heading_error_deg", "convergence_time_s", "diverged", "reinitialisations",
    "final_east_error_m", "final_north_error_m", "filter_wall_s",
)


@dataclass
class RunResult:
    """Per-run metrics (dict of scalars) and per-update series (dict of equal-length arrays)."""

    metrics: dict
    series: dict


def update_indices(scenario: Scenario, vehicle: VehicleData) -> tuple[np.ndarray, np.ndarray]:
    """(ping rows used by the filter, their IMU sample indices) for the sampling time."""
    step = int(round(scenario.sampling_time_s * scenario.sensors.sonar_rate_hz))
    rows = np.arange(0, vehicle.ping_idx.size, step)
    return rows, vehicle.ping_idx[rows]


def check_start_on_map(scenario: Scenario, nmap) -> None:
    """Refuse a start whose initial uncertainty could leave the navigation map.

    The worst case: the navigation system's start is off the true start by up to half
    the initial position error on each axis, and the filter's initial square of side
    ``filter.initial_area_m`` is centred on it.
    """
    from tanbench.simulation import motion_plan

    start = motion_plan(scenario).start_enu
    reach = scenario.navigation.initial_position_error_m / 2.0 + scenario.filter.initial_area_m / 2.0
    e = np.array([start[0] - reach, start[0] + reach])
    n = np.array([start[1] - reach, start[1] + reach])
    if not nmap.contains(e[[0, 1, 0, 1]], n[[0, 0, 1, 1]]).all():
        raise TanbenchError(
            f"the initial uncertainty (up to {reach:.0f} m around the start ({start[0]:.0f}, {start[1]:.0f}) m: "
            f"navigation.initial_position_error_m / 2 + filter.initial_area_m / 2) leaves the navigation map "
            f"(E {nmap.e0:.0f}..{nmap.e_max:.0f}, N {nmap.n0:.0f}..{nmap.n_max:.0f} m); move the start or "
            f"shrink the initial uncertainty")


def run_method(scenario: Scenario, method: str, vehicle: VehicleData,
               seed: np.random.SeedSequence) -> RunResult:
    """Run ``method`` ("tight-dvl", "tight-sbe" or "loose-dvl") and score it."""
    if method not in METHODS:
        raise TanbenchError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    f = scenario.filter
    nmap = navigation_map(scenario.terrain, scenario.map_resolution_m)
    check_start_on_map(scenario, nmap)
    rows, upd = update_indices(scenario, vehicle)
    nav = vehicle.nav
    T = scenario.sampling_time_s
    rng = np.random.default_rng(seed)
    zargs = nmap.kernel_args()
    k_steps = upd.size
    scheme = SCHEMES[f.resampling]
    half = f.initial_area_m / 2.0
    reg_size = f.roughening if f.regularisation == "gordon" else f.regularisation_h
    started = time.perf_counter()
    reinit = np.zeros(k_steps, dtype=np.int64)
    ess = np.empty(k_steps)
    if method.startswith("tight"):
        beams = vehicle.dvl_beams if method == "tight-dvl" else vehicle.sbe_beams
        ranges = (vehicle.dvl_ranges if method == "tight-dvl" else vehicle.sbe_ranges)[rows]
        inc = compute_increments(vehicle.truth.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
        x = np.empty((scenario.particles, N_TIGHT))
        std_att = math.radians(f.initial_std_pitch_roll_deg)
        std_yaw = math.radians(f.initial_std_heading_deg)
        std_bias = f.initial_std_gyro_bias_deg_h * DEG_PER_H
        k0 = upd[0]
        init_tight(x, rng, nav.pos[k0, 0], nav.pos[k0, 1], nav.pos[k0, 2], nav.pitch[k0], nav.roll[k0],
                   nav.yaw[k0], half, f.initial_std_up_m, std_att, std_yaw, std_bias)
        est = np.empty((k_steps, N_TIGHT))
        var = np.empty((k_steps, N_TIGHT))
        tight_filter_loop(
            x, rng, inc, nav.yaw[upd], nav.pitch[upd], nav.roll[upd], nav.pos[upd, 2],
            np.ascontiguousarray(ranges), np.ascontiguousarray(beams), *zargs,
            position_noise(f.process_noise_velocity_mps * T, f.measurement_noise_distance_m,
                           DIST_MODES[f.distance_innovation]), f.process_noise_up_m,
            f.process_noise_attitude_deg_sqrt_h * DEG_PER_SQRT_H * math.sqrt(T),
            DIST_MODES[f.distance_innovation], f.measurement_noise_distance_m, f.measurement_noise_altitude_m,
            f.outside_map_sigma, scheme, f.ess_threshold, REGULARISATIONS[f.regularisation],
            REGULARISED_STATES[f.regularised_states], reg_size, f.min_spread_m, f.divergence_sigma,
            f.divergence_steps, half, f.initial_std_up_m, std_att, std_yaw, std_bias,
            est, var, ess, reinit)
        est_en, est_up, est_yaw = est[:, :2], est[:, U], est[:, YAW]
        var_cols = {"var_e": var[:, 0], "var_n": var[:, 1], "var_u": var[:, U], "var_pitch": var[:, PITCH],
                    "var_roll": var[:, ROLL], "var_yaw": var[:, YAW], "var_bias_x": var[:, 6],
                    "var_bias_z": var[:, 7]}
        extra = {"bias_x_deg_h": est[:, 6] / DEG_PER_H, "bias_z_deg_h": est[:, 7] / DEG_PER_H}
    else:
        ranges = vehicle.dvl_ranges[rows]
        c = dcm_body_to_nav_numpy(nav.pitch[upd], nav.roll[upd], nav.yaw[upd])  # (K, 3, 3)
        offsets = np.einsum("kij,bj->kbi", c, vehicle.dvl_beams) * ranges[:, :, None]
        d0 = np.ascontiguousarray(np.diff(nav.pos[upd, :2], axis=0))
        x = np.empty((scenario.particles, N_LOOSE))
        init_loose(x, rng, nav.pos[upd[0], 0], nav.pos[upd[0], 1], half)
        out_en = np.empty((k_steps, 2))
        var = np.empty((k_steps, 2))
        fixed = np.zeros(k_steps, dtype=np.int64)
        loose_filter_loop(
            x, rng, d0, np.ascontiguousarray(nav.pos[upd, :2]), nav.pos[upd, 2], np.ascontiguousarray(offsets),
            *zargs, f.process_noise_velocity_mps * T,
            math.radians(f.initial_std_heading_deg) if f.loose_heading_noise else 0.0,
            f.measurement_noise_altitude_m, f.outside_map_sigma,
            scheme, f.ess_threshold, REGULARISATIONS[f.regularisation], reg_size, f.min_spread_m,
            f.divergence_sigma, f.divergence_steps, half,
            f.loose_converged_std_m, out_en, var, ess, reinit, fixed)
        est_en, est_up, est_yaw = out_en, nav.pos[upd, 2], nav.yaw[upd]
        var_cols = {"var_e": var[:, 0], "var_n": var[:, 1]}
        extra = {"position_fix": fixed.astype(bool)}
    wall = time.perf_counter() - started
    return _score(scenario, vehicle, upd, est_en, est_up, est_yaw, var_cols, extra, ess, reinit, wall)


def _score(scenario, vehicle, upd, est_en, est_up, est_yaw, var_cols, extra, ess, reinit, wall) -> RunResult:
    truth = vehicle.truth
    t = truth.t[upd]
    err_e = est_en[:, 0] - truth.pos[upd, 0]
    err_n = est_en[:, 1] - truth.pos[upd, 1]
    err_h = np.hypot(err_e, err_n)
    heading_err = np.degrees(wrap_pi(-(est_yaw - truth.yaw[upd])))
    nav = vehicle.nav
    nav_err_h = np.hypot(nav.pos[upd, 0] - truth.pos[upd, 0], nav.pos[upd, 1] - truth.pos[upd, 1])
    f = scenario.filter
    below = err_h < f.convergence_threshold_m
    if below[-1]:
        last_bad = np.nonzero(~below)[0]
        kc = int(last_bad[-1] + 1) if last_bad.size else 0
        conv_time = float(t[kc] - t[0])
        rmse = float(np.sqrt(np.mean(err_h[kc:] ** 2)))
    else:
        conv_time = rmse = float("nan")
    metrics = {
        "final_horizontal_error_m": float(err_h[-1]),
        "mean_horizontal_error_m": float(err_h.mean()),
        "rmse_after_convergence_m": rmse,
        "final_heading_error_deg": float(abs(heading_err[-1])),
        "convergence_time_s": conv_time,
        "diverged": bool(err_h[-1] > f.divergence_threshold_m),
        "reinitialisations": int(reinit.sum()),
        "final_east_error_m": float(err_e[-1]),
        "final_north_error_m": float(err_n[-1]),
        "filter_wall_s": float(wall),
    }
    series = {
        "t": t,
        "est_e": est_en[:, 0], "est_n": est_en[:, 1], "est_u": np.asarray(est_up, dtype=float),
        "est_heading_deg": yaw_to_heading_deg(est_yaw),
        "truth_e": truth.pos[upd, 0], "truth_n": truth.pos[upd, 1], "truth_u": truth.pos[upd, 2],
        "truth_heading_deg": yaw_to_heading_deg(truth.yaw[upd]),
        "nav_e": nav.pos[upd, 0], "nav_n": nav.pos[upd, 1],
        "nav_heading_deg": yaw_to_heading_deg(nav.yaw[upd]),
        "east_error_m": err_e, "north_error_m": err_n, "horizontal_error_m": err_h,
        "heading_error_deg": heading_err, "nav_horizontal_error_m": nav_err_h,
        "ess": ess, "reinit": reinit.astype(bool),
        **var_cols, **extra,
    }
    return RunResult(metrics=metrics, series=series)
