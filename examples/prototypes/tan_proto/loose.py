"""Prototype closed-loop loose TAN (issue 24): the built-in loop, update by update, plus fix gating.

With the default options this is ``tanbench.filters.loose.loose_kalman_loop`` (the
recommended ``kalman-feedback`` architecture) driven from Python, the same kernels in the
same order on the same random numbers: the built-in ``loose-dvl`` bit for bit
(``check_identity.py``). The options make a fix unable to drag the navigation system into a
wrong basin:

* ``bias_gate_sigma``: a fix whose Kalman update would put the z-gyro bias estimate more than
  this many prior sigmas (``filter.initial_std_gyro_bias_deg_h``) from zero is rejected (the
  KF's bias is a random walk without bound; a run of wrong fixes drove it to 160-200 deg/h
  in the diagnosis, docs/filters.md);
* ``shape_gate``: a fix is taken only if the PF cloud is unimodal and compact: at least this
  fraction of the weight lies inside the cloud's own 95 % ellipse (chi^2_2 = 5.99 in its
  weighted covariance; 0.95 for a Gaussian cloud, less for a split one);
* ``reloc_kf``: a re-initialised PF cloud is drawn over a square sized by the navigation KF's
  own position uncertainty (side 6 sigma of its larger axis, at least ``filter.initial_area_m``,
  at most ``reloc_max_side_m``) instead of the fixed initial square, so that a navigation
  system that has drifted further than the initial square can still be found;
* ``tempering``: progressive correction of the PF's updates, as in ``tan_proto.tight``;
* ``heading_offsets``: each particle carries a heading offset delta from the corrected
  navigation heading (drawn from the KF's heading variance at every (re)initialisation,
  random-walking with the gyro's angle random walk and the KF's bias uncertainty), moves by
  the corrected displacement turned by delta and sees its beams turned by delta (the tight
  likelihood kernel on a state whose attitude is the navigation's with yaw psi_c + delta).
  The built-in PF's cross-track random walk sigma_psi |d| cannot follow the coherent drift
  of a heading error (1 m/s at 30 deg and 2 m/s): the diagnosis's Monterey runs never
  converged for 600 s while the navigation drifted 350 m. The window prior of the
  terrain-only fix is then a copy of the cloud at the window start moved the same way and
  never weighted (its mean and covariance), and an accepted fix's heading correction is
  taken out of every delta. The fix stays a position fix.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from tanbench.methods import MethodOutput, MethodRecord


class Options(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    bias_gate_sigma: float | None = Field(None, gt=0)
    shape_gate: float | None = Field(None, gt=0, lt=1)
    reloc_kf: bool = False
    reloc_max_side_m: float = Field(1500.0, gt=0)
    tempering: bool = False
    tempering_ess: float = Field(0.5, gt=0, lt=1)
    tempering_stages: int = Field(8, ge=1, le=64)
    heading_offsets: bool = False


CHI2_2_95 = 5.991


def _ess(logw):
    w = np.exp(logw - logw.max())
    return (w.sum() ** 2) / (w @ w)


def unimodal_fraction(x, w, mean, cov):
    """Weight inside the cloud's own 95 % ellipse (chi^2_2 = 5.99 in its weighted covariance)."""
    d = x[:2] - mean[:2, None]
    try:
        inv = np.linalg.inv(cov)
    except np.linalg.LinAlgError:
        return 0.0
    q = inv[0, 0] * d[0] ** 2 + 2 * inv[0, 1] * d[0] * d[1] + inv[1, 1] * d[1] ** 2
    return float(w[q <= CHI2_2_95].sum())


