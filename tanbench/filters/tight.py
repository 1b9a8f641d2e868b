"""Tightly coupled TAN (Section 3, Algorithm 1): the 8-state particle filter loop.

The loop is jitted end to end and composed of the kernels in ``propagate``,
``likelihood``, ``resample`` and ``estimate``; particles are the columns of ``x`` (8, M),
each kernel a pass over them that compiles to SIMD instructions; random numbers come in
blocks from the generator ``filters/rng.py`` gives the loop. Per update k:

1. propagate every particle over the interval (Eq. 1; skipped at k = 0);
2. weight by the terrain altitude innovations of the beams and the distance
   innovations (Eq. 20), accumulating log-weights;
3. record the MMSE estimate and the weighted variances;
4. if the best particle's mean squared normalised innovation stays above
   ``div_sigma^2`` for ``div_steps`` updates, the filter has diverged: reinitialise the
   cloud with the initial spread, positions around the estimate and headings around
   the navigation heading (a diverged filter's own heading is not trusted; the
   paper's Section 3.3);
5. resample when ESS < ``ess_thr * M``, then regularise: jitter position, heading and the
   gyro biases with a mean- and variance-preserving kernel (``resample.regularise``), so
   duplicated particles spread out again; if the horizontal cloud has nevertheless
   collapsed below ``min_spread`` metres, re-spread it (the paper's reinitialisation of a
   too-small cloud).

The paper-as-written readings (``readings``, a :class:`tanbench.filters.params.Readings`;
docs/model.md section 10): a non-zero ``propagation`` moves the particles with one Euler
step of Eq. 1 over ``dt`` on ``euler_in`` instead of the exact increments; ``cloud_std``
> 0 draws (and redraws) the horizontal cloud as a Gaussian of that std instead of the
uniform square; ``div_reinit`` False never reinitialises a diverged filter;
``collapse_spread`` > 0 redraws a resampled cloud whose horizontal std is below it with
the initial spread around the estimate (the whole state, as a divergence does).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.cloud import gaussian_horizontal, uniform_horizontal
from tanbench.filters.estimate import weighted_estimate
from tanbench.filters.likelihood import (BLOCK, beam_constants, beam_vectors, loglik_tight_pass, new_likelihood_work,
                                        work_block)
from tanbench.filters.bias_walk import walk_biases
from tanbench.filters.posterior import REG_POSTERIOR, resample_posterior
from tanbench.filters.propagate import DIST_NAVIGATION, propagate_tight, propagate_tight_euler
from tanbench.filters.recovery import recovery_square
from tanbench.filters.resample import add_log_weights, normalise_with_ess, resample_and_regularise
from tanbench.filters.rng import fill_normals
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.trig import attitude_reference
from tanbench.navigation.increments import D0E, D0N

REGULARISED_STATES = {
    "position-heading-biases": np.array([E, N, YAW, BX, BZ], dtype=np.int64),
    "heading-biases": np.array([YAW, BX, BZ], dtype=np.int64),
    "biases": np.array([BX, BZ], dtype=np.int64),
}


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _shift_scale(row, centre, std):
    for j in range(row.shape[0]):
        row[j] = centre + std * row[j]


@nb.njit(cache=True)
def init_tight(x, rng, centre_e, centre_n, up, pitch, roll, yaw, prior):
    """Initial cloud (``x`` (8, M)): uniform square of side 2 * prior.half_side around
    (centre_e, centre_n), Gaussians else (``prior`` is a :class:`tanbench.filters.params.TightPrior`)."""
    init_tight_square(x, rng, centre_e, centre_n, prior.half_side, up, pitch, roll, yaw, prior)


@nb.njit(cache=True)
def init_tight_square(x, rng, centre_e, centre_n, half_side, up, pitch, roll, yaw, prior):
    """:func:`init_tight` over a square of half side ``half_side`` instead of ``prior.half_side``."""
    uniform_horizontal(x, rng, centre_e, centre_n, half_side)
    fill_normals(rng, x[U:])
    _shift_scale(x[U], up, prior.std_up)
    _shift_scale(x[PITCH], pitch, prior.std_att)
    _shift_scale(x[ROLL], roll, prior.std_att)
    _shift_scale(x[YAW], yaw, prior.std_yaw)
    _shift_scale(x[BX], 0.0, prior.std_bias)
    _shift_scale(x[BZ], 0.0, prior.std_bias)


@nb.njit(cache=True)
def tight_filter_loop(x, rng, inc, nav_yaw, nav_pitch, nav_roll, nav_up, ranges, beams, grid, model, rs, div,
                      prior, readings, euler_in, lik, guard, est, var, cov_en_out, ess_out, reinit_out,
                      healthy_out):
    """Run the filter over all updates; fill est/var (K+1, 8), cov_en_out, ess_out, reinit_out and
    healthy_out (K+1,).

    ``x`` (8, M) is the initial cloud, a column per particle. ``cov_en_out`` is the cloud's
    weighted east/north covariance (``var`` holds the variances). ``grid`` is the navigation
    map's :class:`~tanbench.terrain.grid.NodeGrid` (with the variance grid interleaved for
    the map-aware likelihood); ``model``, ``rs``, ``div``, ``prior``, ``readings``, ``lik`` and
    ``guard`` are the bundles of :mod:`tanbench.filters.params` (TightModel, Resampling,
    Divergence, TightPrior, Readings, Likelihood, Guard); ``euler_in`` (K, 4) the Euler-step
    inputs (used if ``readings.propagation``). A horizontal cloud std above
    ``guard.spread_limit``, once the cloud has converged since its last (re)initialisation,
    counts as a bad update like a poor fit; an estimate off ``guard.bounds`` is clamped into
    them and the cloud reinitialised there (:func:`keep_on_map`). ``healthy_out[k]`` is 1 when
    the cloud std is below ``guard.healthy_std`` and the best fit within half the divergence
    threshold.

    The particles' sines and cosines are taken about references near them (``trig``; they do
    not change the result): the propagation about the navigation heading at the interval
    start plus ``yaw_off``, the cloud's heading offset from the navigation at the last update
    (and, for the Euler step, about the navigation pitch and roll there); the beams about the
    navigation attitude with its yaw moved by the same offset.
    """
    m = x.shape[1]
    steps = ranges.shape[0]
    logw = np.zeros(m)
    ll = np.empty(m)
    w = np.empty(m)
    uni = np.empty(m)
    idx = np.empty(m, dtype=np.int64)
    scratch = np.empty_like(x)
    block = min(BLOCK, m)
    walk = model.sig_bias > 0.0  # gyro biases random-walk: two more noise rows per particle
    noise_rows = 8 if walk else 6
    noise_buf = np.empty(noise_rows * block)
    dist_buf = np.zeros(2 * block)
    work = new_likelihood_work(block, 4 * grid.grids)
    mean = np.empty(N_TIGHT)
    v = np.empty(N_TIGHT)
    cov = np.empty((2, 2))
    su2, inv_d2, out2 = beam_constants(model.sig_u, model.sig_d, model.outside_sigma)
    with_dist = model.dist_mode == DIST_NAVIGATION
    bad = 0
    locked = False  # the cloud has converged since the last (re)initialisation
    yaw_off = 0.0  # the cloud's heading offset from the navigation (centres the particles' trigonometry)
    healthy_e = np.nan  # the last healthy estimate and the navigation's displacement since (filters/recovery.py)
    healthy_n = np.nan
    healthy_k = 0
    dr_e = 0.0
    dr_n = 0.0
    for k in range(steps):
        if k > 0:
            dr_e += inc[k - 1, D0E]
            dr_n += inc[k - 1, D0N]
        vec = beam_vectors(beams, ranges[k])
        att = attitude_reference(nav_pitch[k], nav_roll[k], nav_yaw[k] + yaw_off)
        best = np.inf
        for lo in range(0, m, block):  # the particle passes, block by block
            n = min(block, m - lo)
            dist = dist_buf[:2 * n].reshape((2, n))
            if k > 0:
                noise_all = noise_buf[:noise_rows * n].reshape((noise_rows, n))
                fill_normals(rng, noise_all)
                noise = noise_all[:6]
                if readings.propagation != 0:
                    propagate_tight_euler(x, euler_in[k - 1], readings.dt, inc[k - 1], noise, model.sig_pos,
                                          model.sig_up, model.sig_att, model.dist_mode, dist, nav_pitch[k - 1],
                                          nav_roll[k - 1], nav_yaw[k - 1] + yaw_off, lo)
                else:
                    propagate_tight(x, inc[k - 1], nav_yaw[k - 1], noise, model.sig_pos, model.sig_up,
                                    model.sig_att, model.dist_mode, dist, yaw_off, lo)
                if walk:
                    walk_biases(x, noise_all[6], noise_all[7], model.sig_bias, lo)
            best = min(best, loglik_tight_pass(x, lo, vec, grid, lik, su2, out2, att, dist, with_dist and k > 0,
                                               inv_d2, work_block(work, n), ll[lo:lo + n]))
        mx = add_log_weights(logw, ll)
        ess = normalise_with_ess(logw, mx, w)
        weighted_estimate(x, w, YAW, nav_yaw[k], mean, v, cov)
        yaw_off = mean[YAW] - nav_yaw[k]
        if not abs(yaw_off) < math.pi:  # NaN, or wrapped: centre on the navigation again
            yaw_off = 0.0
        spread = math.sqrt(v[E] + v[N])
        off_map = keep_on_map(mean, guard.bounds)
        est[k, :] = mean
        var[k, :] = v
        cov_en_out[k] = cov[0, 1]
        ess_out[k] = ess
        reinit_out[k] = 0
        healthy_out[k] = 1 if (spread < guard.healthy_std and best < 0.25 * div.sigma * div.sigma) else 0
        locked = locked or healthy_out[k] == 1
        if healthy_out[k] == 1:
            healthy_e = mean[E]
            healthy_n = mean[N]
            healthy_k = k
            dr_e = 0.0
            dr_n = 0.0
        if best < np.inf:  # an update without any bottom lock says nothing about divergence
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        diverged = readings.div_reinit and bad >= div.steps
        collapsed = ess < rs.ess_threshold * m and spread < readings.collapse_spread
        if diverged or collapsed or off_map:
            centre_e, centre_n, half = mean[E], mean[N], prior.half_side
            if diverged and not off_map:
                centre_e, centre_n, half = recovery_square(div.recovery, mean[E], mean[N], healthy_e, healthy_n, dr_e,
                                                           dr_n, (k - healthy_k) * readings.dt, prior.half_side,
                                                           div.growth, div.max_half)
            init_tight_square(x, rng, centre_e, centre_n, half, nav_up[k], nav_pitch[k], nav_roll[k], nav_yaw[k],
                              prior)
            if readings.cloud_std > 0.0:
                gaussian_horizontal(x, rng, centre_e, centre_n, readings.cloud_std)
            logw[:] = 0.0
            bad = 0
            locked = False
            yaw_off = 0.0  # the new cloud is drawn about the navigation heading
            reinit_out[k] = 1
            continue
        if rs.kind == REG_POSTERIOR:
            resample_posterior(x, w, logw, ess, rng, rs, YAW, mean[YAW], spread, uni, idx, scratch)
        else:
            resample_and_regularise(x, w, logw, ess, rng, rs, N_TIGHT, spread, uni, idx, scratch)


@nb.njit(cache=True)
def keep_on_map(mean, bounds):
    """Clamp the horizontal estimate ``mean[0:2]`` into ``bounds`` (e_min, e_max, n_min, n_max).

    Returns True if it had left them (the caller then reinitialises the cloud around the
    clamped estimate). Bounds with e_min > e_max disable the check.
    """
    if bounds[0] > bounds[1]:
        return False
    out = False
    if mean[0] < bounds[0] or mean[0] > bounds[1]:
        mean[0] = min(max(mean[0], bounds[0]), bounds[1])
        out = True
    if mean[1] < bounds[2] or mean[1] > bounds[3]:
        mean[1] = min(max(mean[1], bounds[2]), bounds[3])
        out = True
    return out


def keep_on_map_numpy(mean, bounds):
    """Plain-numpy reference of :func:`keep_on_map`: (clamped copy, left the bounds)."""
    mean = np.array(mean, dtype=float)
    if bounds[0] > bounds[1]:
        return mean, False
    clamped = mean.copy()
    clamped[0] = np.clip(mean[0], bounds[0], bounds[1])
    clamped[1] = np.clip(mean[1], bounds[2], bounds[3])
    return clamped, bool((clamped[:2] != mean[:2]).any())
