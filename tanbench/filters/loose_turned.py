"""The closed-loop loose TAN with heading-offset particles and gated fixes (issue 24,
docs/filters.md section 5 items 6-8; ``filter.loose_heading_offsets``).

The built-in loose PF (``filters/loose.py``, :func:`~tanbench.filters.loose.loose_kalman_loop`)
moves every particle by the corrected navigation's displacement with a cross-track random
walk sigma_psi |d| per update; a heading error makes the truth drift away coherently (1 m/s
at 30 deg and 2 m/s), which the random walk cannot follow (docs/filters.md 3.3). Here each
particle carries its own heading, psi_c + delta_j (psi_c the corrected navigation heading):

* it moves by the corrected displacement turned by delta_j, plus ``sig_pos`` noise, and
  delta_j random-walks with q_delta = sqrt(q_yaw^2 + P_bb T^2) (the KF's heading process noise
  and its bias uncertainty over the interval; :func:`propagate_loose_turned`);
* its beams are turned by delta_j: the cloud is stored in the tight filter's layout (8, M)
  with the navigation's up, pitch and roll and the particle's absolute yaw, and weighed by the
  tight likelihood kernel (``likelihood.loglik_tight_pass``), which is exact for Rz(psi_c +
  delta) = Rz(delta) Rz(psi_c);
* delta_j ~ N(0, P_psipsi) (the KF's heading variance) at every (re)initialisation; an
  accepted fix turns the corrected heading by dx_psi and, the particle yaws being absolute,
  every delta by -dx_psi;
* the prior of the terrain-only fix is a second cloud moved by the same kernel with its own
  noise and never weighted, restarted from the posterior (and its weights) at each fix
  attempt and at every (re)initialisation; its weighted mean and covariance replace the
  analytic window prior of the built-in loop.

Two gates keep fixes from dragging the navigation KF into a wrong basin (item 8): a fix
whose update would put the z-gyro bias estimate above ``bias_limit`` (rad/s) is rejected
(the KF's covariance is restored), and no fix is taken from a cloud with less than
``shape_min`` of its weight inside its own chi^2_2 95 % ellipse (:func:`unimodal_fraction`).
A third, ``prior_gate`` (``filter.loose_fix_prior_gate``, off by default; docs/filters.md 9),
refuses a terrain-only fix whose chi-square against its own window prior
(``eskf.fix_prior_chi2``) is not below it: the fix then disagrees with the PF's own posterior,
an artefact of dividing two nearly equal covariances. A refused fix is recorded as rejected
but does not count towards reopening the KF. With ``prior_fallback``
(``filter.loose_fix_prior_fallback: posterior``, docs/filters.md 9.1) such a fix is replaced by
the PF's posterior mean with the window prior's covariance and goes on to the KF's own gates.
A fix is attempted after ``divergence_steps`` updates in a row with a cloud std below
``loose_converged_std_m`` and, with ``fit_test`` (``filter.loose_fix_fit_test``), a best particle
whose mean d^2 / v over the beams is below (divergence_sigma / 2)^2. One wild range on one beam
(``faults.outlier_fraction``) or an update without bottom lock fails that fit; with ``fit_neutral``
(``filter.loose_fix_fit_one_wild_beam``, the default since docs/filters.md 11.3) such an update leaves
the count as it is (:func:`fit_without_worst_beam` judges the one wild beam), without it the count
restarts (docs/filters.md 11).
A KF reopened after ``kf.misses`` rejected fixes in a row (``reopen_kf``: its initial position variance back) may
take the cloud's heading (``reopen_cloud``, ``filter.loose_reopen_heading: cloud``, docs/filters.md 14); with
``reopen_reset`` (``filter.loose_reopen_position: fix``, docs/filters.md 15) a fix the reopened KF still rejects
sets its position as a first fix does: a position error beyond a few of the initial standard deviations cannot
otherwise be corrected by any later fix.
A KF update takes the fix's covariance times ``kf.r_scale`` (``filter.loose_fix_correlation_s``, 1 by default:
fixes whose errors are correlated over several fix intervals carry less than independent ones; docs/filters.md 16).
Everything else (fix interval, chi-square gate, floor, reopening a locked-out KF,
divergence, keep-on-map) is the built-in loop's.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.cloud import uniform_horizontal
from tanbench.filters.estimate import weighted_estimate
from tanbench.filters.likelihood import (BLOCK, beam_constants, beam_vectors, loglik_tight_numpy, loglik_tight_pass,
                                        new_likelihood_work, work_block)
from tanbench.filters.loose import navigation_step, position_reset, record_kalman_update, reopen_kf
from tanbench.filters.resample import add_log_weights, normalise_with_ess, resample_and_regularise
from tanbench.filters.rng import fill_normals
from tanbench.filters.state import BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.tight import keep_on_map
from tanbench.filters.trig import attitude_reference, sin_cos
from tanbench.navigation.eskf import (EB, EE, EN, EPSI, N_ERROR, copy_matrix, eskf_predict, eskf_update,
                                      fix_prior_chi2, terrain_only_fix)
from tanbench.navigation.increments import SZ

LOOSE_TURNED_COLS = np.array([E, N, YAW], dtype=np.int64)  # the rows the regularisation jitters
# the navigation solution at the K updates: the (K-1, 12) increments, yaw, pitch, roll and up (K,); the body-frame
# beam unit vectors (m, 3) and the ranges (K, m)
TurnedTrack = namedtuple("TurnedTrack", "inc yaw pitch roll up beams ranges")
# the fix gates: the z-gyro bias limit (rad/s; inf: off), the cloud's weight inside its 95 % ellipse (0: off), the
# sampling time (s), the chi-square above which a terrain-only fix disagrees with its own window prior (inf: off), and
# whether such a fix is replaced by the PF's posterior mean with the window prior's covariance (else refused), and
# whether the updates before a fix must fit (the best particle's mean d^2 / v below (divergence_sigma / 2)^2) besides
# having a cloud std below loose_converged_std_m (filter.loose_fix_fit_test), and whether, with the fit test, an update
# that fails it by one beam only, or has no bottom lock, leaves the count as it is (filter.loose_fix_fit_one_wild_beam),
# and whether the first fix after a (re)initialisation resets the KF's position to the cloud's posterior (mean and
# covariance) instead of the terrain-only fix (filter.loose_first_fix), and whether a KF reopened after rejected fixes
# takes the cloud's mean heading (filter.loose_reopen_heading), and whether a fix the reopened KF still rejects sets
# its position as a first fix does (filter.loose_reopen_position)
Gates = namedtuple("Gates", "bias_limit shape_min dt prior_gate prior_fallback fit_test fit_neutral first_posterior "
                            "reopen_cloud reopen_reset", defaults=(np.inf, False, True, False, False, False, False))
# a one-particle cloud, its beam, work arrays, distance rows and log-likelihood (fit_without_worst_beam)
OneParticle = namedtuple("OneParticle", "x vec work dist ll")
CHI2_2_95 = 5.991464547107979  # chi^2 with 2 degrees of freedom, 95 % quantile


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def propagate_loose_turned(x, d_e, d_n, yaw_ref, dyaw, noise, sig_pos, q_delta, lo=0):
    """Particles ``lo .. lo + n - 1`` of ``x`` (8, M; rows E, N, YAW used) move by (d_e, d_n)
    turned by their heading offset from ``yaw_ref`` (the corrected heading at the interval
    start) plus ``sig_pos`` noise; their yaw by ``dyaw`` (the corrected heading's increment)
    plus ``q_delta`` noise. ``noise`` (3, n) standard normals."""
    n = noise.shape[1]
    e = x[E, lo:lo + n]
    nn = x[N, lo:lo + n]
    yaw = x[YAW, lo:lo + n]
    n_e, n_n, n_y = noise[0], noise[1], noise[2]
    for j in range(n):
        s, c = sin_cos(yaw[j] - yaw_ref)
        e[j] += c * d_e - s * d_n + sig_pos * n_e[j]
        nn[j] += s * d_e + c * d_n + sig_pos * n_n[j]
        yaw[j] += dyaw + q_delta * n_y[j]


def propagate_loose_turned_numpy(x, d_e, d_n, yaw_ref, dyaw, noise, sig_pos, q_delta):
    """Plain-numpy reference of :func:`propagate_loose_turned` on the whole cloud (new array)."""
    x = np.array(x, dtype=float)
    delta = x[YAW] - yaw_ref
    c, s = np.cos(delta), np.sin(delta)
    x[E] += c * d_e - s * d_n + sig_pos * noise[0]
    x[N] += s * d_e + c * d_n + sig_pos * noise[1]
    x[YAW] += dyaw + q_delta * noise[2]
    return x


@nb.njit(cache=True)
def unimodal_fraction(x, w, mean, cov):
    """The weight of the particles inside the cloud's own 95 % ellipse: (x - mean)^T cov^-1
    (x - mean) <= chi^2_2(0.95), rows 0, 1 of ``x``; 0 for a singular ``cov``. About 0.95 for a
    Gaussian cloud, less for a split one."""
    det = cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[1, 0]
    if not det > 0.0:
        return 0.0
    i00 = cov[1, 1] / det
    i11 = cov[0, 0] / det
    i01 = -cov[0, 1] / det
    total = 0.0
    for j in range(x.shape[1]):
        de = x[0, j] - mean[0]
        dn = x[1, j] - mean[1]
        if i00 * de * de + 2.0 * i01 * de * dn + i11 * dn * dn <= CHI2_2_95:
            total += w[j]
    return total


def unimodal_fraction_numpy(x, w, mean, cov):
    """Plain-numpy reference of :func:`unimodal_fraction`."""
    cov = np.asarray(cov, dtype=float)
    if not np.linalg.det(cov) > 0:
        return 0.0
    d = np.asarray(x)[:2] - np.asarray(mean)[:2, None]
    q = np.einsum("ij,ik,kj->j", d, np.linalg.inv(cov), d)
    return float(np.asarray(w)[q <= CHI2_2_95].sum())


@nb.njit(cache=True)
def cloud_heading_offset(yaw, w, yaw_ref):
    """The weighted circular mean of the particle yaws ``yaw`` (weights ``w``, summing to 1) as an angle from
    ``yaw_ref``, in (-pi, pi]."""
    s = 0.0
    c = 0.0
    for j in range(yaw.shape[0]):
        s += w[j] * math.sin(yaw[j] - yaw_ref)
        c += w[j] * math.cos(yaw[j] - yaw_ref)
    return math.atan2(s, c)


def cloud_heading_offset_numpy(yaw, w, yaw_ref):
    """Plain-numpy reference of :func:`cloud_heading_offset`."""
    d = np.asarray(yaw, dtype=float) - yaw_ref
    return float(np.arctan2(np.sum(w * np.sin(d)), np.sum(w * np.cos(d))))


@nb.njit(cache=True)
def _draw_headings(x, rng, yaw_c, std):
    """Row YAW of ``x`` <- yaw_c + std N(0, 1)."""
    row = x[YAW]
    fill_normals(rng, row)
    for j in range(row.shape[0]):
        row[j] = yaw_c + std * row[j]


@nb.njit(cache=True)
def fit_without_worst_beam(x, ll, vec, grid, lik, consts, att, no_distance, one):
    """The mean d^2 / v over the beams ``vec`` (``beam_vectors``) of the particle of ``x`` with the largest
    log-likelihood ``ll``, its worst beam left out when 3 or more beams have a range (else over all of them);
    inf without a beam. Each beam goes through the likelihood pass alone on a one-particle cloud (``one``,
    :data:`OneParticle`), so its d^2 / v is the pass's own."""
    best_j = 0
    for j in range(ll.shape[0]):
        if ll[j] > ll[best_j]:
            best_j = j
    for c in range(x.shape[0]):
        one.x[c, 0] = x[c, best_j]
    total = 0.0
    worst = 0.0
    beams = vec.shape[0]
    # run-time integers, not literals: a literal 0 or 1 would compile the likelihood pass (and all it
    # calls) a second time for this caller alone, about 5 s of a first run
    first, count = np.int64(0), np.int64(1)
    for b in range(beams):
        for c in range(3):
            one.vec[0, c] = vec[b, c]
        fit = loglik_tight_pass(one.x, first, one.vec, grid, lik, consts, att, one.dist, no_distance,
                                work_block(one.work, count), one.ll)
        total += fit
        worst = max(worst, fit)
    if beams >= 3:
        return (total - worst) / (beams - 1)
    return total / beams if beams > 0 else np.inf


def fit_without_worst_beam_numpy(per_beam_fits):
    """Plain-numpy reference of :func:`fit_without_worst_beam`'s last step, from the chosen particle's
    per-beam d^2 / v."""
    f = np.asarray(per_beam_fits, dtype=float)
    if f.size >= 3:
        return float((f.sum() - f.max()) / (f.size - 1))
    return float(f.mean()) if f.size else np.inf


def best_particle_fit_numpy(x, ll, beams, ranges, zmap, mvar, lik, sig_u, outside_sigma):
    """Plain-numpy reference of the whole :func:`fit_without_worst_beam` with ``vec`` = ``beam_vectors(beams,
    ranges)`` (the map as ``likelihood.loglik_tight_numpy`` takes it): the particle of ``x`` (8, M) with the largest
    log-likelihood ``ll`` (the first of equals), each beam with a range alone through ``loglik_tight_numpy`` on it
    (one particle, one beam: its d^2 / v), then :func:`fit_without_worst_beam_numpy`."""
    j = int(np.argmax(ll))
    one = np.asarray(x, dtype=float)[:, j:j + 1]
    ranges = np.asarray(ranges, dtype=float)
    fits = [loglik_tight_numpy(one, beams[i:i + 1], ranges[i:i + 1], zmap, mvar, lik, sig_u, outside_sigma, None,
                               1.0)[1] for i in np.flatnonzero(~np.isnan(ranges))]
    return fit_without_worst_beam_numpy(fits)


@nb.njit(cache=True)
def _level(x, up, pitch, roll):
    """Rows U, PITCH, ROLL of ``x`` <- the navigation's (the loose cloud does not estimate them)."""
    for j in range(x.shape[1]):
        x[U, j] = up
        x[PITCH, j] = pitch
        x[ROLL, j] = roll


@nb.njit(cache=True)
def _move_cloud(x, rng, d_e, d_n, yaw_ref, dyaw, sig_pos, q_delta, noise_buf, block):
    m = x.shape[1]
    for lo in range(0, m, block):
        n = min(block, m - lo)
        noise = noise_buf[:3 * n].reshape((3, n))
        fill_normals(rng, noise)
        propagate_loose_turned(x, d_e, d_n, yaw_ref, dyaw, noise, sig_pos, q_delta, lo)


@nb.njit(cache=True)
def _restart_prior(xp, wp, x, w):
    for c in range(x.shape[0]):
        for j in range(x.shape[1]):
            xp[c, j] = x[c, j]
    for j in range(w.shape[0]):
        wp[j] = w[j]


@nb.njit(cache=True)
def loose_turned_loop(x, rng, track, grid, settings, gates, p_kf, out):
    """:func:`~tanbench.filters.loose.loose_kalman_loop` with heading-offset particles (module
    docstring). ``x`` (8, M): rows E, N hold the initial cloud (the rest is filled here);
    ``track`` a :class:`TurnedTrack`, ``settings`` the loop's ``KalmanSettings`` and ``out`` its
    ``KalmanOutputs`` (filters/loose.py), ``gates`` the :class:`Gates`."""
    inc, nav_yaw, nav_pitch, nav_roll, nav_up, beams, ranges = track
    model, rs, div, half_side, lik, guard, kf = settings
    out_en, _, _, _, _, _, reinit_out, fixed_out, rejected_out, _ = out  # the rest: record_kalman_update
    (bias_limit, shape_min, dt, prior_gate, prior_fallback, fit_test, fit_neutral, first_posterior, reopen_cloud,
     reopen_reset) = gates
    sig_pos = model.sig_pos
    converged_std = model.converged_std
    m = x.shape[1]
    steps = ranges.shape[0]
    block = min(BLOCK, m)
    logw = np.zeros(m)
    ll = np.empty(m)
    w = np.empty(m)
    wp = np.full(m, 1.0 / m)
    uni = np.empty(m)
    idx = np.empty(m, dtype=np.int64)
    scratch = np.empty_like(x)
    xp = np.empty_like(x)
    mean = np.empty(N_TIGHT)
    v = np.empty(N_TIGHT)
    cov = np.empty((2, 2))
    mean_p = np.empty(N_TIGHT)
    v_p = np.empty(N_TIGHT)
    r = np.empty((2, 2))
    r_upd = np.empty((2, 2))  # the fix's covariance in a KF update (``kf.r_scale`` times r)
    dx = np.empty(N_ERROR)
    p_save = np.empty((N_ERROR, N_ERROR))
    m_prior = np.empty(2)
    p_prior = np.empty((2, 2))
    zt = np.empty(2)
    nav = np.zeros((N_TIGHT, 1))  # the corrected navigation, as one tight particle
    dist_buf = np.zeros(2 * block)  # unused (no distance innovation), shaped as the tight loop's
    no_distance = steps < 0  # False, but a run-time bool as in the tight loop's call: one compile of the pass
    one = OneParticle(np.zeros((N_TIGHT, 1)), np.empty((1, 3)), new_likelihood_work(np.int64(1), 4 * grid.grids),
                      np.zeros((2, 1)), np.empty(1))
    noise_buf = np.empty(3 * block)
    work = new_likelihood_work(block, 4 * grid.grids)
    consts = beam_constants(model.sig_u, 1.0, model.outside_sigma)
    nav[E, 0] = out_en[0, 0]
    nav[N, 0] = out_en[0, 1]
    nav[YAW, 0] = nav_yaw[0]
    for c in range(BZ + 1):
        if c != E and c != N:
            for j in range(m):
                x[c, j] = 0.0
    _draw_headings(x, rng, nav[YAW, 0], math.sqrt(p_kf[EPSI, EPSI]))
    _restart_prior(xp, wp, x, wp)
    bad = 0
    good = 0
    since_fix = 0
    rejections = 0
    first_fix = True
    p0_pos = p_kf[EE, EE]
    p0_yaw = p_kf[EPSI, EPSI]
    locked = False
    consistent_chi = (0.5 * div.sigma) ** 2
    for k in range(steps):
        if k > 0:
            yaw_before = nav[YAW, 0]
            d_e, d_n, b_e, b_n = navigation_step(nav, inc[k - 1], nav_yaw[k - 1], nav_up[k - 1])
            dyaw = nav[YAW, 0] - yaw_before
            q_delta = math.sqrt(kf.q_yaw * kf.q_yaw + p_kf[EB, EB] * dt * dt)
            eskf_predict(p_kf, d_e, d_n, b_e, b_n, inc[k - 1, SZ], kf.q_pos, kf.q_yaw, kf.q_bias)
            _move_cloud(x, rng, d_e, d_n, yaw_before, dyaw, sig_pos, q_delta, noise_buf, block)
            _move_cloud(xp, rng, d_e, d_n, yaw_before, dyaw, sig_pos, q_delta, noise_buf, block)
        _level(x, nav_up[k], nav_pitch[k], nav_roll[k])
        vec = beam_vectors(beams, ranges[k])
        att = attitude_reference(nav_pitch[k], nav_roll[k], nav[YAW, 0])
        best = np.inf
        for lo in range(0, m, block):
            n = min(block, m - lo)
            dist = dist_buf[:2 * n].reshape((2, n))
            best = min(best, loglik_tight_pass(x, lo, vec, grid, lik, consts, att, dist, no_distance,
                                               work_block(work, n), ll[lo:lo + n]))
        mx = add_log_weights(logw, ll)
        ess = normalise_with_ess(logw, mx, w)
        weighted_estimate(x[:2], w, -1, 0.0, mean, v, cov)
        spread = math.sqrt(v[0] + v[1])
        healthy = spread < converged_std and best < consistent_chi
        ready = healthy if fit_test else spread < converged_std
        # with fit_neutral, an update that fails the fit for want of bottom lock or by one wild beam leaves the count
        count_stays = (fit_neutral and fit_test and spread < converged_std and not healthy
                       and (best == np.inf or fit_without_worst_beam(x, ll, vec, grid, lik, consts, att, no_distance,
                                                                     one) < consistent_chi))
        if not count_stays:
            good = good + 1 if ready else 0
        locked = locked or healthy
        since_fix += 1
        fixed_out[k] = 0
        rejected_out[k] = 0
        if good >= div.steps and since_fix >= kf.fix_every:
            since_fix = 0
            shape_ok = shape_min <= 0.0 or unimodal_fraction(x, w, mean, cov) >= shape_min
            # the window's prior: the never-weighted cloud's weighted mean and covariance
            total = 0.0
            for j in range(m):
                total += wp[j]
            for j in range(m):
                wp[j] /= total
            weighted_estimate(xp[:2], wp, -1, 0.0, mean_p, v_p, p_prior)
            m_prior[0] = mean_p[0]
            m_prior[1] = mean_p[1]
            usable = shape_ok and terrain_only_fix(mean, cov, m_prior, p_prior, kf.fix_max_std, zt, r)
            if usable and prior_gate < np.inf and not fix_prior_chi2(zt, r, m_prior, p_prior) < prior_gate:
                if prior_fallback:  # the cloud's own estimate, no surer than it was before the window
                    zt[0] = mean[0]
                    zt[1] = mean[1]
                    copy_matrix(r, p_prior)
                else:
                    usable = False  # the fix disagrees with the cloud it came from: refused, not a KF miss
                    rejected_out[k] = 1
            if usable:
                if first_fix and first_posterior:  # a reset replaces the KF's prior, which the cloud started from
                    zt[0] = mean[0]
                    zt[1] = mean[1]
                    copy_matrix(r, cov)
                r[0, 0] += kf.r_floor * kf.r_floor
                r[1, 1] += kf.r_floor * kf.r_floor
                if first_fix:
                    position_reset(p_kf, r, nav, zt)
                    first_fix = False
                    fixed_out[k] = 1
                else:
                    copy_matrix(p_save, p_kf)
                    for i in range(2):  # a reset (first fix, reopened position) takes the fix's own r
                        for j in range(2):
                            r_upd[i, j] = r[i, j] * kf.r_scale
                    chi2 = eskf_update(p_kf, zt[0] - nav[E, 0], zt[1] - nav[N, 0], r_upd, kf.gate, dx)
                    reset = False
                    if not chi2 < kf.gate:
                        rejections += 1
                        if rejections >= kf.misses:
                            reopen_kf(p_kf, p0_pos, p0_yaw)
                            if reopen_cloud:  # the particles' yaws are absolute: the cloud's own heading
                                nav[YAW, 0] += cloud_heading_offset(x[YAW], w, nav[YAW, 0])
                            copy_matrix(p_save, p_kf)
                            chi2 = eskf_update(p_kf, zt[0] - nav[E, 0], zt[1] - nav[N, 0], r_upd, kf.gate, dx)
                            # reopened and still refusing the converged cloud's fix: the KF's position is the lost
                            # part (its initial variance cannot reach the fix), so the fix sets it, as a first fix does
                            reset = reopen_reset and not chi2 < kf.gate
                    if chi2 < kf.gate and abs(nav[BZ, 0] + dx[EB]) > bias_limit:
                        copy_matrix(p_kf, p_save)  # the fix would make the gyro bias implausible
                        chi2 = np.inf
                    if reset:
                        position_reset(p_kf, r, nav, zt)
                        rejections = 0
                        fixed_out[k] = 1
                    elif chi2 < kf.gate:
                        rejections = 0
                        nav[E, 0] += dx[EE]
                        nav[N, 0] += dx[EN]
                        nav[YAW, 0] += dx[EPSI]  # the particles' absolute yaws stay: every delta -= dx_psi
                        nav[BZ, 0] += dx[EB]
                        fixed_out[k] = 1
                    else:
                        rejected_out[k] = 1
            _restart_prior(xp, wp, x, w)
        off_map = keep_on_map(nav[:2, 0], guard.bounds)
        record_kalman_update(out, k, nav, p_kf, ess, healthy)
        if best < np.inf:
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        if bad >= div.steps or off_map:
            uniform_horizontal(x, rng, nav[E, 0], nav[N, 0], half_side)
            _draw_headings(x, rng, nav[YAW, 0], math.sqrt(p_kf[EPSI, EPSI]))
            for j in range(m):
                w[j] = 1.0 / m
            _restart_prior(xp, wp, x, w)
            logw[:] = 0.0
            bad = 0
            good = 0
            locked = False
            first_fix = True
            reinit_out[k] = 1
            continue
        resample_and_regularise(x, w, logw, ess, rng, rs, 3, spread, uni, idx, scratch)
