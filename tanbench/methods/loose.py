"""Built-in method ``loose-dvl``: the loosely coupled TAN (filters/loose.py).

Two architectures (``filter.loose_architecture``, docs/model.md Section 6.2):

* ``kalman-feedback`` (recommended): the position-only PF's terrain-only fixes go to an
  error-state Kalman filter of the navigation system (position, heading, z-gyro bias;
  navigation/eskf.py), whose corrected navigation drives the PF (closed loop);
* ``fix-only`` (the earlier baseline): the PF's converged estimate is fed back to the
  navigation system as a position fix; heading and biases are never corrected.
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.registry import MethodRecord, register
from tanbench.filters.cloud import gaussian_horizontal, uniform_horizontal
from tanbench.filters.likelihood import likelihood_grid, likelihood_of
from tanbench.filters.loose import (LOOSE_COLS, FixOnlyOutputs, FixOnlySettings, FixOnlyTrack, KalmanOutputs,
                                    KalmanSettings, KalmanTrack, LooseKalman, LooseModel, fix_covariance_scale,
                                    loose_filter_loop, loose_kalman_loop)
from tanbench.filters.rng import loop_rng
from tanbench.filters.loose_turned import LOOSE_TURNED_COLS, Gates, TurnedTrack, loose_turned_loop
from tanbench.filters.state import N_LOOSE, N_TIGHT
from tanbench.filters.tight import collapse_resampling_of, divergence_of, guard_of, readings_of
from tanbench.navigation.eskf import EB, EE, EN, EPSI, N_ERROR
from tanbench.units import DEG_PER_H, DEG_PER_SQRT_H
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy


LOOP_TURNED, LOOP_KALMAN, LOOP_FIX_ONLY = "turned", "kalman", "fix-only"


def loop_kind(f) -> str:
    """The jitted loop loose-dvl runs under these filter settings, each compiled on its first use:
    the Kalman feedback with heading offsets (``turned``, the default), without them (``kalman``),
    or the paper's fix-only filter (``fix-only``). ``tanbench.runner.plan.kernel_variant`` names a
    cell's compiled variant by it."""
    if f.loose_architecture != "kalman-feedback":
        return LOOP_FIX_ONLY
    return LOOP_TURNED if f.loose_heading_offsets else LOOP_KALMAN


def run_loose_dvl(ctx: MethodContext) -> MethodOutput:
    """The loosely coupled position-only particle filter feeding fixes to the navigation system."""
    sc, obs, nav, upd = ctx.scenario, ctx.obs, ctx.nav, ctx.updates.imu
    f = sc.filter
    T = sc.sampling_time_s
    half = f.initial_area_m / 2.0
    ranges = obs.dvl_ranges[ctx.updates.rows]
    c = dcm_body_to_nav_numpy(nav.pitch[upd], nav.roll[upd], nav.yaw[upd])  # (K, 3, 3)
    offsets = np.ascontiguousarray(np.einsum("kij,bj->kbi", c, obs.dvl_beams) * ranges[:, :, None])
    model = LooseModel(sc.position_step_m,
                       f.initial_std_heading_rad if f.loose_heading_noise else 0.0,
                       sc.measurement_sigmas_m[1], f.outside_map_sigma, f.loose_converged_std_m)
    rng = loop_rng(ctx.rng, f.random_numbers)
    readings = readings_of(f, T)
    x = np.empty((N_LOOSE, sc.particles))  # a column per particle
    uniform_horizontal(x, rng, nav.pos[upd[0], 0], nav.pos[upd[0], 1], half)
    if readings.cloud_std > 0.0:
        gaussian_horizontal(x, rng, nav.pos[upd[0], 0], nav.pos[upd[0], 1], readings.cloud_std)
    k = upd.size
    out_en, var, cov_en = np.empty((k, 2)), np.empty((k, 2)), np.empty(k)
    ess, reinit, fixed = np.empty(k), np.zeros(k, dtype=np.int64), np.zeros(k, dtype=np.int64)
    if loop_kind(f) != LOOP_FIX_ONLY:
        return _run_kalman_feedback(ctx, rng, x, offsets, model, out_en, var, ess, reinit, fixed)
    d0 = np.ascontiguousarray(np.diff(nav.pos[upd, :2], axis=0))
    loose_filter_loop(x, rng, FixOnlyTrack(d0, np.ascontiguousarray(nav.pos[upd, :2]), nav.pos[upd, 2]),
                      offsets, likelihood_grid(f, ctx.nmap),
                      FixOnlySettings(model, collapse_resampling_of(f, LOOSE_COLS), divergence_of(f), half, readings),
                      FixOnlyOutputs(out_en, var, cov_en, ess, reinit, fixed))
    return MethodOutput(east=out_en[:, 0], north=out_en[:, 1], var_e=var[:, 0], var_n=var[:, 1], cov_en=cov_en,
                        ess=ess, reinit=reinit.astype(bool),
                        extra={"position_fix": fixed.astype(float), "healthy": fixed.astype(float)})


