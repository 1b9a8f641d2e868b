"""Plain-numpy references of the loose TAN's loops (``filters/loose.py``, ``filters/loose_turned.py``), for the tests.

Each function below is one jitted loop written again with numpy and the plain-numpy references of the loop's
kernels and of the generator's fills (``rng.fill_numpy``): no jitted function is called, directly or indirectly.
Each takes the loop's own arguments but ``out`` (the Kalman-feedback loops read their start position from
``out.en[0]``: here it is the argument ``start_en``) and returns what the loop fills and what it leaves in its
arrays (the cloud; the navigation KF's covariance); the arguments are not changed, but for ``rng``, which is
advanced as the loop advances it. They draw the same random numbers in the same order as the jitted loops (the
same fills of the same sizes, block by block of ``likelihood.BLOCK`` particles, so the fast generator's words
are rounded up per fill and per chunk just as the loops' are): given the same initial cloud and generator state
loop and reference agree up to rounding (the kernels' own sines, fastmath's reciprocals, their sums over four
accumulators and moments about the first particle, 2x2 inverses in closed form, where the references call numpy
and LAPACK). Their discrete decisions (convergence and fit counts, fixes, the gates, the KF's reopening,
divergence, keep-on-map, resampling) are taken from the same values, so they agree unless a value falls within
that rounding of a threshold.

* :func:`loose_filter_loop_numpy`: ``loose.loose_filter_loop`` (``filter.loose_architecture: fix-only``), the
  whole loop: the particles moved by the navigation's increments with the cross-track noise
  (``propagate.propagate_loose_numpy``), weighed with the plain Gaussian density
  (``likelihood.loglik_loose_numpy``, as the loop weighs them whatever ``filter.likelihood`` says), the estimate
  (``weighted_estimate_numpy``), the convergence count and the position fix it feeds back, the divergence and
  collapse re-draws (``cloud.uniform_horizontal_numpy``, then ``gaussian_horizontal_numpy`` for a Gaussian
  initial cloud; ``divergence_reinit`` false), the shared resampling (``resample.resample_and_regularise_numpy``:
  every scheme, both regularisation kernels or none, the re-spread). Nothing raises ValueError.
* :func:`loose_kalman_loop_numpy`: ``loose.loose_kalman_loop`` (``kalman-feedback`` without heading offsets),
  the whole loop: the corrected navigation's step (``loose.navigation_step_numpy``), the KF's prediction and
  update (``navigation/eskf.py``'s ``eskf_predict_numpy``, ``eskf_update_numpy``), the fix window's prior
  (``loose.advance_window_prior_numpy``), the beams turned by the corrected heading, the particles moved and
  weighed (``propagate_loose_numpy``, ``loglik_loose_numpy`` with the filter's density), the terrain-only fix
  (``eskf.terrain_only_fix_numpy``), the first fix's position reset (``loose.position_reset_numpy``), the gate,
  the reopening of a locked-out KF (``loose.reopen_kf_numpy``), keep-on-map (``tight.keep_on_map_numpy``), the
  spread guard, the re-initialisation and the resampling. Nothing raises ValueError.
* :func:`loose_turned_loop_numpy`: ``loose_turned.loose_turned_loop`` (the recommended default), the whole
  loop: the heading-offset particles and the never-weighted prior cloud moved by
  ``loose_turned.propagate_loose_turned_numpy``, the headings drawn at every (re)initialisation, the tight
  likelihood of the turned beams (``likelihood.loglik_tight_numpy``, no distance innovation), the fit test and
  its one-wild-beam rule (:func:`~tanbench.filters.loose_turned.best_particle_fit_numpy`), the shape gate
  (``unimodal_fraction_numpy``), the window prior from the prior cloud, the fix-prior gate and its fallback
  (``eskf.fix_prior_chi2_numpy``), the posterior first fix, the fix covariance's factor ``kf.r_scale``, the
  bias gate (the KF's covariance restored), the reopening with the cloud's heading
  (``cloud_heading_offset_numpy``) and the reopened KF's position reset, keep-on-map, the spread guard, the
  re-initialisation and the resampling of rows E, N, YAW: every setting of
  :class:`~tanbench.filters.loose_turned.Gates`.
  A particle's yaw wound ``trig.WOUND`` / 2 rad or more away from the corrected heading (or NaN) raises
  ValueError: the kernels' ``trig.sin_cos`` then takes a pseudo-random direction (``trig.wound_angle``), which
  the reference does not follow; only a filter that has lost its heading for good winds it so far.

Out of scope everywhere (not a setting: inputs no run produces): an exactly singular 2x2 covariance given to the
terrain-only fix (``eskf.terrain_only_fix_numpy`` inverts before it checks the determinants, and numpy raises
LinAlgError where the kernel returns "no fix"; a weighted cloud or its prior cloud never has one).

The references were written from the loops' code, not from a description; where a loop keeps a quirk (the
fix-only loop keeps its convergence count and its latest fix across a re-initialisation; the Kalman-feedback
loops' keep-on-map clamps the corrected navigation itself, before it is recorded; in the turned loop a fix the bias
gate rejects neither counts towards reopening the KF nor restarts that count, and a KF reopened with the cloud's
heading keeps that heading even when the bias gate then rejects the fix) the reference keeps it too.
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.filters.cloud import gaussian_horizontal_numpy, uniform_horizontal_numpy
from tanbench.filters.estimate import weighted_estimate_numpy
from tanbench.filters.likelihood import Likelihood, loglik_loose_numpy, loglik_tight_numpy
from tanbench.filters.loose import (FixOnlyOutputs, KalmanOutputs, advance_window_prior_numpy, navigation_step_numpy,
                                    position_reset_numpy, reopen_kf_numpy)
from tanbench.filters.loose_turned import (best_particle_fit_numpy, cloud_heading_offset_numpy,
                                           propagate_loose_turned_numpy, unimodal_fraction_numpy)
from tanbench.filters.propagate import propagate_loose_numpy
from tanbench.filters.resample import normalize_log_weights_numpy, resample_and_regularise_numpy
from tanbench.filters.rng import fill_numpy
from tanbench.filters.state import BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.tight import keep_on_map_numpy
from tanbench.filters.tight_reference import block_normals, check_not_wound, grid_maps, loop_draw
from tanbench.navigation.eskf import (EB, EE, EN, EPSI, eskf_predict_numpy, eskf_update_numpy, fix_prior_chi2_numpy,
                                      terrain_only_fix_numpy)
from tanbench.navigation.increments import SZ

PLAIN = Likelihood(False, 0, 4.0)  # the fix-only loop's density: the plain Gaussian


# --------------------------------------------------------------------------------------
# what the loops share
# --------------------------------------------------------------------------------------
def _weigh(logw, ll):
    """The log-weights after an update's log-likelihoods, the normalised weights and the ESS (``add_log_weights``,
    ``normalise_with_ess``)."""
    logw = logw + ll
    w, _ = normalize_log_weights_numpy(logw)
    return logw, w, 1.0 / np.sum(w * w)


def _record(out, k, nav, p, ess, healthy):
    """``loose.record_kalman_update``: update ``k`` of a Kalman-feedback loop into ``out``."""
    out.en[k] = nav[E, 0], nav[N, 0]
    out.yaw[k] = nav[YAW, 0]
    out.bias[k] = nav[BZ, 0]
    out.var[k] = p[EE, EE], p[EN, EN]
    out.var_yaw[k] = p[EPSI, EPSI]
    out.ess[k] = ess
    out.healthy[k] = int(healthy)
    out.reinit[k] = 0


def _kalman_outputs(steps):
    return KalmanOutputs(np.empty((steps, 2)), np.empty(steps), np.empty(steps), np.empty((steps, 2)), np.empty(steps),
                         np.empty(steps), np.zeros(steps, dtype=np.int64), np.zeros(steps, dtype=np.int64),
                         np.zeros(steps, dtype=np.int64), np.zeros(steps, dtype=np.int64))


def _keep_navigation_on_map(nav, bounds):
    """``keep_on_map(nav[:2, 0], bounds)``: the corrected navigation clamped in place; whether it had left."""
    clamped, off_map = keep_on_map_numpy(nav[[E, N], 0], bounds)
    nav[E, 0], nav[N, 0] = clamped
    return off_map


def _window(centre_e, centre_n, half_side):
    """``loose._open_window``: the uniform square's mean and covariance."""
    return np.array([centre_e, centre_n], dtype=float), np.eye(2) * (half_side * half_side / 3.0)


