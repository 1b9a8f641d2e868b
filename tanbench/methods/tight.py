"""Built-in methods ``tight-dvl`` and ``tight-sbe``: the paper's tightly coupled 8-state PF.

Set-up of the jitted loop in :mod:`tanbench.filters.tight` from the scenario's filter
settings and the run's observations: the navigation increments between updates, the
initial cloud around the navigation solution, the parameter bundles.
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.registry import MethodRecord, register

TIGHT_STATES = ("east", "north", "up", "pitch", "roll", "heading", "gyro_bias_x", "gyro_bias_z")
TIGHT_SERIES = ("var_pitch", "var_roll", "var_bias_x", "var_bias_z", "bias_x_deg_h", "bias_z_deg_h", "healthy")


def resampling_bundle(f, regularised_cols: np.ndarray):
    """The :class:`~tanbench.filters.params.Resampling` bundle of a ``FilterSpec``."""
    from tanbench.filters.params import Resampling
    from tanbench.options import REGULARISATION, RESAMPLING

    size = f.roughening if f.regularisation == "gordon" else f.regularisation_h
    return Resampling(RESAMPLING[f.resampling], f.ess_threshold, REGULARISATION[f.regularisation],
                      regularised_cols, size, f.min_spread_m)


def measurement_sigmas(f) -> tuple[float, float]:
    """(distance, altitude) noise std of the likelihood under ``filter.likelihood_r``.

    ``per-component``: Table 2's diag(0.1, 0.1, 1)^2 as given. ``scalar-norm``: Eq. 20's
    single |R| as the norm of R (its largest variance), for every term.
    ``scalar-determinant``: |R| as the determinant of R, taken as a variance in m^2.
    """
    d, u = f.measurement_noise_distance_m, f.measurement_noise_altitude_m
    if f.likelihood_r == "per-component":
        return d, u
    variance = max(d * d, u * u) if f.likelihood_r == "scalar-norm" else (d * d) * (d * d) * (u * u)
    return math.sqrt(variance), math.sqrt(variance)


def readings_bundle(f, sampling_time_s: float):
    """The :class:`~tanbench.filters.params.Readings` bundle of a ``FilterSpec`` (docs/model.md section 10)."""
    from tanbench.filters.params import Readings
    from tanbench.options import PROPAGATION

    return Readings(PROPAGATION[f.propagation], float(sampling_time_s),
                    f.initial_area_m if f.initial_cloud == "gaussian" else 0.0, f.divergence_reinit,
                    f.min_spread_m if f.collapse_reinit == "initial" else 0.0)


def resampling_of(f, regularised_cols: np.ndarray):
    """The Resampling bundle, without the re-spread when a collapsed cloud is redrawn instead."""
    rs = resampling_bundle(f, regularised_cols)
    return rs._replace(min_spread=0.0) if f.collapse_reinit == "initial" else rs


# the Euler inputs' averaging window per propagation reading, seconds (0: the one IMU sample at the update;
# euler-interval-start: the one sample at the interval's start)
EULER_WINDOW_S = {"euler-last-second": 1.0, "euler-last-sample": 0.0, "euler-interval-start": 0.0}


def position_step_noise(f, T: float) -> float:
    """East/north process noise std per update of the tight and loose particle filters:
    ``process_noise_velocity_mps`` times T (``position_noise_growth: linear``) or sqrt(T) (``sqrt``)."""
    return f.process_noise_velocity_mps * (math.sqrt(T) if f.position_noise_growth == "sqrt" else T)


def euler_inputs_of(ctx: MethodContext) -> np.ndarray:
    """The (K-1, 4) Euler-step inputs of ``filter.propagation`` (zeros for ``exact``)."""
    from tanbench.navigation.increments import N_EULER, compute_euler_inputs

    f, obs, nav, upd = ctx.scenario.filter, ctx.obs, ctx.nav, ctx.updates.imu
    if f.propagation == "exact":
        return np.zeros((max(upd.size - 1, 0), N_EULER))
    window = max(1, int(round(EULER_WINDOW_S[f.propagation] / obs.dt)))
    if f.propagation == "euler-interval-start":
        # interval m runs from upd[m] to upd[m+1]; its inputs are the one sample at upd[m]
        upd = np.concatenate([upd[:1], upd[:-1] + 1])
    return compute_euler_inputs(obs.gyro, obs.dvl_velocity, nav.pitch, nav.roll, nav.yaw, obs.latitude_rad,
                                upd, window)


def likelihood_bundle(f):
    """The :class:`~tanbench.filters.params.Likelihood` bundle: the map-aware density when the
    map-aware variance or a non-Gaussian density is asked for."""
    from tanbench.filters.params import Likelihood
    from tanbench.options import LIKELIHOOD

    mapaware = f.map_aware_likelihood or f.likelihood != "gaussian"
    return Likelihood(bool(mapaware), LIKELIHOOD[f.likelihood], float(f.student_nu))


def likelihood_grid(f, nmap):
    """The navigation map as the particle filters read it (:class:`~tanbench.terrain.grid.NodeGrid`):
    with the map-aware density, its variance grid interleaved with its heights: the map's
    representation variance with its declared error (``filter.map_aware_likelihood``,
    terrain/representation.py), or zero."""
    from tanbench.terrain.grid import node_grid
    from tanbench.terrain.representation import map_variance_grid

    if not likelihood_bundle(f).mapaware:
        return node_grid(nmap)
    if f.map_aware_likelihood:
        mvar = map_variance_grid(nmap, f.map_slope_factor, float(nmap.meta.get("map_error_m", 0.0)))
    else:
        mvar = np.where(np.isnan(nmap.z), np.nan, 0.0)
    return node_grid(nmap, mvar)


def guard_bundle(f, nmap):
    """The :class:`~tanbench.filters.params.Guard` bundle (spread divergence, keep on map)."""
    from tanbench.filters.params import Guard

    bounds = np.array([nmap.e0, nmap.e_max, nmap.n0, nmap.n_max]) if f.keep_on_map else np.array([1.0, 0.0, 0.0, 0.0])
    spread = float(f.divergence_spread_m) if f.divergence_spread_m is not None else np.inf
    return Guard(spread, f.loose_converged_std_m, bounds)


def divergence_bundle(f):
    from tanbench.filters.params import Divergence

    return Divergence(f.divergence_sigma, f.divergence_steps)


def run_tight(ctx: MethodContext, sensor: str) -> MethodOutput:
    from tanbench.filters.cloud import gaussian_horizontal
    from tanbench.filters.params import TightModel, TightPrior
    from tanbench.filters.propagate import position_noise
    from tanbench.filters.rng import loop_rng
    from tanbench.filters.state import N_TIGHT, PITCH, ROLL, U, YAW
    from tanbench.filters.tight import REGULARISED_STATES, init_tight, tight_filter_loop
    from tanbench.navigation.increments import compute_increments
    from tanbench.options import DISTANCE_INNOVATION
    from tanbench.sensors.imu import DEG_PER_H, DEG_PER_SQRT_H

    sc, obs, nav, upd = ctx.scenario, ctx.obs, ctx.nav, ctx.updates.imu
    f = sc.filter
    T = sc.sampling_time_s
    beams = obs.dvl_beams if sensor == "dvl" else obs.sbe_beams
    ranges = (obs.dvl_ranges if sensor == "dvl" else obs.sbe_ranges)[ctx.updates.rows]
    inc = compute_increments(obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    dist_mode = DISTANCE_INNOVATION[f.distance_innovation]
    sig_d, sig_u = measurement_sigmas(f)
    model = TightModel(position_noise(position_step_noise(f, T), sig_d, dist_mode),
                       f.process_noise_up_m, f.process_noise_attitude_deg_sqrt_h * DEG_PER_SQRT_H * math.sqrt(T),
                       dist_mode, sig_d, sig_u, f.outside_map_sigma)
    readings = readings_bundle(f, T)
    prior = TightPrior(f.initial_area_m / 2.0, f.initial_std_up_m, math.radians(f.initial_std_pitch_roll_deg),
                       math.radians(f.initial_std_heading_deg), f.initial_std_gyro_bias_deg_h * DEG_PER_H)
    rng = loop_rng(ctx.rng, f.random_numbers)
    x = np.empty((N_TIGHT, sc.particles))  # a column per particle
    k0 = upd[0]
    init_tight(x, rng, nav.pos[k0, 0], nav.pos[k0, 1], nav.pos[k0, 2], nav.pitch[k0], nav.roll[k0],
               nav.yaw[k0], prior)
    if readings.cloud_std > 0.0:
        gaussian_horizontal(x, rng, nav.pos[k0, 0], nav.pos[k0, 1], readings.cloud_std)
    k = upd.size
    est, var, cov_en = np.empty((k, N_TIGHT)), np.empty((k, N_TIGHT)), np.empty(k)
    ess, reinit, healthy = np.empty(k), np.zeros(k, dtype=np.int64), np.zeros(k, dtype=np.int64)
    tight_filter_loop(x, rng, inc, nav.yaw[upd], nav.pitch[upd], nav.roll[upd], nav.pos[upd, 2],
                      np.ascontiguousarray(ranges), np.ascontiguousarray(beams), likelihood_grid(f, ctx.nmap), model,
                      resampling_of(f, REGULARISED_STATES[f.regularised_states]), divergence_bundle(f), prior,
                      readings, euler_inputs_of(ctx), likelihood_bundle(f), guard_bundle(f, ctx.nmap),
                      est, var, cov_en, ess, reinit, healthy)
    return MethodOutput(
        east=est[:, 0], north=est[:, 1], up=est[:, U], yaw=est[:, YAW],
        var_e=var[:, 0], var_n=var[:, 1], cov_en=cov_en, var_u=var[:, U], var_heading=np.degrees(np.sqrt(var[:, YAW])) ** 2,
        ess=ess, reinit=reinit.astype(bool),
        extra={"var_pitch": var[:, PITCH], "var_roll": var[:, ROLL], "var_yaw": var[:, YAW],
               "var_bias_x": var[:, 6], "var_bias_z": var[:, 7],
               "bias_x_deg_h": est[:, 6] / DEG_PER_H, "bias_z_deg_h": est[:, 7] / DEG_PER_H,
               "healthy": healthy.astype(float)})


def run_tight_dvl(ctx: MethodContext) -> MethodOutput:
    """The tightly coupled 8-state PF weighted by the 4 DVL beams."""
    return run_tight(ctx, "dvl")


def run_tight_sbe(ctx: MethodContext) -> MethodOutput:
    """The tightly coupled 8-state PF weighted by the single altimeter beam."""
    return run_tight(ctx, "sbe")


TIGHT_DVL = register(MethodRecord(
    name="tight-dvl", seed_id=1, builtin=True, run=run_tight_dvl, states=TIGHT_STATES,
    series=TIGHT_SERIES + ("var_yaw",),
    summary="the paper's tightly coupled 8-state particle filter (position, attitude, two gyro biases), "
            "weighted by the 4 DVL beams",
    cost_ns=105.0, color="tab:red", linestyle="--", bound=("dvl", "full")))
TIGHT_SBE = register(MethodRecord(
    name="tight-sbe", seed_id=2, builtin=True, run=run_tight_sbe, states=TIGHT_STATES,
    series=TIGHT_SERIES + ("var_yaw",),
    summary="the same 8-state particle filter weighted by the single-beam altimeter",
    cost_ns=88.0, color="tab:blue", linestyle="-.", bound=("sbe", "full")))