def run_loose(ctx) -> MethodOutput:
    from tanbench.filters.cloud import uniform_horizontal
    from tanbench.filters.estimate import weighted_estimate
    from tanbench.filters.likelihood import BLOCK, beam_constants, new_likelihood_work
    from tanbench.filters.loose import (LOOSE_COLS, _open_window, position_reset, propagate_and_weigh_loose,
                                        reopen_kf)
    from tanbench.filters.loose import LooseBuffers, LooseKalman, LooseModel, LooseMotion
    from tanbench.filters.propagate import DIST_NONE, propagate_tight
    from tanbench.filters.resample import add_log_weights, normalise_with_ess, resample_and_regularise
    from tanbench.filters.rng import loop_rng
    from tanbench.filters.state import BZ, E, N, N_LOOSE, N_TIGHT, U, YAW
    from tanbench.filters.tight import keep_on_map
    from tanbench.filters.likelihood import likelihood_grid
    from tanbench.filters.likelihood import likelihood_of as likelihood_bundle
    from tanbench.filters.tight import collapse_resampling_of as resampling_of
    from tanbench.filters.tight import divergence_of as divergence_bundle
    from tanbench.filters.tight import guard_of as guard_bundle
    from tanbench.filters.tight import readings_of as readings_bundle
    from tanbench.navigation.eskf import EB, EE, EN, EPSI, N_ERROR, eskf_predict, eskf_update, terrain_only_fix
    from tanbench.navigation.increments import JAZE, JAZN, SZ, compute_increments
    from tanbench.sensors.imu import DEG_PER_H, DEG_PER_SQRT_H
    from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

    o = ctx.options or Options()
    sc, obs, nav, upd = ctx.scenario, ctx.obs, ctx.nav, ctx.updates.imu
    f, s, T = sc.filter, sc.sensors, sc.sampling_time_s
    if f.loose_architecture != "kalman-feedback":
        raise ValueError("the prototype implements the kalman-feedback architecture only")
    half = f.initial_area_m / 2.0
    ranges = obs.dvl_ranges[ctx.updates.rows]
    c = dcm_body_to_nav_numpy(nav.pitch[upd], nav.roll[upd], nav.yaw[upd])
    offsets = np.ascontiguousarray(np.einsum("kij,bj->kbi", c, obs.dvl_beams) * ranges[:, :, None])
    model = LooseModel(f.process_noise_velocity_mps * T,
                       math.radians(f.initial_std_heading_deg) if f.loose_heading_noise else 0.0,
                       f.measurement_sigmas_m[1], f.outside_map_sigma, f.loose_converged_std_m)
    rng = loop_rng(ctx.rng, f.random_numbers)
    readings = readings_bundle(f, T)
    m = sc.particles
    hd = o.heading_offsets
    x = np.empty((N_LOOSE + (1 if hd else 0), m))
    uniform_horizontal(x, rng, nav.pos[upd[0], 0], nav.pos[upd[0], 1], half)
    rng_np = np.random.default_rng(np.random.SeedSequence(ctx.rng.bit_generator.seed_seq.entropy,
                                                          spawn_key=tuple(ctx.rng.bit_generator.seed_seq.spawn_key)
                                                          + (2425,)))
    steps = upd.size
    inc = compute_increments(obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    p_kf = np.zeros((N_ERROR, N_ERROR))
    p_kf[EE, EE] = p_kf[EN, EN] = f.initial_area_m ** 2 / 12.0
    p_kf[EPSI, EPSI] = math.radians(f.initial_std_heading_deg) ** 2
    p_kf[EB, EB] = (f.initial_std_gyro_bias_deg_h * DEG_PER_H) ** 2
    q_bias = s.gyro_bias_instability_deg_h * DEG_PER_H * math.sqrt(2.0 * T / s.gyro_bias_corr_time_s)
    kf = LooseKalman(f.process_noise_velocity_mps * T, s.gyro_arw_deg_sqrt_h * DEG_PER_SQRT_H * math.sqrt(T),
                     q_bias, max(1, int(round(f.loose_fix_interval_s / T))), f.loose_fix_gate, f.loose_fix_floor_m,
                     f.loose_fix_max_std_m, f.loose_fix_misses)
    bias_limit = (o.bias_gate_sigma * f.initial_std_gyro_bias_deg_h * DEG_PER_H if o.bias_gate_sigma is not None
                  else np.inf)
    rs, div = resampling_of(f, np.array([0, 1, 2]) if hd else LOOSE_COLS), divergence_bundle(f)
    lik, guard, grid = likelihood_bundle(f), guard_bundle(f, ctx.nmap), likelihood_grid(f, ctx.nmap)
    if hd:
        from tanbench.filters.likelihood import beam_vectors, loglik_tight_pass, work_block
        from tanbench.filters.trig import attitude_reference

        x[2] = rng_np.standard_normal(m) * math.radians(f.initial_std_heading_deg)
        x8 = np.zeros((N_TIGHT, m))
        work8 = work_block(new_likelihood_work(m, 4 * grid.grids), m)
        dist8 = np.zeros((2, m))
        beams_body = np.ascontiguousarray(obs.dvl_beams)
        ranges_k = np.ascontiguousarray(ranges)
        nav_pitch_k, nav_roll_k = nav.pitch[upd], nav.roll[upd]
        xp, wp = x.copy(), np.full(m, 1.0 / m)  # the window's prior cloud: moved, never weighted

    def move(cloud, k_):
        """Heading-offset particles: the corrected displacement turned by each delta, plus noise."""
        cd, sd = np.cos(cloud[2]), np.sin(cloud[2])
        z = rng_np.standard_normal((3, m))
        cloud[0] += cd * d_e - sd * d_n + sig_pos * z[0]
        cloud[1] += sd * d_e + cd * d_n + sig_pos * z[1]
        cloud[2] += q_delta * z[2]

    def weigh(k_):
        x8[E], x8[N] = x[0], x[1]
        x8[U] = nav_up[k_]
        x8[3] = nav_pitch_k[k_]
        x8[4] = nav_roll_k[k_]
        x8[YAW] = navp[YAW, 0] + x[2]
        vec = beam_vectors(beams_body, ranges_k[k_])
        att = attitude_reference(nav_pitch_k[k_], nav_roll_k[k_], navp[YAW, 0])
        return loglik_tight_pass(x8, 0, vec, grid, lik, consts, att, dist8, False, work8, ll)

    nav_yaw, nav_up = nav.yaw[upd], nav.pos[upd, 2]
    out_en, var, ess_out = np.empty((steps, 2)), np.empty((steps, 2)), np.empty(steps)
    out_yaw, out_bias, var_yaw = np.empty(steps), np.empty(steps), np.empty(steps)
    reinit_out, fixed_out = np.zeros(steps, dtype=np.int64), np.zeros(steps, dtype=np.int64)
    rejected_out, healthy_out = np.zeros(steps, dtype=np.int64), np.zeros(steps, dtype=np.int64)
    shape_out, stages_out, side_out = np.full(steps, np.nan), np.ones(steps), np.full(steps, np.nan)
    out_en[0] = nav.pos[upd[0], :2]
    delta_mean, delta_std = np.full(steps, np.nan), np.full(steps, np.nan)
    nb_beams = offsets.shape[1]
    logw, ll, w = np.zeros(m), np.empty(m), np.empty(m)
    uni, idx, scratch = np.empty(m), np.empty(m, dtype=np.int64), np.empty_like(x)
    mean, v, cov = np.empty(2), np.empty(2), np.empty((2, 2))
    r, dx, rot = np.empty((2, 2)), np.empty(N_ERROR), np.empty((nb_beams, 3))
    m_prior, p_prior, zt = np.empty(2), np.empty((2, 2)), np.empty(2)
    _open_window(m_prior, p_prior, out_en[0, 0], out_en[0, 1], half)
    navp = np.zeros((N_TIGHT, 1))
    zero_noise, dist = np.zeros((6, 1)), np.zeros((2, 1))
    bufs = LooseBuffers(np.empty(3 * min(BLOCK, m)), new_likelihood_work(min(BLOCK, m), 4 * grid.grids), ll)
    consts = beam_constants(model.sig_u, 1.0, model.outside_sigma)
    navp[E, 0], navp[N, 0], navp[YAW, 0] = out_en[0, 0], out_en[0, 1], nav_yaw[0]
    bad = good = since_fix = rejections = 0
    first_fix, locked = True, False
    p0_pos, p0_yaw = p_kf[EE, EE], p_kf[EPSI, EPSI]
    consistent_chi = (0.5 * div.sigma) ** 2
    d_e = d_n = sig_heading = 0.0
    sig_pos = model.sig_pos
    converged_std = model.converged_std
    for k in range(steps):
        if k > 0:
            e_before, n_before = navp[E, 0], navp[N, 0]
            s_, c_ = math.sin(navp[YAW, 0] - nav_yaw[k - 1]), math.cos(navp[YAW, 0] - nav_yaw[k - 1])
            b_e = -(c_ * inc[k - 1, JAZE] - s_ * inc[k - 1, JAZN])
            b_n = -(s_ * inc[k - 1, JAZE] + c_ * inc[k - 1, JAZN])
            navp[U, 0] = nav_up[k - 1]
            propagate_tight(navp, inc[k - 1], nav_yaw[k - 1], zero_noise, 0.0, 0.0, 0.0, DIST_NONE, dist)
            d_e, d_n = navp[E, 0] - e_before, navp[N, 0] - n_before
            sig_heading = math.sqrt(p_kf[EPSI, EPSI])
            eskf_predict(p_kf, d_e, d_n, b_e, b_n, inc[k - 1, SZ], kf.q_pos, kf.q_yaw, kf.q_bias)
            m_prior[0] += d_e
            m_prior[1] += d_n
            sh2 = sig_heading * sig_heading
            p_prior[0, 0] += sig_pos * sig_pos + sh2 * d_n * d_n
            p_prior[1, 1] += sig_pos * sig_pos + sh2 * d_e * d_e
            p_prior[0, 1] -= sh2 * d_e * d_n
            p_prior[1, 0] -= sh2 * d_e * d_n
        s_, c_ = math.sin(navp[YAW, 0] - nav_yaw[k]), math.cos(navp[YAW, 0] - nav_yaw[k])
        for i in range(nb_beams):
            rot[i, 0] = c_ * offsets[k, i, 0] - s_ * offsets[k, i, 1]
            rot[i, 1] = s_ * offsets[k, i, 0] + c_ * offsets[k, i, 1]
            rot[i, 2] = offsets[k, i, 2]
        if hd:
            q_delta = math.sqrt(kf.q_yaw ** 2 + p_kf[EB, EB] * T * T)
            if k > 0:
                move(x, k)
                move(xp, k)
            best = weigh(k)
        else:
            best = propagate_and_weigh_loose(x, rng, k > 0, LooseMotion(d_e, d_n, sig_pos, sig_heading), rot,
                                             nav_up[k], grid, lik, consts, bufs)
        if o.tempering:
            stages, remaining = 1, 1.0
            while _ess(logw + remaining * ll) < o.tempering_ess * m and stages < o.tempering_stages:
                lo_, hi_ = 0.0, remaining
                for _ in range(30):
                    mid = 0.5 * (lo_ + hi_)
                    lo_, hi_ = (mid, hi_) if _ess(logw + mid * ll) >= o.tempering_ess * m else (lo_, mid)
                lam = max(lo_, 1e-6 * remaining)
                logw += lam * ll
                remaining -= lam
                wn = np.exp(logw - logw.max())
                wn /= wn.sum()
                weighted_estimate(x[:2], wn, -1, 0.0, mean, v, cov)
                resample_and_regularise(x, wn, logw, 0.0, rng, rs, x.shape[0], math.sqrt(v[0] + v[1]), uni, idx,
                                        scratch)
                best = weigh(k) if hd else propagate_and_weigh_loose(
                    x, rng, False, LooseMotion(0.0, 0.0, sig_pos, sig_heading), rot, nav_up[k], grid, lik, consts,
                    bufs)
                stages += 1
            ll *= remaining
            stages_out[k] = stages
        mx = add_log_weights(logw, ll)
        ess = normalise_with_ess(logw, mx, w)
        weighted_estimate(x[:2], w, -1, 0.0, mean, v, cov)
        spread = math.sqrt(v[0] + v[1])
        healthy = spread < converged_std and best < consistent_chi
        good = good + 1 if healthy else 0
        locked = locked or healthy
        since_fix += 1
        if good >= div.steps and since_fix >= kf.fix_every:
            since_fix = 0
            shape_ok = True
            if o.shape_gate is not None:
                shape_out[k] = unimodal_fraction(x, w, mean, cov)
                shape_ok = shape_out[k] >= o.shape_gate
            if hd:
                wpn = wp / wp.sum()
                m_prior[:] = xp[:2] @ wpn
                dp = xp[:2] - m_prior[:, None]
                p_prior[:, :] = (dp * wpn) @ dp.T
            if shape_ok and terrain_only_fix(mean, cov, m_prior, p_prior, kf.fix_max_std, zt, r):
                r[0, 0] += kf.r_floor * kf.r_floor
                r[1, 1] += kf.r_floor * kf.r_floor
                if first_fix:
                    position_reset(p_kf, r, navp, zt)
                    first_fix = False
                    fixed_out[k] = 1
                else:
                    p_save = p_kf.copy()
                    chi2 = eskf_update(p_kf, zt[0] - navp[E, 0], zt[1] - navp[N, 0], r, kf.gate, dx)
                    if not chi2 < kf.gate:
                        rejections += 1
                        if rejections >= kf.misses:
                            reopen_kf(p_kf, p0_pos, p0_yaw)
                            p_save = p_kf.copy()
                            chi2 = eskf_update(p_kf, zt[0] - navp[E, 0], zt[1] - navp[N, 0], r, kf.gate, dx)
                    if chi2 < kf.gate and abs(navp[BZ, 0] + dx[EB]) > bias_limit:
                        p_kf[:, :] = p_save  # the fix would make the gyro bias implausible
                        chi2 = np.inf
                    if chi2 < kf.gate:
                        rejections = 0
                        navp[E, 0] += dx[EE]
                        navp[N, 0] += dx[EN]
                        navp[YAW, 0] += dx[EPSI]
                        navp[BZ, 0] += dx[EB]
                        fixed_out[k] = 1
                        if hd:
                            x[2] -= dx[EPSI]
                    else:
                        rejected_out[k] = 1
            m_prior[:] = mean
            p_prior[:, :] = cov
            if hd:
                xp[:, :] = x
                wp[:] = w
        off_map = keep_on_map(navp[:2, 0], guard.bounds)
        out_en[k] = navp[E, 0], navp[N, 0]
        out_yaw[k], out_bias[k] = navp[YAW, 0], navp[BZ, 0]
        var[k] = p_kf[EE, EE], p_kf[EN, EN]
        var_yaw[k] = p_kf[EPSI, EPSI]
        ess_out[k] = ess
        healthy_out[k] = 1 if healthy else 0
        if best < np.inf:
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        if bad >= div.steps or off_map:
            side_half = half
            if o.reloc_kf:
                sig = math.sqrt(max(p_kf[EE, EE], p_kf[EN, EN]))
                side_half = min(max(half, 3.0 * sig), o.reloc_max_side_m / 2.0)
            side_out[k] = 2 * side_half
            uniform_horizontal(x, rng, navp[E, 0], navp[N, 0], side_half)
            if hd:
                x[2] = rng_np.standard_normal(m) * math.sqrt(p_kf[EPSI, EPSI])
                xp[:, :] = x
                wp[:] = 1.0 / m
            logw[:] = 0.0
            bad = good = 0
            locked = False
            first_fix = True
            _open_window(m_prior, p_prior, navp[E, 0], navp[N, 0], side_half)
            reinit_out[k] = 1
            continue
        resample_and_regularise(x, w, logw, ess, rng, rs, x.shape[0], spread, uni, idx, scratch)
        if hd:
            delta_mean[k] = float(np.mean(x[2]))
            delta_std[k] = float(np.std(x[2]))
    return MethodOutput(east=out_en[:, 0], north=out_en[:, 1], yaw=out_yaw, var_e=var[:, 0], var_n=var[:, 1],
                        var_heading=np.degrees(np.sqrt(var_yaw)) ** 2, ess=ess_out, reinit=reinit_out.astype(bool),
                        extra={"position_fix": fixed_out.astype(float), "fix_accepted": fixed_out.astype(float),
                               "fix_rejected": rejected_out.astype(float), "healthy": healthy_out.astype(float),
                               "var_yaw": var_yaw, "bias_z_deg_h": out_bias / DEG_PER_H, "fix_shape": shape_out,
                               "stages": stages_out, "reinit_side_m": side_out,
                               "delta_mean_deg": np.degrees(delta_mean), "delta_std_deg": np.degrees(delta_std)})


LOOSE_DVL = MethodRecord(name="proto-loose-dvl", seed_id=0, run=run_loose, options=Options,
                         summary="prototype closed-loop loose TAN with fix gating", cost_ns=300.0,
                         bound=("dvl", "position"), states=("east", "north", "heading", "gyro_bias_z"))