# --------------------------------------------------------------------------------------
# fix-only
# --------------------------------------------------------------------------------------
def loose_filter_loop_numpy(x, rng, track, offsets, grid, settings):
    """Plain-numpy reference of ``loose_filter_loop(x, rng, track, offsets, grid, settings, out)`` (module
    docstring): returns (the :class:`~tanbench.filters.loose.FixOnlyOutputs` the loop fills, the cloud the loop
    leaves in ``x``), ``rng`` advanced as the loop advances it. ``grid`` the ``NodeGrid`` the loop reads (its
    grids taken apart, ``tight_reference.grid_maps``)."""
    d0, nav_en, nav_up = track
    model, rs, div, half_side, readings = settings
    zmap, mvar = grid_maps(grid)
    draw = loop_draw(rng)
    x = np.array(x, dtype=float)
    m = x.shape[1]
    steps = offsets.shape[0]
    out = FixOnlyOutputs(np.empty((steps, 2)), np.empty((steps, 2)), np.empty(steps), np.empty(steps),
                         np.zeros(steps, dtype=np.int64), np.zeros(steps, dtype=np.int64))
    logw = np.zeros(m)
    fix = np.zeros(2)  # the latest fix's correction of the navigation position
    bad = good = 0
    consistent_chi = (0.5 * div.sigma) ** 2
    for k in range(steps):
        if k > 0:
            x = propagate_loose_numpy(x, d0[k - 1, 0], d0[k - 1, 1], block_normals(rng, 3, m), model.sig_pos,
                                      model.sig_heading)
        ll, best = loglik_loose_numpy(x, offsets[k], nav_up[k], zmap, mvar, PLAIN, model.sig_u, model.outside_sigma)
        logw, w, ess = _weigh(logw, ll)
        mean, v, cov = weighted_estimate_numpy(x, w, -1, 0.0)
        spread = math.sqrt(v[0] + v[1])
        good = good + 1 if (spread < model.converged_std and best < consistent_chi) else 0
        converged = good >= div.steps
        if converged:
            fix = mean[:2] - nav_en[k]
        out.en[k] = nav_en[k] + fix
        out.var[k] = v[:2]
        out.cov_en[k] = cov[0, 1]
        out.ess[k] = ess
        out.fixed[k] = int(converged)
        if best < np.inf:  # an update without any bottom lock says nothing about divergence
            bad = bad + 1 if best > div.sigma * div.sigma else 0
        diverged = readings.div_reinit and bad >= div.steps
        collapsed = ess < rs.ess_threshold * m and spread < readings.collapse_spread
        if diverged or collapsed:
            centre = out.en[k] if diverged else mean[:2]
            x = uniform_horizontal_numpy(x, fill_numpy(rng, (2, m), False), centre[0], centre[1], half_side)
            if readings.cloud_std > 0.0:
                x = gaussian_horizontal_numpy(x, fill_numpy(rng, (2, m), True), centre[0], centre[1],
                                              readings.cloud_std)
            logw = np.zeros(m)
            bad = 0
            out.reinit[k] = 1
            continue
        x, logw = resample_and_regularise_numpy(x, w, logw, ess, draw, rs, 2, spread)
    return out, x


