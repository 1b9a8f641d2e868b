"""Plain-numpy reference of the tight particle filter's loop (``filters/tight.py``), for the tests.

:func:`tight_loop_numpy` is :func:`tanbench.filters.tight.tight_filter_loop` written again with
numpy and the plain-numpy references of the loop's kernels (``propagate_tight_numpy``,
``walk_biases_numpy``, ``loglik_tight_numpy``, ``normalize_log_weights_numpy``,
``weighted_estimate_numpy``, ``keep_on_map_numpy``, ``recovery_square_numpy``,
``weighted_covariance_numpy``, ``cholesky_small_numpy``, ``resample_indices_numpy``,
``shrink_jitter_full_numpy``, ``gaussian_horizontal_numpy``) and the generator's
(``rng.fill_numpy``): no jitted function is called, directly or indirectly. It draws the same
random numbers in the same order as the jitted loop (the same fills of the same sizes, so the
fast generator's words are rounded up per fill and per chunk just as the loop's are), from the same
generator, and leaves it in the same state: given the same initial cloud and generator state the
two runs agree up to rounding (the kernels' own sines, logarithms and exponentials, their fixed
summation orders and fastmath's reciprocals; the references' numpy functions).

What it covers: the default path, that is exact increments (``filter.propagation: exact``), the
posterior-sized regularisation (``filter.tight_regularisation: posterior``:
``posterior.resample_posterior_into``), any resampling scheme, no progressive correction
(``filter.tempering_ess`` 0: one stage per update), a fixed particle count (no KLD sampling), no
global search (``tight_filter_loop``'s ``search`` None; with ``filter.recovery: global`` the loop then
re-draws around the filter's own estimate, as here), with the gyro biases' random walk
(``filter.gyro_bias_noise``), the three distance innovations, every beam density, the divergence,
collapse and off-map re-draws (:func:`draw_tight_numpy`, ``filters/recovery.py``'s square for
``filter.recovery: last-healthy``), the collapsed cloud's re-spread (``tight_min_spread_m``), a
Gaussian initial cloud's re-draws and ``divergence_reinit`` false. Settings outside that raise
ValueError: the Euler step, the shared regularisation kernel, tempering, KLD sampling, a search.
Headings, pitches and rolls wound more than ``trig.WOUND`` / 2 rad away from the navigation
attitude (only a filter that has lost its heading for good winds them so far; the kernels then
take pseudo-random directions, ``trig.wound_angle``) raise ValueError too.

:func:`draw_tight_numpy` and :func:`init_tight_numpy` are the references of the (re)initial
clouds :func:`tanbench.filters.tight.draw_tight` and ``init_tight``.
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.filters.bias_walk import walk_biases_numpy
from tanbench.filters.cloud import gaussian_horizontal_numpy, uniform_horizontal_numpy
from tanbench.filters.estimate import weighted_estimate_numpy
from tanbench.filters.likelihood import BLOCK, loglik_tight_numpy
from tanbench.filters.posterior import (REG_POSTERIOR, cholesky_small_numpy, posterior_bandwidth,
                                        shrink_jitter_full_numpy, weighted_covariance_numpy)
from tanbench.filters.propagate import DIST_NAVIGATION, propagate_tight_numpy
from tanbench.filters.recovery import recovery_square_numpy
from tanbench.filters.resample import SYSTEMATIC, normalize_log_weights_numpy, resample_indices_numpy
from tanbench.filters.rng import fill_numpy
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.tight import TightOutputs, keep_on_map_numpy
from tanbench.filters.trig import WOUND
from tanbench.navigation.increments import D0E, D0N
from tanbench.terrain.grid import MapArgs


def draw_tight_numpy(x, rng, centre_e, centre_n, up, pitch, roll, yaw, prior, half_side):
    """Plain-numpy reference of :func:`tanbench.filters.tight.draw_tight` (returns a new array of ``x``'s
    shape): the numbers drawn from ``rng`` as the kernel's fills draw them (``rng.fill_numpy``; ``rng``
    advanced in place): the square's uniforms (east row, then north), then one block of normals for the
    rows up .. gyro bias z, row after row."""
    m = np.shape(x)[1]
    out = uniform_horizontal_numpy(np.empty((N_TIGHT, m)), fill_numpy(rng, (2, m), False), centre_e, centre_n,
                                   half_side)
    z = fill_numpy(rng, (N_TIGHT - U, m), True)
    for row, centre, std in ((U, up, prior.std_up), (PITCH, pitch, prior.std_att), (ROLL, roll, prior.std_att),
                             (YAW, yaw, prior.std_yaw), (BX, 0.0, prior.std_bias), (BZ, 0.0, prior.std_bias)):
        out[row] = centre + std * z[row - U]
    return out


def init_tight_numpy(x, rng, centre_e, centre_n, up, pitch, roll, yaw, prior):
    """Plain-numpy reference of :func:`tanbench.filters.tight.init_tight`: :func:`draw_tight_numpy` over the
    prior's square."""
    return draw_tight_numpy(x, rng, centre_e, centre_n, up, pitch, roll, yaw, prior, prior.half_side)


