"""Tightly coupled TAN (Section 3, Algorithm 1): the 8-state particle filter loop.

The loop is jitted end to end and composed of the kernels in ``propagate``,
``likelihood``, ``resample`` and ``estimate``; random numbers come from the run's
``numpy.random.Generator``, passed in. Per update k:

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

from tanbench.filters.cloud import gaussian_horizontal
from tanbench.filters import FASTMATH
from tanbench.filters.estimate import weighted_estimate
from tanbench.filters.likelihood import (beam_constants, beam_vectors, loglik_tight_mapaware_particle,
                                        loglik_tight_particle)
from tanbench.filters.propagate import propagate_tight_euler_particle, propagate_tight_particle
from tanbench.filters.resample import add_log_weights, normalise_with_ess, resample_and_regularise
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, YAW
from tanbench.filters.trig import attitude_reference

REGULARISED_STATES = {
    "position-heading-biases": np.array([E, N, YAW, BX, BZ], dtype=np.int64),
    "heading-biases": np.array([YAW, BX, BZ], dtype=np.int64),
    "biases": np.array([BX, BZ], dtype=np.int64),
}



@nb.njit(cache=True)
def init_tight(x, rng, centre_e, centre_n, up, pitch, roll, yaw, prior):
    """Initial cloud: uniform square of side 2 * prior.half_side around (centre_e, centre_n),
    Gaussians else (``prior`` is a :class:`tanbench.filters.params.TightPrior`)."""
    half_side = prior.half_side
    for j in range(x.shape[0]):
        x[j, 0] = centre_e + rng.uniform(-half_side, half_side)
        x[j, 1] = centre_n + rng.uniform(-half_side, half_side)
        x[j, 2] = up + prior.std_up * rng.standard_normal()
        x[j, 3] = pitch + prior.std_att * rng.standard_normal()
        x[j, 4] = roll + prior.std_att * rng.standard_normal()
        x[j, 5] = yaw + prior.std_yaw * rng.standard_normal()
        x[j, 6] = prior.std_bias * rng.standard_normal()
        x[j, 7] = prior.std_bias * rng.standard_normal()


@nb.njit(cache=True, fastmath=FASTMATH)
def propagate_and_weigh(x, rng, propagate, inc, yaw_nav0, yaw_off, start_pitch, start_roll, euler_in, readings, model,
                        beams, ranges, zmap, lik, ref_pitch, ref_roll, ref_yaw, ll):
    """One pass over the particles of a tight update: for each particle, draw its six
    propagation normals (E, N, U, pitch, roll, yaw: the same numbers in the same order as
    filling an (M, 6) array row by row), move it (if ``propagate``: ``propagate_tight``, or
    ``propagate_tight_euler`` if ``readings.propagation``) and weigh it (``loglik_tight`` or
    ``loglik_tight_mapaware``, into ``ll``); the cloud is read once instead of twice and no
    noise or innovation arrays are written. Returns the best chi^2 per beam.

    The per-particle arithmetic is the array kernels' (their ``*_particle`` functions, under
    the same flags); the log-weights are accumulated outside (``resample.add_log_weights``),
    where no reassociation reaches them.

    The particles' sines and cosines are taken about references near them (``trig``; they
    only decide where the short series is used): the propagation about the navigation
    heading at the interval start plus ``yaw_off``, the cloud's heading offset from the
    navigation at the last update (and, for the Euler step, about the navigation pitch and
    roll there, ``start_*``); the beams about ``ref_*``, which the loop sets to the
    navigation attitude with the yaw moved by the same offset. With a navigation heading
    off by tens of degrees, as the paper's 30 degree initial error, the offset keeps the
    particles within the series' range instead of calling ``math.sin`` and ``math.cos``.
    """
    z, e0, n0, inv_re, inv_rn = zmap
    su2, inv_u2, inv_d2, outside_sq, out2 = beam_constants(model.sig_u, model.sig_d, model.outside_sigma)
    att = attitude_reference(ref_pitch, ref_roll, ref_yaw)
    att0 = attitude_reference(start_pitch, start_roll, yaw_nav0 + yaw_off)
    s_off, c_off = math.sin(yaw_off), math.cos(yaw_off)
    vec = beam_vectors(beams, ranges)
    used = vec.shape[0]
    euler = readings.propagation != 0
    best = np.inf
    for j in range(x.shape[0]):
        dist_e = 0.0
        dist_n = 0.0
        if propagate:
            n_e = rng.standard_normal()
            n_n = rng.standard_normal()
            n_u = rng.standard_normal()
            n_pitch = rng.standard_normal()
            n_roll = rng.standard_normal()
            n_yaw = rng.standard_normal()
            if euler:
                dist_e, dist_n = propagate_tight_euler_particle(x, j, euler_in, readings.dt, inc, att0, n_e, n_n,
                                                                n_u, n_pitch, n_roll, n_yaw, model.sig_pos,
                                                                model.sig_up, model.sig_att, model.dist_mode)
            else:
                dist_e, dist_n = propagate_tight_particle(x, j, inc, yaw_nav0, yaw_off, s_off, c_off, n_e, n_n, n_u,
                                                          n_pitch, n_roll, n_yaw, model.sig_pos, model.sig_up,
                                                          model.sig_att, model.dist_mode)
        if lik.mapaware:
            lj, chi = loglik_tight_mapaware_particle(x, j, vec, lik.grids, e0, n0, inv_re, inv_rn, su2,
                                                     inv_u2, out2, att, lik.kind, lik.nu, dist_e, dist_n, inv_d2)
        else:
            lj, chi = loglik_tight_particle(x, j, vec, z, e0, n0, inv_re, inv_rn, inv_u2, outside_sq, att,
                                            dist_e, dist_n, inv_d2)
        if used > 0 and chi / used < best:
            best = chi / used
        ll[j] = lj
    return best


@nb.njit(cache=True)
def tight_filter_loop(x, rng, inc, nav_yaw, nav_pitch, nav_roll, nav_up, ranges, beams, zmap, model, rs, div,
                      prior, readings, euler_in, lik, guard, est, var, cov_en_out, ess_out, reinit_out,
                      healthy_out):
    """Run the filter over all updates; fill est/var (K+1, 8), cov_en_out, ess_out, reinit_out and
    healthy_out (K+1,).

    ``cov_en_out`` is the cloud's weighted east/north covariance (``var`` holds the variances).

    ``zmap``, ``model``, ``rs``, ``div``, ``prior``, ``readings``, ``lik`` and ``guard`` are the
    bundles of :mod:`tanbench.filters.params` (MapArgs, TightModel, Resampling, Divergence,
    TightPrior, Readings, Likelihood, Guard); ``euler_in`` (K, 4) the Euler-step inputs (used if
    ``readings.propagation``). ``lik.mapaware`` selects :func:`loglik_tight_mapaware` instead of
    :func:`loglik_tight`; a horizontal cloud std above ``guard.spread_limit``, once the
    cloud has converged since its last (re)initialisation, counts as a bad update like a
    poor fit; an estimate off ``guard.bounds`` is clamped into them and the cloud
    reinitialised there (:func:`keep_on_map`). ``healthy_out[k]`` is 1 when the cloud std
    is below ``guard.healthy_std`` and the best fit within half the divergence threshold.
    """
    m = x.shape[0]
    steps = ranges.shape[0]
    logw = np.zeros(m)
    ll = np.empty(m)
    w = np.empty(m)
    uni = np.empty(m)
    idx = np.empty(m, dtype=np.int64)
    scratch = np.empty_like(x)
    mean = np.empty(N_TIGHT)
    v = np.empty(N_TIGHT)
    cov = np.empty((2, 2))
    no_inc = np.zeros(inc.shape[1])  # the interval before update 0: none, nothing moves
    no_euler = np.zeros(euler_in.shape[1])
    bad = 0
    locked = False  # the cloud has converged since the last (re)initialisation
    yaw_off = 0.0  # the cloud's heading offset from the navigation (centres the particles' trigonometry)
    for k in range(steps):
        inc_k = inc[k - 1] if k > 0 else no_inc
        euler_k = euler_in[k - 1] if k > 0 and readings.propagation != 0 else no_euler
        k0 = max(k - 1, 0)
        best = propagate_and_weigh(x, rng, k > 0, inc_k, nav_yaw[k0], yaw_off, nav_pitch[k0], nav_roll[k0], euler_k,
                                   readings, model, beams, ranges[k], zmap, lik, nav_pitch[k], nav_roll[k],
                                   nav_yaw[k] + yaw_off, ll)
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
        if best < np.inf:  # an update without any bottom lock says nothing about divergence
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        diverged = readings.div_reinit and bad >= div.steps
        collapsed = ess < rs.ess_threshold * m and spread < readings.collapse_spread
        if diverged or collapsed or off_map:
            init_tight(x, rng, mean[E], mean[N], nav_up[k], nav_pitch[k], nav_roll[k], nav_yaw[k], prior)
            if readings.cloud_std > 0.0:
                gaussian_horizontal(x, rng, mean[E], mean[N], readings.cloud_std)
            logw[:] = 0.0
            bad = 0
            locked = False
            yaw_off = 0.0  # the new cloud is drawn about the navigation heading
            reinit_out[k] = 1
            continue
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