# --------------------------------------------------------------------------------------
# Kalman feedback
# --------------------------------------------------------------------------------------
def _navigation_start(start_en, nav_yaw):
    """The corrected navigation at the start, as one tight particle (8, 1)."""
    nav = np.zeros((N_TIGHT, 1))
    nav[E, 0], nav[N, 0], nav[YAW, 0] = start_en[0], start_en[1], nav_yaw[0]
    return nav


def _kf_constants(p, div, kf):
    """The Kalman loops' constants: the initial position and heading variances (a reopened KF's), the
    consistent fit's chi-square and the fixes' floor covariance."""
    return p[EE, EE], p[EPSI, EPSI], (0.5 * div.sigma) ** 2, np.eye(2) * (kf.r_floor * kf.r_floor)


def loose_kalman_loop_numpy(x, rng, track, offsets, grid, settings, p_kf, start_en):
    """Plain-numpy reference of ``loose_kalman_loop(x, rng, track, offsets, grid, settings, p_kf, out)`` with
    ``out.en[0]`` = ``start_en`` (module docstring): returns (the :class:`~tanbench.filters.loose.KalmanOutputs`
    the loop fills, the cloud it leaves in ``x``, the covariance it leaves in ``p_kf``), ``rng`` advanced as the
    loop advances it."""
    inc, nav_yaw, nav_up = track
    model, rs, div, half_side, lik, guard, kf = settings
    zmap, mvar = grid_maps(grid)
    draw = loop_draw(rng)
    x = np.array(x, dtype=float)
    p = np.array(p_kf, dtype=float)
    m = x.shape[1]
    steps = offsets.shape[0]
    out = _kalman_outputs(steps)
    m_prior, p_prior = _window(start_en[0], start_en[1], half_side)
    nav = _navigation_start(start_en, nav_yaw)
    logw = np.zeros(m)
    bad = good = since_fix = rejections = 0
    first_fix = True
    locked = False
    p0_pos, p0_yaw, consistent_chi, floor = _kf_constants(p, div, kf)
    for k in range(steps):
        if k > 0:
            nav, d_e, d_n, b_e, b_n = navigation_step_numpy(nav, inc[k - 1], nav_yaw[k - 1], nav_up[k - 1])
            sig_heading = math.sqrt(p[EPSI, EPSI])
            p = eskf_predict_numpy(p, d_e, d_n, b_e, b_n, inc[k - 1, SZ], kf.q_pos, kf.q_yaw, kf.q_bias)
            m_prior, p_prior = advance_window_prior_numpy(m_prior, p_prior, d_e, d_n, model.sig_pos, sig_heading)
            x = propagate_loose_numpy(x, d_e, d_n, block_normals(rng, 3, m), model.sig_pos, sig_heading)
        # the beams turned by the corrected heading's offset from the navigation heading
        turn = nav[YAW, 0] - nav_yaw[k]
        c, s = math.cos(turn), math.sin(turn)
        o = offsets[k]
        rot = np.stack([c * o[:, 0] - s * o[:, 1], s * o[:, 0] + c * o[:, 1], o[:, 2]], axis=1)
        ll, best = loglik_loose_numpy(x, rot, nav_up[k], zmap, mvar, lik, model.sig_u, model.outside_sigma)
        logw, w, ess = _weigh(logw, ll)
        mean, v, cov = weighted_estimate_numpy(x, w, -1, 0.0)
        spread = math.sqrt(v[0] + v[1])
        healthy = spread < model.converged_std and best < consistent_chi
        good = good + 1 if healthy else 0
        locked = locked or healthy
        since_fix += 1
        if good >= div.steps and since_fix >= kf.fix_every:
            since_fix = 0
            usable, zt, r = terrain_only_fix_numpy(mean[:2], cov, m_prior, p_prior, kf.fix_max_std)
            if usable:
                r = r + floor
                if first_fix:  # one fix cannot tell an initial position error from a heading error
                    p, nav = position_reset_numpy(p, r, nav, zt)
                    first_fix = False
                    out.fixed[k] = 1
                else:
                    chi2, dx, p = eskf_update_numpy(p, zt - nav[[E, N], 0], r, kf.gate)
                    if not chi2 < kf.gate:
                        rejections += 1
                        if rejections >= kf.misses:  # the KF is locked out: reopened, and the fix tried again
                            p = reopen_kf_numpy(p, p0_pos, p0_yaw)
                            chi2, dx, p = eskf_update_numpy(p, zt - nav[[E, N], 0], r, kf.gate)
                    if chi2 < kf.gate:
                        rejections = 0
                        nav[[E, N, YAW, BZ], 0] += dx[[EE, EN, EPSI, EB]]
                        out.fixed[k] = 1
                    else:
                        out.rejected[k] = 1
            m_prior, p_prior = mean[:2].copy(), cov.copy()
        off_map = _keep_navigation_on_map(nav, guard.bounds)
        _record(out, k, nav, p, ess, healthy)
        if best < np.inf:  # an update without any bottom lock says nothing about divergence
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        if bad >= div.steps or off_map:
            x = uniform_horizontal_numpy(x, fill_numpy(rng, (2, m), False), nav[E, 0], nav[N, 0], half_side)
            logw = np.zeros(m)
            bad = good = 0
            locked = False
            first_fix = True
            m_prior, p_prior = _window(nav[E, 0], nav[N, 0], half_side)
            out.reinit[k] = 1
            continue
        x, logw = resample_and_regularise_numpy(x, w, logw, ess, draw, rs, 2, spread)
    return out, x, p