def check_scope(settings, search=None) -> None:
    """Raise ValueError if the loop's ``settings`` (a ``TightSettings``) or ``search`` ask for a part of
    the loop :func:`tight_loop_numpy` does not cover."""
    problems = []
    if settings.readings.propagation != 0:
        problems.append("the Euler step (filter.propagation other than exact)")
    if settings.rs.kind != REG_POSTERIOR:
        problems.append("the shared regularisation kernel (filter.tight_regularisation: shared, "
                        "or regularisation: none)")
    if settings.temper.stages != 1:
        problems.append("progressive correction (filter.tempering_ess above 0)")
    if settings.kld.epsilon > 0.0:
        problems.append("KLD sampling (filter.kld_epsilon)")
    if search is not None:
        problems.append("the global search (a search bundle; with filter.recovery: global pass search=None)")
    if problems:
        raise ValueError("tight_loop_numpy covers the default path only; these settings ask for "
                         + "; ".join(problems))


def grid_maps(grid):
    """The map heights as ``MapArgs`` and the variance grid (None if there is none) of a ``NodeGrid``: the
    grids ``loglik_tight_numpy`` takes, from the interleaved nodes the jitted passes read."""
    nodes = np.asarray(grid.nodes).reshape(grid.ny, grid.nx, grid.grids)
    zmap = MapArgs(np.ascontiguousarray(nodes[..., 0]), grid.e0, grid.n0, grid.inv_re, grid.inv_rn)
    return zmap, (np.ascontiguousarray(nodes[..., 1]) if grid.grids == 2 else None)


def check_not_wound(k, *angles):
    """Refuse (ValueError) an update ``k`` where a particle's angle is wound (or NaN) WOUND / 2 or more from its
    reference: ``angles`` are (the particles' angles, the reference) pairs. The kernels then take pseudo-random
    directions (``trig.wound_angle``), which the loop references do not follow."""
    for values, reference in angles:
        if not (np.abs(np.asarray(values) - reference) < WOUND / 2.0).all():
            raise ValueError(f"update {k}: a particle's attitude is wound (or NaN) beyond WOUND / 2 from its "
                             "reference (the navigation's, or the loose loop's corrected heading); the kernels then "
                             "take pseudo-random directions, which this reference does not follow")


def block_normals(rng, rows, m):
    """The (rows, m) standard normals a loop draws for its particles block by block (``likelihood.BLOCK``): one
    fill of (rows, n) per block (``rng.fill_numpy``, ``rng`` advanced in place), the blocks side by side."""
    block = min(BLOCK, m)
    return np.concatenate([fill_numpy(rng, (rows, min(block, m - lo)), True) for lo in range(0, m, block)], axis=1)


def loop_draw(rng):
    """``draw(n, normal)`` as ``resample.resample_and_regularise_numpy`` takes it: the loop's generator's next fill
    (``rng`` advanced in place)."""
    return lambda count, normal: fill_numpy(rng, count, normal)