def _run_kalman_feedback(ctx, rng, x, offsets, model, out_en, var, ess, reinit, fixed) -> MethodOutput:
    """The closed loop: PF -> terrain-only fixes -> navigation KF -> corrected navigation -> PF."""
    sc, nav, upd = ctx.scenario, ctx.nav, ctx.updates.imu
    f, s, T = sc.filter, sc.sensors, sc.sampling_time_s
    k = upd.size
    inc = ctx.increments()
    p_kf = np.zeros((N_ERROR, N_ERROR))
    p_kf[EE, EE] = p_kf[EN, EN] = f.initial_area_m ** 2 / 12.0
    p_kf[EPSI, EPSI] = f.initial_std_heading_rad ** 2
    p_kf[EB, EB] = f.initial_std_gyro_bias_rad_s ** 2
    # the random walk that keeps a first-order Gauss-Markov bias's steady-state std (data sheet values)
    q_bias = s.gyro_bias_instability_deg_h * DEG_PER_H * math.sqrt(2.0 * T / s.gyro_bias_corr_time_s)
    fix_every = max(1, int(round(f.loose_fix_interval_s / T)))  # updates between fixes
    kf = LooseKalman(sc.position_step_m, s.gyro_arw_deg_sqrt_h * DEG_PER_SQRT_H * math.sqrt(T),
                     q_bias, fix_every, f.loose_fix_gate, f.loose_fix_floor_m, f.loose_fix_max_std_m, f.loose_fix_misses,
                     fix_covariance_scale(fix_every * T, f.loose_fix_correlation_s))
    out_en[0] = nav.pos[upd[0], :2]
    out_yaw, out_bias, var_yaw = np.empty(k), np.empty(k), np.empty(k)
    rejected, healthy = np.zeros(k, dtype=np.int64), np.zeros(k, dtype=np.int64)
    settings = KalmanSettings(model, collapse_resampling_of(f, LOOSE_COLS), divergence_of(f), f.initial_area_m / 2.0,
                              likelihood_of(f), guard_of(f, ctx.nmap), kf)
    outputs = KalmanOutputs(out_en, out_yaw, out_bias, var, var_yaw, ess, reinit, fixed, rejected, healthy)
    if loop_kind(f) == LOOP_TURNED:
        _run_turned(ctx, rng, x, inc, settings._replace(rs=collapse_resampling_of(f, LOOSE_TURNED_COLS)), p_kf,
                    outputs)
    else:
        loose_kalman_loop(x, rng, KalmanTrack(inc, nav.yaw[upd], nav.pos[upd, 2]), offsets,
                          likelihood_grid(f, ctx.nmap), settings, p_kf, outputs)
    return MethodOutput(east=out_en[:, 0], north=out_en[:, 1], yaw=out_yaw, var_e=var[:, 0], var_n=var[:, 1],
                        var_heading=np.degrees(np.sqrt(var_yaw)) ** 2, ess=ess, reinit=reinit.astype(bool),
                        extra={"position_fix": fixed.astype(float), "fix_accepted": fixed.astype(float),
                               "fix_rejected": rejected.astype(float), "healthy": healthy.astype(float),
                               "var_yaw": var_yaw, "bias_z_deg_h": out_bias / DEG_PER_H})


def _run_turned(ctx, rng, x, inc, settings, p_kf, out):
    """The closed loop with heading-offset particles and gated fixes (filters/loose_turned.py);
    ``x`` (2, M) is the initial cloud, drawn as for the built-in loop."""
    sc, obs, nav, upd = ctx.scenario, ctx.obs, ctx.nav, ctx.updates.imu
    f = sc.filter
    x8 = np.zeros((N_TIGHT, x.shape[1]))
    x8[:2] = x
    bias_limit = (f.loose_bias_gate_sigma * f.initial_std_gyro_bias_rad_s if f.loose_bias_gate_sigma is not None
                  else np.inf)
    gates = Gates(float(bias_limit), float(f.loose_fix_shape or 0.0), float(sc.sampling_time_s),
                  float(f.loose_fix_prior_gate) if f.loose_fix_prior_gate is not None else np.inf,
                  f.loose_fix_prior_fallback == "posterior", bool(f.loose_fix_fit_test),
                  bool(f.loose_fix_fit_one_wild_beam), f.loose_first_fix == "posterior",
                  f.loose_reopen_heading == "cloud", f.loose_reopen_position == "fix")
    track = TurnedTrack(inc, nav.yaw[upd], nav.pitch[upd], nav.roll[upd], nav.pos[upd, 2],
                        np.ascontiguousarray(obs.dvl_beams), np.ascontiguousarray(obs.dvl_ranges[ctx.updates.rows]))
    loose_turned_loop(x8, rng, track, likelihood_grid(f, ctx.nmap), settings, gates, p_kf, out)


LOOSE_DVL = register(MethodRecord(
    name="loose-dvl", seed_id=3, builtin=True, run=run_loose_dvl,
    states=("east", "north", "heading", "gyro_bias_z"),
    series=("position_fix", "healthy", "fix_accepted", "fix_rejected", "var_yaw", "bias_z_deg_h"),
    summary="loosely coupled TAN: a position-only particle filter whose terrain fixes go to the navigation "
            "system's Kalman filter (position, heading, gyro bias), closed loop (filter.loose_architecture)",
    cost_ns=40.9, color="tab:purple", linestyle=":", bound=("dvl", "position")))
