"""Prototype tightly coupled PF (issue 24): the built-in loop, update by update, plus options.

With the default options this is ``tanbench.filters.tight.tight_filter_loop`` (recommended
settings: exact propagation, uniform initial cloud, reinitialisation on divergence) driven
from Python, the same kernels in the same order on the same random numbers, so the output is
the built-in's bit for bit (``check_identity.py`` checks it). The options add, one at a time:

* ``bias_walk``: the two gyro-bias states random-walk between updates with the std per update
  that keeps a first-order Gauss-Markov bias at its data-sheet std (``sensors.gyro_bias_instability_deg_h``
  over ``sensors.gyro_bias_corr_time_s``: sigma sqrt(2 T / tau), as the loose TAN's Kalman filter
  does); Table 2 gives the biases no process noise, so the built-in holds them constant while
  the simulated gyros' in-run bias wanders.
* ``range_sigma: sensor``: the beams' noise std in the likelihood is the sonar's (the std of its
  uniform range noise, noise_m / sqrt(3): 0.58 m at the default 1 m) instead of Table 2's 1 m
  for every noise level (the bound uses the sonar's; a filter given the sensor's data sheet
  can too).
* ``map_correlation``: the map's error at a footprint (representation and node error) is the
  same for every ping whose footprint falls in the same map cell, but the likelihood treats
  consecutive pings as independent. With n pings per cell, the n pings carry the information
  of one map-error draw plus n sonar draws, which a per-ping variance sigma_U^2 + n m gives
  (m the map variance): the map-variance grid is multiplied by n = max(1, res / (v T)), res
  the map spacing, v the median DVL speed (what the vehicle measures), T the sampling time.
* ``floor_m``: the horizontal std below which a resampled cloud is re-spread (the built-in's
  ``filter.min_spread_m``, 2 m); 0 switches the floor off.
* ``regularisation: posterior``: after resampling, jitter (E, N, yaw, bias x, bias z) with a
  Gaussian kernel of covariance h^2 Sigma, Sigma the cloud's weighted covariance before the
  resampling (correlations included), h = ``bandwidth`` * h_opt, h_opt = (4 / ((d + 2) M))^(1 /
  (d + 4)) (Musso, Oudjane & Le Gland 2001), shrunk towards the mean (Liu-West) so the cloud's
  mean and covariance are kept.
* ``tempering``: progressive correction (Oudjane & Musso 2000): when one update's likelihood
  would leave fewer than ``tempering_ess`` * M effective particles, it is applied in stages,
  the likelihood raised to a fraction chosen (bisection) so that each stage keeps that ESS,
  with a resampling and a regularisation move between stages and the likelihood recomputed
  at the moved particles; at most ``tempering_stages`` stages (the last takes what is left).
* ``relocalise``: divergence detection from the filter's own quantities and a wider search.
  The statistic is the cloud's predictive log-likelihood of each update, log sum_i w_i p(z|x_i),
  against what the filter itself expects of it: its running median over the last
  ``detect_window`` updates while healthy; the filter is declared lost when the best
  particle's per-beam chi^2 exceeds ``detect_chi2`` for ``detect_steps`` updates in a row
  (the built-in's test with a lower threshold) or the predictive likelihood stays more than
  ``detect_drop`` log units below its healthy median for ``detect_steps`` updates. A lost
  filter is re-drawn over a square of side ``relocalise_side_m`` around its estimate with
  headings around the navigation heading and its initial heading spread (the built-in
  re-draws the initial 150 m square), and, with ``tempering``, the first updates after it are
  tempered as at the start.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from tanbench.methods import MethodOutput, MethodRecord


class Options(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    bias_walk: bool = Field(False, description="gyro biases random-walk at the data sheet's in-run rate")
    range_sigma: Literal["table2", "sensor"] = Field(
        "table2", description="beam noise std: Table 2's measurement_noise_altitude_m, or the sonar's own "
                              "(noise_m / sqrt(3), the std of its uniform range noise)")
    map_correlation: bool = Field(False, description="map variance times the pings that share a map cell")
    floor_m: float | None = Field(None, ge=0, description="re-spread floor (m std); None: filter.min_spread_m")
    regularisation: Literal["builtin", "posterior"] = "builtin"
    bandwidth: float = Field(1.0, gt=0, le=3, description="posterior kernel: factor on h_opt")
    tempering: bool = False
    tempering_ess: float = Field(0.5, gt=0, lt=1)
    tempering_stages: int = Field(8, ge=1, le=64)
    relocalise: bool = False
    relocalise_side_m: float = Field(300.0, gt=0)
    detect_chi2: float = Field(9.0, gt=0, description="best particle's per-beam chi^2 meaning a bad fit")
    detect_steps: int = Field(10, ge=1)
    detect_drop: float = Field(float("inf"), gt=0, description="predictive log-likelihood drop meaning lost")
    detect_window: int = Field(60, ge=5)


REG_COLS = None  # filled lazily: (E, N, YAW, BX, BZ)


def _log_ess(logw):
    mx = logw.max()
    w = np.exp(logw - mx)
    return (w.sum() ** 2) / (w @ w)


def _weighted_cov(x, cols, w, yaw_row, yaw_ref):
    """Weighted mean and covariance of rows ``cols`` of ``x`` (yaw wrapped about ``yaw_ref``)."""
    v = x[cols].copy()
    for i, c in enumerate(cols):
        if c == yaw_row:
            v[i] = (v[i] - yaw_ref + np.pi) % (2 * np.pi) - np.pi
    mu = v @ w
    d = v - mu[:, None]
    cov = (d * w) @ d.T
    for i, c in enumerate(cols):
        if c == yaw_row:
            mu[i] += yaw_ref
    return mu, cov


def _posterior_jitter(x, rng_np, cols, mu, cov, h):
    """Shrinkage kernel x <- a x + (1 - a) mu + h L z on rows ``cols`` (L L^T = cov)."""
    a = math.sqrt(1.0 - h * h)
    d = len(cols)
    scale = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    corr = cov / np.outer(scale, scale)
    try:
        chol = np.linalg.cholesky(corr + 1e-9 * np.eye(d)) * scale[:, None]
    except np.linalg.LinAlgError:
        chol = np.diag(scale)
    z = rng_np.standard_normal((d, x.shape[1]))
    x[cols] = a * x[cols] + ((1.0 - a) * mu)[:, None] + h * (chol @ z)


def run_tight(ctx, sensor: str) -> MethodOutput:
    from tanbench.filters.cloud import gaussian_horizontal
    from tanbench.filters.estimate import weighted_estimate
    from tanbench.filters.likelihood import (beam_constants, beam_vectors, loglik_tight_pass, new_likelihood_work,
                                            work_block)
    from tanbench.filters.tight import TightModel, tight_prior_of
    from tanbench.config import position_noise
    from tanbench.filters.propagate import DIST_NAVIGATION, propagate_tight
    from tanbench.filters.resample import (add_log_weights, apply_resample, normalise_with_ess,
                                          resample_and_regularise, resample_indices)
    from tanbench.filters.rng import fill_normals, fill_uniforms, loop_rng
    from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
    from tanbench.filters.tight import REGULARISED_STATES, init_tight, keep_on_map
    from tanbench.filters.trig import attitude_reference
    from tanbench.filters.likelihood import likelihood_grid
    from tanbench.filters.likelihood import likelihood_of as likelihood_bundle
    from tanbench.filters.tight import collapse_resampling_of as resampling_of
    from tanbench.filters.tight import divergence_of as divergence_bundle
    from tanbench.filters.tight import guard_of as guard_bundle
    from tanbench.filters.tight import readings_of as readings_bundle
    from tanbench.navigation.increments import compute_increments
    from tanbench.options import DISTANCE_INNOVATION
    from tanbench.sensors.imu import DEG_PER_H, DEG_PER_SQRT_H

    o = ctx.options or Options()
    sc, obs, nav, upd = ctx.scenario, ctx.obs, ctx.nav, ctx.updates.imu
    f = sc.filter
    if f.propagation != "exact" or f.initial_cloud != "uniform" or f.collapse_reinit != "respread":
        raise ValueError("the prototype implements the recommended readings only")
    T = sc.sampling_time_s
    beams = np.ascontiguousarray(obs.dvl_beams if sensor == "dvl" else obs.sbe_beams)
    ranges = np.ascontiguousarray((obs.dvl_ranges if sensor == "dvl" else obs.sbe_ranges)[ctx.updates.rows])
    inc = compute_increments(obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    dist_mode = DISTANCE_INNOVATION[f.distance_innovation]
    sig_d, sig_u = f.measurement_sigmas_m
    if o.range_sigma == "sensor" and sc.noise_m > 0:
        sig_u = sc.noise_m / math.sqrt(3.0)
    model = TightModel(position_noise(f.process_noise_velocity_mps * T, sig_d, dist_mode),
                       f.process_noise_up_m, f.process_noise_attitude_deg_sqrt_h * DEG_PER_SQRT_H * math.sqrt(T),
                       dist_mode, sig_d, sig_u, f.outside_map_sigma)
    readings = readings_bundle(f, T)
    prior = tight_prior_of(f)
    reloc_prior = prior._replace(half_side=o.relocalise_side_m / 2.0)
    rs = resampling_of(f, REGULARISED_STATES[f.regularised_states])
    if o.floor_m is not None:
        rs = rs._replace(min_spread=o.floor_m)
    div, lik, guard = divergence_bundle(f), likelihood_bundle(f), guard_bundle(f, ctx.nmap)
    grid = likelihood_grid(f, ctx.nmap)
    if o.map_correlation and lik.mapaware and f.map_aware_likelihood:
        from tanbench.terrain.grid import node_grid
        from tanbench.terrain.representation import map_variance_grid

        speed = float(np.median(np.hypot(obs.dvl_velocity[:, 0], obs.dvl_velocity[:, 1])))
        n_cell = max(1.0, min(ctx.nmap.res_e, ctx.nmap.res_n) / max(speed * T, 1e-6))
        mvar = map_variance_grid(ctx.nmap, f.map_slope_factor, float(ctx.nmap.meta.get("map_error_m", 0.0)))
        grid = node_grid(ctx.nmap, mvar * n_cell)
    rng = loop_rng(ctx.rng, f.random_numbers)
    # the prototype's own draws (posterior kernel) come from a separate generator, so that with
    # the options off the kernels' stream is the built-in's
    rng_np = np.random.default_rng(np.random.SeedSequence(ctx.rng.bit_generator.seed_seq.entropy,
                                                          spawn_key=tuple(ctx.rng.bit_generator.seed_seq.spawn_key)
                                                          + (2424,)))
    m = sc.particles
    nav_yaw, nav_pitch, nav_roll, nav_up = nav.yaw[upd], nav.pitch[upd], nav.roll[upd], nav.pos[upd, 2]
    x = np.empty((N_TIGHT, m))
    init_tight(x, rng, nav.pos[upd[0], 0], nav.pos[upd[0], 1], nav_up[0], nav_pitch[0], nav_roll[0], nav_yaw[0],
               prior)
    steps = upd.size
    est, var, cov_en_out = np.empty((steps, N_TIGHT)), np.empty((steps, N_TIGHT)), np.empty(steps)
    ess_out, reinit_out, healthy_out = np.empty(steps), np.zeros(steps, dtype=np.int64), np.zeros(steps, dtype=np.int64)
    stages_out, pred_ll_out, best_out = np.zeros(steps), np.full(steps, np.nan), np.full(steps, np.nan)
    lost_out = np.zeros(steps)
    logw, ll, w = np.zeros(m), np.empty(m), np.empty(m)
    uni, idx, scratch = np.empty(m), np.empty(m, dtype=np.int64), np.empty_like(x)
    noise, dist = np.empty((6, m)), np.zeros((2, m))
    work = work_block(new_likelihood_work(m, 4 * grid.grids), m)
    mean, v, cov = np.empty(N_TIGHT), np.empty(N_TIGHT), np.empty((2, 2))
    consts = beam_constants(model.sig_u, model.sig_d, model.outside_sigma)
    with_dist = model.dist_mode == DIST_NAVIGATION
    cols = [E, N, YAW, BX, BZ]
    d = len(cols)
    h_post = o.bandwidth * (4.0 / ((d + 2) * m)) ** (1.0 / (d + 4))
    custom_reg = o.regularisation == "posterior"
    q_bias = (sc.sensors.gyro_bias_instability_deg_h * DEG_PER_H * math.sqrt(2.0 * T / sc.sensors.gyro_bias_corr_time_s)
              if o.bias_walk else 0.0)
    bad = 0
    locked = False
    yaw_off = 0.0
    lost_steps = 0
    healthy_ll = []

    def regularise_after_resample(mu_cov, spread):
        """The built-in's jitter (Liu-West per row, inside resample_and_regularise) or the posterior kernel."""
        mu, c = mu_cov
        _posterior_jitter(x, rng_np, cols, mu, c, h_post)
        if spread < rs.min_spread:
            fill_normals(rng, scratch[:2])
            s = rs.min_spread / math.sqrt(2.0)
            x[E] += s * scratch[0]
            x[N] += s * scratch[1]

    def resample_now(wn, spread, yaw_ref):
        """Resample with weights ``wn`` and regularise (options); log-weights restart at 0."""
        if not custom_reg:
            resample_and_regularise(x, wn, logw, 0.0, rng, rs, N_TIGHT, spread, uni, idx, scratch)
            return
        mu_cov = _weighted_cov(x, cols, wn, YAW, yaw_ref)
        draws = uni[:1]
        fill_uniforms(rng, draws)
        resample_indices(rs.scheme, wn, uni, idx)
        apply_resample(x, idx, scratch)
        logw[:] = 0.0
        regularise_after_resample(mu_cov, spread)

    def loglik(k, vec, att, use_dist):
        return loglik_tight_pass(x, 0, vec, grid, lik, consts, att, dist, use_dist, work, ll)

    for k in range(steps):
        vec = beam_vectors(beams, ranges[k])
        att = attitude_reference(nav_pitch[k], nav_roll[k], nav_yaw[k] + yaw_off)
        if k > 0:
            fill_normals(rng, noise)
            propagate_tight(x, inc[k - 1], nav_yaw[k - 1], noise, model.sig_pos, model.sig_up, model.sig_att,
                            model.dist_mode, dist, yaw_off, 0)
            if q_bias > 0.0:
                x[BX] += q_bias * rng_np.standard_normal(m)
                x[BZ] += q_bias * rng_np.standard_normal(m)
        best = loglik(k, vec, att, with_dist and k > 0)
        # the cloud's predictive log-likelihood of this update: log sum_i w_i p(z | x_i)
        lw_prev = logw - logw.max()
        wp = np.exp(lw_prev)
        wp /= wp.sum()
        lmax = ll.max()
        pred = lmax + math.log(max(float(wp @ np.exp(ll - lmax)), 1e-300)) if vec.shape[0] else np.nan
        stages = 1
        if o.tempering and vec.shape[0]:
            remaining = 1.0
            while True:
                full = logw + remaining * ll
                if _log_ess(full) >= o.tempering_ess * m or stages >= o.tempering_stages:
                    break
                lo_, hi_ = 0.0, remaining
                for _ in range(30):
                    mid = 0.5 * (lo_ + hi_)
                    if _log_ess(logw + mid * ll) >= o.tempering_ess * m:
                        lo_ = mid
                    else:
                        hi_ = mid
                lam = max(lo_, 1e-6 * remaining)
                logw += lam * ll
                remaining -= lam
                wn = np.exp(logw - logw.max())
                wn /= wn.sum()
                weighted_estimate(x, wn, YAW, nav_yaw[k], mean, v, cov)
                resample_now(wn, math.sqrt(v[E] + v[N]), nav_yaw[k])
                best = loglik(k, vec, att, with_dist and k > 0)
                stages += 1
            ll *= remaining
        stages_out[k] = stages
        mx = add_log_weights(logw, ll)
        ess = normalise_with_ess(logw, mx, w)
        weighted_estimate(x, w, YAW, nav_yaw[k], mean, v, cov)
        yaw_off = mean[YAW] - nav_yaw[k]
        if not abs(yaw_off) < math.pi:
            yaw_off = 0.0
        spread = math.sqrt(v[E] + v[N])
        off_map = keep_on_map(mean, guard.bounds)
        est[k, :] = mean
        var[k, :] = v
        cov_en_out[k] = cov[0, 1]
        ess_out[k] = ess
        pred_ll_out[k] = pred
        best_out[k] = best
        reinit_out[k] = 0
        healthy_out[k] = 1 if (spread < guard.healthy_std and best < 0.25 * div.sigma * div.sigma) else 0
        locked = locked or healthy_out[k] == 1
        if best < np.inf:
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        diverged = readings.div_reinit and bad >= div.steps
        relocalise = False
        if o.relocalise and best < np.inf:
            poor = best > o.detect_chi2
            if healthy_out[k] and not poor:
                healthy_ll.append(pred)
                del healthy_ll[:-o.detect_window]
            dropped = (len(healthy_ll) >= o.detect_window // 2
                       and pred < float(np.median(healthy_ll)) - o.detect_drop)
            lost_steps = lost_steps + 1 if (poor or dropped) else 0
            lost_out[k] = lost_steps
            relocalise = lost_steps >= o.detect_steps
        if diverged or off_map or relocalise:
            init_tight(x, rng, mean[E], mean[N], nav_up[k], nav_pitch[k], nav_roll[k], nav_yaw[k],
                       reloc_prior if (relocalise and not off_map) else prior)
            logw[:] = 0.0
            bad = 0
            lost_steps = 0
            healthy_ll.clear()
            locked = False
            yaw_off = 0.0
            reinit_out[k] = 1
            continue
        if not custom_reg:
            resample_and_regularise(x, w, logw, ess, rng, rs, N_TIGHT, spread, uni, idx, scratch)
        else:
            logw -= logw.max()
            if ess < rs.ess_threshold * m:
                resample_now(w, spread, nav_yaw[k])
    return MethodOutput(
        east=est[:, 0], north=est[:, 1], up=est[:, U], yaw=est[:, YAW],
        var_e=var[:, 0], var_n=var[:, 1], cov_en=cov_en_out, var_u=var[:, U],
        var_heading=np.degrees(np.sqrt(var[:, YAW])) ** 2, ess=ess_out, reinit=reinit_out.astype(bool),
        extra={"var_pitch": var[:, PITCH], "var_roll": var[:, ROLL], "var_yaw": var[:, YAW],
               "var_bias_x": var[:, BX], "var_bias_z": var[:, BZ],
               "bias_x_deg_h": est[:, BX] / DEG_PER_H, "bias_z_deg_h": est[:, BZ] / DEG_PER_H,
               "healthy": healthy_out.astype(float), "stages": stages_out, "pred_loglik": pred_ll_out,
               "best_chi2": best_out, "lost_steps": lost_out})


def run_tight_dvl(ctx):
    """Prototype tight PF over the 4 DVL beams."""
    return run_tight(ctx, "dvl")


def run_tight_sbe(ctx):
    """Prototype tight PF over the altimeter."""
    return run_tight(ctx, "sbe")


TIGHT_DVL = MethodRecord(name="proto-tight-dvl", seed_id=0, run=run_tight_dvl, options=Options,
                         summary=run_tight_dvl.__doc__, cost_ns=300.0, bound=("dvl", "full"),
                         states=("east", "north", "up", "pitch", "roll", "heading", "gyro_bias_x", "gyro_bias_z"))
TIGHT_SBE = MethodRecord(name="proto-tight-sbe", seed_id=0, run=run_tight_sbe, options=Options,
                         summary=run_tight_sbe.__doc__, cost_ns=300.0, bound=("sbe", "full"),
                         states=("east", "north", "up", "pitch", "roll", "heading", "gyro_bias_x", "gyro_bias_z"))