def tight_loop_numpy(x, rng, track, ranges, beams, grid, settings, search=None) -> TightOutputs:
    """Plain-numpy reference of ``tight_filter_loop(x, rng, track, ranges, beams, grid, settings, out,
    search=None)`` (module docstring: what it covers): returns the :class:`TightOutputs` the loop fills,
    ``rng`` (the loop's generator: the fast generator's words, a ``Pcg64Stream`` or a Generator) advanced
    as the loop advances it; ``x`` is not changed. The same arguments as the loop's: ``grid`` the
    ``NodeGrid`` the loop reads (its grids taken apart, :func:`grid_maps`)."""
    check_scope(settings, search)
    inc, nav_yaw, nav_pitch, nav_roll, nav_up, _ = track
    model, rs, div, prior, readings, lik, guard, _, _ = settings
    zmap, mvar = grid_maps(grid)
    x = np.array(x, dtype=float)
    m = x.shape[1]
    steps = ranges.shape[0]
    out = TightOutputs(np.empty((steps, N_TIGHT)), np.empty((steps, N_TIGHT)), np.empty(steps), np.empty(steps),
                       np.zeros(steps, dtype=np.int64), np.zeros(steps, dtype=np.int64),
                       np.ones(steps, dtype=np.int64), np.full(steps, m, dtype=np.int64))
    walk = model.sig_bias > 0.0
    noise_rows = 8 if walk else 6
    with_dist = model.dist_mode == DIST_NAVIGATION
    logw = np.zeros(m)
    bad = 0
    locked = False
    healthy_e = healthy_n = math.nan
    healthy_k = 0
    dr_e = dr_n = 0.0
    for k in range(steps):
        if k > 0:
            dr_e += inc[k - 1, D0E]
            dr_n += inc[k - 1, D0N]
            check_not_wound(k, (x[PITCH], nav_pitch[k - 1]), (x[ROLL], nav_roll[k - 1]), (x[YAW], nav_yaw[k - 1]))
            # the noise of each block of the cloud, one fill a block: (rows, n) in row order
            noise = block_normals(rng, noise_rows, m)
            x, dist = propagate_tight_numpy(x, inc[k - 1], nav_yaw[k - 1], noise[:6], model.sig_pos, model.sig_up,
                                            model.sig_att, model.dist_mode)
            if walk:
                x = walk_biases_numpy(x, noise[6], noise[7], model.sig_bias)
        check_not_wound(k, (x[PITCH], nav_pitch[k]), (x[ROLL], nav_roll[k]), (x[YAW], nav_yaw[k]))
        ll, best = loglik_tight_numpy(x, beams, ranges[k], zmap, mvar, lik, model.sig_u, model.outside_sigma,
                                      dist if (with_dist and k > 0) else None, model.sig_d)
        logw = logw + ll
        w, _ = normalize_log_weights_numpy(logw)
        ess = 1.0 / np.sum(w * w)
        mean, v, cov = weighted_estimate_numpy(x, w, YAW, nav_yaw[k])
        spread = math.sqrt(v[E] + v[N])
        mean, off_map = keep_on_map_numpy(mean, guard.bounds)
        out.est[k] = mean
        out.var[k] = v
        out.cov_en[k] = cov[0, 1]
        out.ess[k] = ess
        healthy = spread < guard.healthy_std and best < 0.25 * div.sigma * div.sigma
        out.healthy[k] = int(healthy)
        locked = locked or healthy
        if healthy:
            healthy_e, healthy_n, healthy_k = mean[E], mean[N], k
            dr_e = dr_n = 0.0
        if best < np.inf:
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        diverged = readings.div_reinit and bad >= div.steps
        collapsed = ess < rs.ess_threshold * m and spread < readings.collapse_spread
        if diverged or collapsed or off_map:
            centre_e, centre_n, half = mean[E], mean[N], prior.reinit_half_side
            if diverged and not off_map:
                centre_e, centre_n, half = recovery_square_numpy(div.recovery, mean[E], mean[N], healthy_e, healthy_n,
                                                                 dr_e, dr_n, (k - healthy_k) * readings.dt,
                                                                 prior.reinit_half_side, div.growth, div.max_half)
            x = draw_tight_numpy(x, rng, centre_e, centre_n, nav_up[k], nav_pitch[k], nav_roll[k], nav_yaw[k], prior,
                                 half)
            if readings.cloud_std > 0.0:
                x = gaussian_horizontal_numpy(x, fill_numpy(rng, (2, m), True), centre_e, centre_n,
                                              readings.cloud_std)
            logw = np.zeros(m)
            bad = 0
            locked = False
            out.reinit[k] = 1
            continue
        logw = logw - logw.max()
        if ess < rs.ess_threshold * m:
            x = _resample_posterior_numpy(x, w, rng, rs, mean[YAW], spread)
            logw = np.zeros(m)
    return out


def _resample_posterior_numpy(x, w, rng, rs, yaw_ref, spread):
    """``posterior.resample_posterior_into`` with M draws (the loop's fixed count) from the references:
    the weighted covariance of the regularised rows before resampling, the ancestors, the kernel's
    correlated jitter, then the re-spread of a cloud below ``rs.min_spread``; the random numbers drawn
    in the kernel's order (the uniforms: one for the systematic scheme, M else; the jitter's (d, M)
    normals; the re-spread's (2, M))."""
    m = x.shape[1]
    d = rs.cols.shape[0]
    mean, cov = weighted_covariance_numpy(x, rs.cols, w, YAW, yaw_ref)
    chol, _ = cholesky_small_numpy(cov)
    uni = fill_numpy(rng, 1 if rs.scheme == SYSTEMATIC else m, False)
    x = x[:, resample_indices_numpy(rs.scheme, w, uni, m)]
    x = shrink_jitter_full_numpy(x, rs.cols, YAW, mean, chol, posterior_bandwidth(d, m, rs.size),
                                 fill_numpy(rng, (d, m), True))
    if spread < rs.min_spread:
        noise = fill_numpy(rng, (2, m), True)
        s = rs.min_spread / math.sqrt(2.0)
        x[E] += s * noise[0]
        x[N] += s * noise[1]
    return x
