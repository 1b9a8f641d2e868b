"""Loosely coupled TAN (Melo & Matos Section 5, after Hagen et al. 2011): two loops.

* :func:`loose_kalman_loop` (``filter.loose_architecture: kalman-feedback``, recommended):
  a position-only particle filter whose terrain-only fixes go to an error-state Kalman
  filter of the navigation system (``navigation/eskf.py``: position, heading, z-gyro
  bias); the corrected navigation drives the PF (closed loop). docs/model.md, Section 6.2.
* :func:`loose_filter_loop` (``fix-only``, the earlier baseline): the PF is driven by the
  navigation system's position increments with Table 2's process noise plus the
  cross-track error the 30 deg heading prior causes on each increment; while it has
  converged (horizontal std below ``converged_std`` and its best particle fitting the
  terrain within half the divergence threshold, for ``div_steps`` updates in a row), its
  estimate is fed back to the navigation system as a position fix; the output is the
  navigation system corrected by the latest fix. Its heading is never corrected.

Beams are projected with the navigation system's attitude (turned by the corrected
heading in the closed loop). Divergence, resampling and regularisation as in the tight
filter.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters.cloud import gaussian_horizontal, uniform_horizontal
from tanbench.filters.estimate import weighted_estimate
from tanbench.filters.likelihood import (BLOCK, Likelihood, beam_constants, loglik_loose_pass, new_likelihood_work, used_offsets,
                                        work_block)
from tanbench.filters.propagate import dead_reckon, dead_reckon_numpy, propagate_loose
from tanbench.filters.resample import add_log_weights, normalise_with_ess, resample_and_regularise
from tanbench.filters.rng import fill_normals
from tanbench.filters.state import BZ, E, N, N_TIGHT, U, YAW
from tanbench.filters.tight import keep_on_map
from tanbench.navigation.eskf import EB, EE, EN, EPSI, N_ERROR, eskf_predict, eskf_update, terrain_only_fix
from tanbench.navigation.increments import JAZE, JAZN, SZ

# position process noise, heading-induced cross-track noise, altitude std, off-map innovation,
# and the horizontal std below which the filter's estimate is a position fix
LooseModel = namedtuple("LooseModel", "sig_pos sig_heading sig_u outside_sigma converged_std")

# the closed-loop loose TAN's navigation KF (navigation/eskf.py): process noise std per update
# (position, heading, z-gyro bias), a fix every ``fix_every`` updates, chi-square gate, std added
# to a fix, the weakest terrain-only fix used, the gate rejections in a row after which the
# KF is reopened, and the factor on a fix's covariance in a KF update (``fix_covariance_scale``; the
# loop with heading offsets reads it)
LooseKalman = namedtuple("LooseKalman", "q_pos q_yaw q_bias fix_every gate r_floor fix_max_std misses r_scale",
                         defaults=(1.0,))


def fix_covariance_scale(interval_s: float, correlation_s: float) -> float:
    """The factor on a fix's covariance when fixes ``interval_s`` apart have errors correlated as a first-order
    Gauss-Markov process of time constant ``correlation_s``: (1 + r) / (1 - r), r = exp(-interval / correlation),
    so that a KF counting them as independent gains, per fix, the information the mean of such a sequence of
    fixes holds (its variance, for many fixes, is the fixes' variance times this factor over their number);
    1 for independent fixes (``correlation_s`` 0)."""
    if correlation_s <= 0.0:
        return 1.0
    r = math.exp(-interval_s / correlation_s)
    return (1.0 + r) / (1.0 - r)

# the fix-only loop: the navigation at the K updates (displacements (K-1, 2), position (K, 2),
# up (K,)), its settings (``half_side``: the initial square's) and what it fills: the
# fix-corrected position (K, 2), the cloud's east/north variances (K, 2) and covariance,
# ESS, reinitialisations and fixes (K,)
FixOnlyTrack = namedtuple("FixOnlyTrack", "d0 en up")
FixOnlySettings = namedtuple("FixOnlySettings", "model rs div half_side readings")
FixOnlyOutputs = namedtuple("FixOnlyOutputs", "en var cov_en ess reinit fixed")

# the closed loop: the navigation at the updates (increments (K-1, 12), yaw, up (K,)), its
# settings and what it fills (position (K, 2), yaw, z-gyro bias, variances (K, 2), yaw
# variance, ESS, reinitialisations, accepted and rejected fixes, health (K,))
KalmanTrack = namedtuple("KalmanTrack", "inc yaw up")
KalmanSettings = namedtuple("KalmanSettings", "model rs div half_side lik guard kf")
KalmanOutputs = namedtuple("KalmanOutputs", "en yaw bias var var_yaw ess reinit fixed rejected healthy")

LOOSE_COLS = np.array([0, 1], dtype=np.int64)  # the states (rows) the regularisation jitters

# one loose update's motion (propagate_loose): the displacement (d_e, d_n) the particles move
# by, the position noise std and the heading std (rad) behind the cross-track noise
LooseMotion = namedtuple("LooseMotion", "d_e d_n sig_pos sig_heading")

# the buffers of the loose particle passes: the noise rows (at least 3 * block), the
# likelihood's work arrays (likelihood.new_likelihood_work; their size is the block) and the
# particles' log-likelihoods (M,), which the passes fill
LooseBuffers = namedtuple("LooseBuffers", "noise work ll")


@nb.njit(cache=True)
def propagate_and_weigh_loose(x, rng, propagate, motion, offsets, up, grid, lik, consts, bufs):
    """One loose update's particle passes, block by block (the size of ``bufs.work``): draw the
    three noise rows (east, north, cross-track), move the particles by ``motion`` (a
    :class:`LooseMotion`) if ``propagate`` (:func:`~tanbench.filters.propagate.propagate_loose`)
    and weigh them into ``bufs.ll`` (:func:`~tanbench.filters.likelihood.loglik_loose_pass`,
    ``consts`` its :class:`~tanbench.filters.likelihood.BeamConstants`). Returns the best chi^2
    per beam."""
    d_e, d_n, sig_pos, sig_heading = motion
    noise_buf, work, ll = bufs
    rows = used_offsets(offsets)
    m = x.shape[1]
    block = work.norm.shape[0]
    best = np.inf
    for lo in range(0, m, block):
        n = min(block, m - lo)
        if propagate:
            noise = noise_buf[:3 * n].reshape((3, n))
            fill_normals(rng, noise)
            propagate_loose(x, d_e, d_n, noise, sig_pos, sig_heading, lo)
        best = min(best, loglik_loose_pass(x, lo, rows, up, grid, lik, consts, work_block(work, n), ll[lo:lo + n]))
    return best


@nb.njit(cache=True)
def loose_filter_loop(x, rng, track, offsets, grid, settings, out):
    """Run the loose filter along ``track`` (:class:`FixOnlyTrack`); fill ``out``
    (:class:`FixOnlyOutputs`), whose ``en`` is the fix-corrected navigation position.

    ``x`` (2, M) is the initial cloud, a column per particle; ``grid`` the navigation map's
    :class:`~tanbench.terrain.grid.NodeGrid`; ``settings`` the :class:`FixOnlySettings`
    (LooseModel above, Resampling, Divergence, Readings of :mod:`tanbench.filters.tight`;
    of the readings the loose filter uses ``cloud_std``, ``div_reinit`` and ``collapse_spread``).
    """
    d0, nav_en, nav_up = track
    model, rs, div, half_side, readings = settings
    out_en, var, cov_en_out, ess_out, reinit_out, fixed_out = out
    m = x.shape[1]
    steps = offsets.shape[0]
    logw = np.zeros(m)
    ll = np.empty(m)
    w = np.empty(m)
    uni = np.empty(m)
    idx = np.empty(m, dtype=np.int64)
    scratch = np.empty_like(x)
    mean = np.empty(2)
    v = np.empty(2)
    cov = np.empty((2, 2))
    fix_e = 0.0
    fix_n = 0.0
    bad = 0
    good = 0
    consistent_chi = (0.5 * div.sigma) ** 2
    plain = Likelihood(False, 0, 4.0)  # the fix-only loop weighs with the plain Gaussian
    bufs = LooseBuffers(np.empty(3 * min(BLOCK, m)), new_likelihood_work(min(BLOCK, m), 4 * grid.grids), ll)
    consts = beam_constants(model.sig_u, 1.0, model.outside_sigma)
    for k in range(steps):
        d_e = d0[k - 1, 0] if k > 0 else 0.0
        d_n = d0[k - 1, 1] if k > 0 else 0.0
        best = propagate_and_weigh_loose(x, rng, k > 0, LooseMotion(d_e, d_n, model.sig_pos, model.sig_heading),
                                         offsets[k], nav_up[k], grid, plain, consts, bufs)
        mx = add_log_weights(logw, ll)
        ess = normalise_with_ess(logw, mx, w)
        weighted_estimate(x, w, -1, 0.0, mean, v, cov)
        good = good + 1 if (math.sqrt(v[0] + v[1]) < model.converged_std and best < consistent_chi) else 0
        converged = good >= div.steps
        if converged:
            fix_e = mean[0] - nav_en[k, 0]
            fix_n = mean[1] - nav_en[k, 1]
        out_en[k, 0] = nav_en[k, 0] + fix_e
        out_en[k, 1] = nav_en[k, 1] + fix_n
        var[k, 0] = v[0]
        var[k, 1] = v[1]
        cov_en_out[k] = cov[0, 1]
        ess_out[k] = ess
        fixed_out[k] = 1 if converged else 0
        reinit_out[k] = 0
        if best < np.inf:  # an update without any bottom lock says nothing about divergence
            bad = bad + 1 if best > div.sigma * div.sigma else 0
        spread = math.sqrt(v[0] + v[1])
        diverged = readings.div_reinit and bad >= div.steps
        collapsed = ess < rs.ess_threshold * m and spread < readings.collapse_spread
        if diverged or collapsed:
            centre_e = out_en[k, 0] if diverged else mean[0]
            centre_n = out_en[k, 1] if diverged else mean[1]
            uniform_horizontal(x, rng, centre_e, centre_n, half_side)
            if readings.cloud_std > 0.0:
                gaussian_horizontal(x, rng, centre_e, centre_n, readings.cloud_std)
            logw[:] = 0.0
            bad = 0
            reinit_out[k] = 1
            continue
        resample_and_regularise(x, w, logw, ess, rng, rs, 2, math.sqrt(v[0] + v[1]), uni, idx, scratch)


@nb.njit(cache=True)
def position_reset(p_kf, r, nav, zt):
    """The first fix after a (re)initialisation sets the position: the navigation's east and north
    (``nav[E, 0]``, ``nav[N, 0]``) become the fix ``zt``, P_pp = R, the position's correlations with
    heading and bias dropped (a single fix cannot tell an initial position error from a heading
    error; heading is learnt from the fixes that follow)."""
    nav[E, 0] = zt[0]
    nav[N, 0] = zt[1]
    for i in range(N_ERROR):
        p_kf[EE, i] = p_kf[i, EE] = 0.0
        p_kf[EN, i] = p_kf[i, EN] = 0.0
    p_kf[EE, EE] = r[0, 0]
    p_kf[EE, EN] = r[0, 1]
    p_kf[EN, EE] = r[1, 0]
    p_kf[EN, EN] = r[1, 1]


def position_reset_numpy(p_kf, r, nav, zt):
    """Plain-numpy reference of :func:`position_reset`: returns (new covariance, new navigation); the
    position's rows and columns of ``p_kf`` zero but for their 2x2 block, which is ``r``."""
    p = np.array(p_kf, dtype=np.float64)
    pos = [EE, EN]
    p[pos, :] = 0.0
    p[:, pos] = 0.0
    p[np.ix_(pos, pos)] = r
    nav = np.array(nav, dtype=np.float64)
    nav[[E, N], 0] = zt[:2]
    return p, nav


@nb.njit(cache=True)
def reopen_kf(p_kf, p0_pos, p0_yaw):
    """Recovery of a locked-out navigation KF (``kf.misses`` fixes rejected in a row: the
    healthy terrain PF and the KF disagree persistently, so the KF is the overconfident
    one): position variances back to the initial ones, heading variance to a quarter of
    the initial (half its std; a larger one shrinks to it), their correlations dropped; the bias
    keeps its own."""
    for i in range(N_ERROR):
        if i != EB:
            for j in range(N_ERROR):
                p_kf[i, j] = 0.0
                p_kf[j, i] = 0.0
    p_kf[EE, EE] = p0_pos
    p_kf[EN, EN] = p0_pos
    p_kf[EPSI, EPSI] = 0.25 * p0_yaw


def reopen_kf_numpy(p_kf, p0_pos, p0_yaw):
    """Plain-numpy reference of :func:`reopen_kf` (returns a new covariance): the bias's own variance kept,
    everything else replaced by diag(p0_pos, p0_pos, p0_yaw / 4) on the position and heading."""
    p = np.zeros((N_ERROR, N_ERROR))
    p[EE, EE] = p[EN, EN] = p0_pos
    p[EPSI, EPSI] = 0.25 * p0_yaw
    p[EB, EB] = p_kf[EB, EB]
    return p


@nb.njit(cache=True)
def _open_window(m_prior, p_prior, centre_e, centre_n, half_side):
    """The prior of a (re)initialised cloud: the uniform square's mean and covariance."""
    m_prior[0] = centre_e
    m_prior[1] = centre_n
    p_prior[0, 0] = p_prior[1, 1] = half_side * half_side / 3.0
    p_prior[0, 1] = p_prior[1, 0] = 0.0


# --------------------------------------------------------------------------------------
# Closed-loop loose TAN ("kalman-feedback", the recommended architecture)
# --------------------------------------------------------------------------------------

@nb.njit(cache=True)
def record_kalman_update(out, k, nav, p_kf, ess, healthy):
    """Write update ``k`` of a Kalman-feedback loop into its :class:`KalmanOutputs` ``out``: the corrected
    navigation (east, north, yaw, z-gyro bias), the KF's variances, the ESS and the health flag; no
    re-initialisation (the loop sets ``reinit`` to 1 itself when it re-initialises)."""
    out_en, out_yaw, out_bias, var, var_yaw, ess_out, reinit_out, _, _, healthy_out = out
    out_en[k, 0] = nav[E, 0]
    out_en[k, 1] = nav[N, 0]
    out_yaw[k] = nav[YAW, 0]
    out_bias[k] = nav[BZ, 0]
    var[k, 0] = p_kf[EE, EE]
    var[k, 1] = p_kf[EN, EN]
    var_yaw[k] = p_kf[EPSI, EPSI]
    ess_out[k] = ess
    healthy_out[k] = 1 if healthy else 0
    reinit_out[k] = 0

@nb.njit(cache=True, inline="always")
def navigation_step(nav, inc_row, yaw_nav, up_nav):
    """The corrected navigation ``nav`` (8, 1) dead-reckoned over one increments row ``inc_row`` from
    the navigation solution's heading ``yaw_nav`` and up ``up_nav`` at the interval's start
    (:func:`~tanbench.filters.propagate.dead_reckon`); returns its east and north displacement and the
    z-gyro bias's lever on them in the navigation frame (``b_e``, ``b_n``), which the error-state KF's
    prediction (:func:`~tanbench.navigation.eskf.eskf_predict`) takes: (d_e, d_n, b_e, b_n). The loose
    loops' one step of the navigation system."""
    e_before = nav[E, 0]
    n_before = nav[N, 0]
    s, c = math.sin(nav[YAW, 0] - yaw_nav), math.cos(nav[YAW, 0] - yaw_nav)
    b_e = -(c * inc_row[JAZE] - s * inc_row[JAZN])
    b_n = -(s * inc_row[JAZE] + c * inc_row[JAZN])
    nav[U, 0] = up_nav
    dead_reckon(nav, inc_row, yaw_nav)
    return nav[E, 0] - e_before, nav[N, 0] - n_before, b_e, b_n


def navigation_step_numpy(nav, inc_row, yaw_nav, up_nav):
    """Plain-numpy reference of :func:`navigation_step`: (new navigation, d_e, d_n, b_e, b_n), the lever
    (b_e, b_n) = -Rz(yaw - yaw_nav) [JAZE, JAZN] at the interval's start, the dead reckoning
    :func:`~tanbench.filters.propagate.dead_reckon_numpy` from up ``up_nav``."""
    nav = np.array(nav, dtype=np.float64)
    with np.errstate(invalid="ignore"):  # an infinite heading offset: NaN, as the kernel's
        turn = nav[YAW, 0] - yaw_nav
        rz = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    b_e, b_n = -(rz @ np.array([inc_row[JAZE], inc_row[JAZN]]))
    start = nav[[E, N], 0].copy()
    nav[U, 0] = up_nav
    nav = dead_reckon_numpy(nav, inc_row, yaw_nav)
    d_e, d_n = nav[[E, N], 0] - start
    return nav, float(d_e), float(d_n), float(b_e), float(b_n)


@nb.njit(cache=True, inline="always")
def advance_window_prior(m_prior, p_prior, d_e, d_n, sig_pos, sig_heading):
    """The prior of the Kalman-feedback loop's fix window over one interval, in place: the mean ``m_prior``
    (2,) moves by the corrected navigation's displacement (d_e, d_n), the covariance ``p_prior`` (2, 2)
    grows by the particles' process noise: ``sig_pos``^2 on each axis and the cross-track variance
    ``sig_heading``^2 (-d_n, d_e)(-d_n, d_e)^T of the heading std ``sig_heading`` (rad)."""
    m_prior[0] += d_e
    m_prior[1] += d_n
    sh2 = sig_heading * sig_heading
    p_prior[0, 0] += sig_pos * sig_pos + sh2 * d_n * d_n
    p_prior[1, 1] += sig_pos * sig_pos + sh2 * d_e * d_e
    p_prior[0, 1] -= sh2 * d_e * d_n
    p_prior[1, 0] -= sh2 * d_e * d_n


def advance_window_prior_numpy(m_prior, p_prior, d_e, d_n, sig_pos, sig_heading):
    """Plain-numpy reference of :func:`advance_window_prior`: returns the new (mean, covariance)."""
    across = np.array([-d_n, d_e])  # the displacement turned by 90 deg: where a heading error moves it
    noise = sig_pos ** 2 * np.eye(2) + sig_heading ** 2 * np.outer(across, across)
    return np.asarray(m_prior, dtype=np.float64) + np.array([d_e, d_n]), np.asarray(p_prior, dtype=np.float64) + noise


@nb.njit(cache=True)
def loose_kalman_loop(x, rng, track, offsets, grid, settings, p_kf, out):
    """Position PF -> fixes -> error-state KF of the navigation system -> corrected navigation,
    which drives the PF (docs/model.md, Section 6.2).

    The corrected navigation (position, yaw, z-gyro bias) is dead-reckoned from the
    navigation increments ``inc`` like one zero-noise tight particle; the PF particles move
    by its displacement with a cross-track noise from the KF's heading std; the beams
    (``offsets``, projected with the navigation attitude) are turned by the corrected
    heading. Every ``fix_every`` updates, if the PF has converged (as in
    :func:`loose_filter_loop`), its mean and covariance (plus ``r_floor``^2) are a fix for
    the KF (:func:`~tanbench.navigation.eskf.eskf_update`, chi-square gate ``gate``); an
    accepted fix is injected into the corrected navigation. ``p_kf`` (4, 4) is the KF's
    initial covariance, updated in place; ``out_en[0]`` holds the start position.

    ``x`` (2, M) is the initial cloud; ``grid`` the navigation map's
    :class:`~tanbench.terrain.grid.NodeGrid`; ``track`` the :class:`KalmanTrack`; ``settings``
    the :class:`KalmanSettings` (LooseModel, LooseKalman above; Resampling, Divergence,
    Likelihood, Guard); ``model.sig_heading`` is not used (the KF's heading std replaces
    it); ``out`` the :class:`KalmanOutputs` it fills.
    """
    inc, nav_yaw, nav_up = track
    model, rs, div, half_side, lik, guard, kf = settings
    out_en, out_yaw, out_bias, var, var_yaw, ess_out, reinit_out, fixed_out, rejected_out, healthy_out = out
    sig_pos = model.sig_pos
    converged_std = model.converged_std
    m = x.shape[1]
    steps = offsets.shape[0]
    nb_beams = offsets.shape[1]
    logw = np.zeros(m)
    ll = np.empty(m)
    w = np.empty(m)
    uni = np.empty(m)
    idx = np.empty(m, dtype=np.int64)
    scratch = np.empty_like(x)
    mean = np.empty(2)
    v = np.empty(2)
    cov = np.empty((2, 2))
    r = np.empty((2, 2))
    dx = np.empty(N_ERROR)
    rot = np.empty((nb_beams, 3))
    m_prior = np.empty(2)  # the PF's prior over the window since the last fix
    p_prior = np.empty((2, 2))
    zt = np.empty(2)
    _open_window(m_prior, p_prior, out_en[0, 0], out_en[0, 1], half_side)
    nav = np.zeros((N_TIGHT, 1))  # the corrected navigation, as one tight particle
    bufs = LooseBuffers(np.empty(3 * min(BLOCK, m)), new_likelihood_work(min(BLOCK, m), 4 * grid.grids), ll)
    consts = beam_constants(model.sig_u, 1.0, model.outside_sigma)
    nav[E, 0] = out_en[0, 0]
    nav[N, 0] = out_en[0, 1]
    nav[YAW, 0] = nav_yaw[0]
    bad = 0
    good = 0
    since_fix = 0
    rejections = 0  # fixes rejected by the gate in a row
    first_fix = True  # the next fix resets the position (after the start or a PF reinitialisation)
    p0_pos = p_kf[EE, EE]
    p0_yaw = p_kf[EPSI, EPSI]
    locked = False  # the cloud has converged since the last (re)initialisation
    consistent_chi = (0.5 * div.sigma) ** 2
    d_e = 0.0  # the corrected navigation's displacement over the interval ending at update k
    d_n = 0.0
    sig_heading = 0.0
    for k in range(steps):
        if k > 0:
            d_e, d_n, b_e, b_n = navigation_step(nav, inc[k - 1], nav_yaw[k - 1], nav_up[k - 1])
            sig_heading = math.sqrt(p_kf[EPSI, EPSI])
            eskf_predict(p_kf, d_e, d_n, b_e, b_n, inc[k - 1, SZ], kf.q_pos, kf.q_yaw, kf.q_bias)
            # the window's prior: the same motion and process noise as the particles
            advance_window_prior(m_prior, p_prior, d_e, d_n, sig_pos, sig_heading)
        # beams turned by the corrected heading's offset from the navigation heading
        s, c = math.sin(nav[YAW, 0] - nav_yaw[k]), math.cos(nav[YAW, 0] - nav_yaw[k])
        for i in range(nb_beams):
            rot[i, 0] = c * offsets[k, i, 0] - s * offsets[k, i, 1]
            rot[i, 1] = s * offsets[k, i, 0] + c * offsets[k, i, 1]
            rot[i, 2] = offsets[k, i, 2]
        # the particles move (k > 0) and are weighed
        best = propagate_and_weigh_loose(x, rng, k > 0, LooseMotion(d_e, d_n, sig_pos, sig_heading), rot, nav_up[k],
                                         grid, lik, consts, bufs)
        mx = add_log_weights(logw, ll)
        ess = normalise_with_ess(logw, mx, w)
        weighted_estimate(x, w, -1, 0.0, mean, v, cov)
        spread = math.sqrt(v[0] + v[1])
        healthy = spread < converged_std and best < consistent_chi
        good = good + 1 if healthy else 0
        locked = locked or healthy
        since_fix += 1
        fixed_out[k] = 0
        rejected_out[k] = 0
        if good >= div.steps and since_fix >= kf.fix_every:
            since_fix = 0
            if terrain_only_fix(mean, cov, m_prior, p_prior, kf.fix_max_std, zt, r):
                r[0, 0] += kf.r_floor * kf.r_floor
                r[1, 1] += kf.r_floor * kf.r_floor
                if first_fix:  # position reset: one fix cannot tell an initial position error from heading
                    position_reset(p_kf, r, nav, zt)
                    first_fix = False
                    fixed_out[k] = 1
                else:
                    chi2 = eskf_update(p_kf, zt[0] - nav[E, 0], zt[1] - nav[N, 0], r, kf.gate, dx)
                    if not chi2 < kf.gate:
                        rejections += 1
                        if rejections >= kf.misses:  # the KF is locked out: reopen it and take the fix
                            reopen_kf(p_kf, p0_pos, p0_yaw)
                            chi2 = eskf_update(p_kf, zt[0] - nav[E, 0], zt[1] - nav[N, 0], r, kf.gate, dx)
                    if chi2 < kf.gate:
                        rejections = 0
                        nav[E, 0] += dx[EE]
                        nav[N, 0] += dx[EN]
                        nav[YAW, 0] += dx[EPSI]
                        nav[BZ, 0] += dx[EB]
                        fixed_out[k] = 1
                    else:
                        rejected_out[k] = 1
            m_prior[0] = mean[0]
            m_prior[1] = mean[1]
            for a in range(2):
                for b in range(2):
                    p_prior[a, b] = cov[a, b]
        off_map = keep_on_map(nav[:2, 0], guard.bounds)
        record_kalman_update(out, k, nav, p_kf, ess, healthy)
        if best < np.inf:  # an update without any bottom lock says nothing about divergence
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        if bad >= div.steps or off_map:
            uniform_horizontal(x, rng, nav[E, 0], nav[N, 0], half_side)
            logw[:] = 0.0
            bad = 0
            good = 0
            locked = False
            first_fix = True
            _open_window(m_prior, p_prior, nav[E, 0], nav[N, 0], half_side)
            reinit_out[k] = 1
            continue
        resample_and_regularise(x, w, logw, ess, rng, rs, 2, spread, uni, idx, scratch)