# --------------------------------------------------------------------------------------
# Kalman feedback with heading-offset particles
# --------------------------------------------------------------------------------------
def loose_turned_loop_numpy(x, rng, track, grid, settings, gates, p_kf, start_en):
    """Plain-numpy reference of ``loose_turned_loop(x, rng, track, grid, settings, gates, p_kf, out)`` with
    ``out.en[0]`` = ``start_en`` (module docstring): returns (the :class:`~tanbench.filters.loose.KalmanOutputs`
    the loop fills, the cloud it leaves in ``x`` (8, M), the covariance it leaves in ``p_kf``), ``rng`` advanced
    as the loop advances it. Only rows E, N of ``x`` are read, as by the loop."""
    inc, nav_yaw, nav_pitch, nav_roll, nav_up, beams, ranges = track
    model, rs, div, half_side, lik, guard, kf = settings
    (bias_limit, shape_min, dt, prior_gate, prior_fallback, fit_test, fit_neutral, first_posterior, reopen_cloud,
     reopen_reset) = gates
    zmap, mvar = grid_maps(grid)
    draw = loop_draw(rng)
    p = np.array(p_kf, dtype=float)
    m = np.shape(x)[1]
    steps = ranges.shape[0]
    out = _kalman_outputs(steps)
    nav = _navigation_start(start_en, nav_yaw)
    heading_std = math.sqrt(p[EPSI, EPSI])
    cloud = np.zeros((N_TIGHT, m))  # the loop's rows other than E and N zeroed, then its headings drawn
    cloud[[E, N]] = np.asarray(x, dtype=float)[[E, N]]
    cloud[YAW] = nav[YAW, 0] + heading_std * fill_numpy(rng, m, True)
    x = cloud
    xp, wp = x.copy(), np.full(m, 1.0 / m)  # the never-weighted prior cloud and its weights
    logw = np.zeros(m)
    bad = good = since_fix = rejections = 0
    first_fix = True
    locked = False
    p0_pos, p0_yaw, consistent_chi, floor = _kf_constants(p, div, kf)
    for k in range(steps):
        if k > 0:
            yaw_before = nav[YAW, 0]
            nav, d_e, d_n, b_e, b_n = navigation_step_numpy(nav, inc[k - 1], nav_yaw[k - 1], nav_up[k - 1])
            dyaw = nav[YAW, 0] - yaw_before
            q_delta = math.sqrt(kf.q_yaw * kf.q_yaw + p[EB, EB] * dt * dt)
            p = eskf_predict_numpy(p, d_e, d_n, b_e, b_n, inc[k - 1, SZ], kf.q_pos, kf.q_yaw, kf.q_bias)
            for cloud in (x, xp):
                check_not_wound(k, (cloud[YAW], yaw_before))
            x = propagate_loose_turned_numpy(x, d_e, d_n, yaw_before, dyaw, block_normals(rng, 3, m), model.sig_pos,
                                             q_delta)
            xp = propagate_loose_turned_numpy(xp, d_e, d_n, yaw_before, dyaw, block_normals(rng, 3, m),
                                              model.sig_pos, q_delta)
        x[U], x[PITCH], x[ROLL] = nav_up[k], nav_pitch[k], nav_roll[k]
        check_not_wound(k, (x[YAW], nav[YAW, 0]))
        ll, best = loglik_tight_numpy(x, beams, ranges[k], zmap, mvar, lik, model.sig_u, model.outside_sigma, None, 1.0)
        logw, w, ess = _weigh(logw, ll)
        mean, v, cov = weighted_estimate_numpy(x[:2], w, -1, 0.0)
        spread = math.sqrt(v[0] + v[1])
        healthy = spread < model.converged_std and best < consistent_chi
        ready = healthy if fit_test else spread < model.converged_std
        # with fit_neutral, an update that fails the fit for want of bottom lock or by one wild beam leaves the count
        count_stays = (fit_neutral and fit_test and spread < model.converged_std and not healthy
                       and (best == np.inf or best_particle_fit_numpy(x, ll, beams, ranges[k], zmap, mvar, lik,
                                                                      model.sig_u, model.outside_sigma)
                            < consistent_chi))
        if not count_stays:
            good = good + 1 if ready else 0
        locked = locked or healthy
        since_fix += 1
        if good >= div.steps and since_fix >= kf.fix_every:
            since_fix = 0
            shape_ok = shape_min <= 0.0 or unimodal_fraction_numpy(x, w, mean, cov) >= shape_min
            # the window's prior: the never-weighted cloud's weighted mean and covariance
            wp = wp / wp.sum()
            m_prior, _, p_prior = weighted_estimate_numpy(xp[:2], wp, -1, 0.0)
            usable, zt, r = terrain_only_fix_numpy(mean, cov, m_prior, p_prior, kf.fix_max_std) if shape_ok \
                else (False, None, None)
            if usable and prior_gate < np.inf and not fix_prior_chi2_numpy(zt, r, m_prior, p_prior) < prior_gate:
                if prior_fallback:  # the cloud's own estimate, no surer than it was before the window
                    zt, r = mean.copy(), p_prior.copy()
                else:
                    usable = False  # refused, not a KF miss
                    out.rejected[k] = 1
            if usable:
                if first_fix and first_posterior:  # a reset to the cloud's posterior
                    zt, r = mean.copy(), cov.copy()
                r = r + floor
                if first_fix:
                    p, nav = position_reset_numpy(p, r, nav, zt)
                    first_fix = False
                    out.fixed[k] = 1
                else:
                    p_save = p.copy()
                    r_upd = r * kf.r_scale  # a reset (first fix, reopened position) takes the fix's own r
                    chi2, dx, p = eskf_update_numpy(p, zt - nav[[E, N], 0], r_upd, kf.gate)
                    reset = False
                    if not chi2 < kf.gate:
                        rejections += 1
                        if rejections >= kf.misses:
                            p = reopen_kf_numpy(p, p0_pos, p0_yaw)
                            if reopen_cloud:  # the particles' yaws are absolute: the cloud's own heading
                                nav[YAW, 0] += cloud_heading_offset_numpy(x[YAW], w, nav[YAW, 0])
                            p_save = p.copy()
                            chi2, dx, p = eskf_update_numpy(p, zt - nav[[E, N], 0], r_upd, kf.gate)
                            reset = reopen_reset and not chi2 < kf.gate
                    if chi2 < kf.gate and abs(nav[BZ, 0] + dx[EB]) > bias_limit:
                        p = p_save  # the fix would make the gyro bias implausible
                        chi2 = np.inf
                    if reset:
                        p, nav = position_reset_numpy(p, r, nav, zt)
                        rejections = 0
                        out.fixed[k] = 1
                    elif chi2 < kf.gate:
                        rejections = 0
                        nav[[E, N, YAW, BZ], 0] += dx[[EE, EN, EPSI, EB]]  # every particle's offset -= dx_psi
                        out.fixed[k] = 1
                    else:
                        out.rejected[k] = 1
            xp, wp = x.copy(), w.copy()
        off_map = _keep_navigation_on_map(nav, guard.bounds)
        _record(out, k, nav, p, ess, healthy)
        if best < np.inf:
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        if bad >= div.steps or off_map:
            x = uniform_horizontal_numpy(x, fill_numpy(rng, (2, m), False), nav[E, 0], nav[N, 0], half_side)
            x[YAW] = nav[YAW, 0] + math.sqrt(p[EPSI, EPSI]) * fill_numpy(rng, m, True)
            xp, wp = x.copy(), np.full(m, 1.0 / m)
            logw = np.zeros(m)
            bad = good = 0
            locked = False
            first_fix = True
            out.reinit[k] = 1
            continue
        x, logw = resample_and_regularise_numpy(x, w, logw, ess, draw, rs, 3, spread)
    return out, x, p
