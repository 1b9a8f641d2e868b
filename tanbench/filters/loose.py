"""Loosely coupled TAN (Melo & Matos Section 5, after Hagen et al. 2011): the baseline.

The terrain measurements are processed in a separate particle filter over horizontal
position only, driven by the navigation system's position increments; its beams are
projected with the navigation system's attitude (it has no attitude or bias states).
Its process noise is Table 2's plus, by default, the cross-track error the navigation
system's heading uncertainty (the same prior the tight filter starts from, 30 deg)
causes on each increment: without it a position-only filter cannot follow a track
dead-reckoned with a wrong heading, and its fixes make the navigation worse than none.
While the filter has converged (horizontal std below ``converged_std`` and its best
particle fitting the terrain within half the divergence threshold, for ``div_steps``
updates in a row), its estimate is fed back to the navigation system as a position fix; the method's output is the
navigation system corrected by the latest fix. The navigation system keeps its own
heading, so a heading error is never corrected, only the position it has caused.
Divergence, resampling and regularisation are handled as in the tight filter.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters.cloud import gaussian_horizontal
from tanbench.filters.estimate import weighted_estimate
from tanbench.filters.likelihood import loglik_loose
from tanbench.filters.propagate import propagate_loose
from tanbench.filters.resample import effective_sample_size, normalize_log_weights, resample_and_regularise

LOOSE_COLS = np.array([0, 1], dtype=np.int64)  # the states the regularisation jitters


@nb.njit(cache=True)
def init_loose(x, rng, centre_e, centre_n, half_side):
    """Uniform square of side 2 * half_side around the centre."""
    for j in range(x.shape[0]):
        x[j, 0] = centre_e + rng.uniform(-half_side, half_side)
        x[j, 1] = centre_n + rng.uniform(-half_side, half_side)


@nb.njit(cache=True)
def loose_filter_loop(x, rng, d0, nav_en, nav_up, offsets, zmap, model, rs, div, half_side, readings,
                      out_en, var, cov_en_out, ess_out, reinit_out, fixed_out):
    """Run the loose filter; ``out_en`` (K+1, 2) is the fix-corrected navigation position.

    ``var`` (K+1, 2) and ``cov_en_out`` (K+1,) are the cloud's east/north (co)variances.

    ``zmap``, ``model``, ``rs``, ``div`` and ``readings`` are the bundles of
    :mod:`tanbench.filters.params` (MapArgs, LooseModel, Resampling, Divergence, Readings;
    of the readings the loose filter uses ``cloud_std``, ``div_reinit`` and ``collapse_spread``).
    """
    z, e0, n0, inv_re, inv_rn = zmap
    m = x.shape[0]
    steps = offsets.shape[0]
    logw = np.zeros(m)
    ll = np.empty(m)
    w = np.empty(m)
    noise = np.empty((m, 3))
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
    for k in range(steps):
        if k > 0:
            for j in range(m):
                noise[j, 0] = rng.standard_normal()
                noise[j, 1] = rng.standard_normal()
                noise[j, 2] = rng.standard_normal()
            propagate_loose(x, d0[k - 1, 0], d0[k - 1, 1], noise, model.sig_pos, model.sig_heading)
        best = loglik_loose(x, offsets[k], nav_up[k], z, e0, n0, inv_re, inv_rn, model.sig_u, model.outside_sigma,
                            ll)
        for j in range(m):
            logw[j] += ll[j]
        normalize_log_weights(logw, w)
        weighted_estimate(x, w, -1, 0.0, mean, v, cov)
        ess = effective_sample_size(w)
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
            init_loose(x, rng, centre_e, centre_n, half_side)
            if readings.cloud_std > 0.0:
                gaussian_horizontal(x, rng, centre_e, centre_n, readings.cloud_std)
            logw[:] = 0.0
            bad = 0
            reinit_out[k] = 1
            continue
        resample_and_regularise(x, w, logw, ess, rng, rs, 2, spread, uni, idx, scratch)
