"""Plain-numpy references of the other estimators' loops (the point-mass filter, TERCOM, the iterated EKF,
the marginalized PF), for the tests.

Each function below is one jitted loop written again with numpy and the plain-numpy references of the
loop's kernels (and, for the MPF, of the generator's fills, ``rng.fill_numpy``): no jitted function is
called, directly or indirectly. Each takes the loop's own arguments but ``out`` and returns what the loop
fills; the arguments are not changed. Given the same inputs (and, for the MPF, the same generator state)
loop and reference agree up to rounding: the kernels' own sums, moments about a grid's centre or the first
particle, sines and cosines (the MPF's polynomials, ``trig.sin_cos``), fastmath's reciprocals and
Sherman-Morrison's closed form, where the references call numpy and LAPACK in other orders. Their discrete
decisions (blurring, re-gridding, fixes, gates, divergence, resampling) are taken from the same values,
so they agree unless a value falls within that rounding of a threshold.

* :func:`pmf_loop_numpy`: ``pmf.pmf_loop``, the whole loop: the grid's translation, the accumulated
  process-noise blur (``blur_separable_numpy``; a kernel of more taps than the grid has nodes included),
  the heading random walk between slices (``mix_headings_numpy``), the likelihood of every live slice
  (``grid_nodes_numpy``, ``likelihood.loglik_loose_numpy`` with the plain Gaussian density, as the loop
  takes it), the mixture's moments (``slice_moments_numpy``), the divergence re-initialisation
  (``pmf_init_numpy``) and the re-gridding (``resample_grid_numpy``), with one heading slice or a bank.
  Nothing raises ValueError: no setting of the loop is left out.
* :func:`tercom_loop_numpy`: ``tercom.tercom_loop``, the whole loop: the corrected solution, the profile's
  ring buffer (``collect_numpy``), the coarse and fine searches (``profile_surface_numpy``, ``best_numpy``,
  ``surface_likelihood_moments_numpy``), the ambiguity, edge and consistency tests and the fix that moves
  the solution and its profile; both metrics, one heading or several. Nothing raises ValueError.
* :func:`ekf_loop_numpy`: ``ekf.ekf_loop``, the whole loop (``ekf_predict_numpy``, ``iekf_update_numpy``):
  every pass count and gate, rejected and skipped (no usable beam) updates. Nothing raises ValueError.
* :func:`mpf_loop_numpy`: ``mpf.mpf_loop``, the whole loop: the propagation and the per-particle Kalman
  filters (``mpf_propagate_numpy``; the yaw noise drawn as the loop's fill draws it), the marginal
  likelihood (``mpf_loglik_update_numpy``, the dense Gaussian density), the weights and estimate
  (``normalize_log_weights_numpy``, ``weighted_estimate_numpy``), the divergence re-initialisation
  (``init_mpf_numpy``) and the shared resampling (``resample.resample_and_regularise_numpy``: every scheme,
  both regularisation kernels or none, the re-spread), from any of the loops' generators (the fast
  generator's words, a ``Pcg64Stream``, a Generator: what ``mpf.run_mpf`` passes, whatever
  ``filter.random_numbers`` says, and what the tests' loop runs use). A particle's yaw wound
  more than ``trig.WOUND`` / 2 rad from the navigation's (or NaN) raises ValueError: the kernels then take
  a pseudo-random direction (``trig.wound_angle``), which the reference does not follow; only a filter
  that has lost its heading for good (Gordon roughening of an unobserved yaw) winds it so far.

The references were written from the loops' code, not from a description; where a loop keeps a quirk
(the PMF keeps a slice's old masses when its re-gridded density sums to zero but moves its centre; its
re-initialisation resets the blur's accumulated variance but not the heading walk's; the MPF re-initialises
whatever ``filter.divergence_reinit`` says) the reference keeps it too.
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.filters.ekf import NX, EkfOutputs, ekf_predict_numpy, iekf_update_numpy
from tanbench.filters.estimate import weighted_estimate_numpy
from tanbench.filters.likelihood import Likelihood, loglik_loose_numpy
from tanbench.filters.mpf import (E, N, N_MPF, PSI, MpfOutputs, init_mpf_numpy, mpf_loglik_update_numpy,
                                  mpf_propagate_numpy)
from tanbench.filters.pmf import (DEAD_MASS, PmfOutputs, blur_separable_numpy, grid_nodes_numpy, mix_headings_numpy,
                                  pmf_init_numpy, resample_grid_numpy, slice_moments_numpy)
from tanbench.filters.resample import normalize_log_weights_numpy, resample_and_regularise_numpy
from tanbench.filters.rng import fill_numpy
from tanbench.filters.tercom import (MSD, TercomOutputs, best_numpy, collect_numpy, profile_surface_numpy,
                                     surface_likelihood_moments_numpy)
from tanbench.filters.tight_reference import check_not_wound, grid_maps, loop_draw
from tanbench.terrain.grid import MapArgs


# --------------------------------------------------------------------------------------
# point-mass filter
# --------------------------------------------------------------------------------------
def pmf_loop_numpy(track, offsets, grid, settings) -> PmfOutputs:
    """Plain-numpy reference of ``pmf_loop(track, offsets, grid, settings, out)`` (module docstring): returns
    the :class:`~tanbench.filters.pmf.PmfOutputs` the loop fills. ``grid`` the ``NodeGrid`` the loop reads
    (its heights taken apart, ``tight_reference.grid_maps``)."""
    nav_en, nav_up, nav_yaw, d0 = track
    (n, deltas, sig_heading0, half_side, sig_pos, sig_cross, sig_heading_step, s_min, sig_u, outside_sigma,
     div_sigma, div_steps) = settings
    deltas = np.asarray(deltas, dtype=float)
    zmap, _ = grid_maps(grid)
    plain = Likelihood(False, 0, 4.0)
    h = deltas.shape[0]
    steps = nav_en.shape[0]
    out = PmfOutputs(np.empty((steps, 3)), np.empty((steps, 3)), np.zeros(steps, dtype=np.int64),
                     np.zeros(steps, dtype=np.int64))
    s0 = 2.0 * half_side / (n - 1)
    s = s0
    p, centres = pmf_init_numpy((len(deltas), n, n), deltas, nav_en[0, 0], nav_en[0, 1], sig_heading0)
    q_acc = 0.0
    a_acc = 0.0
    dh = deltas[1] - deltas[0] if h > 1 else 1.0
    cos_d, sin_d = np.cos(deltas), np.sin(deltas)
    bad = 0
    for k in range(steps):
        if k > 0:
            de, dn = d0[k - 1]
            centres = centres + np.stack([cos_d * de - sin_d * dn, sin_d * de + cos_d * dn], axis=1)
            q_acc += sig_pos * sig_pos + (sig_cross * sig_cross) * (de * de + dn * dn)
            if q_acc >= 0.25 * s * s:
                p = np.array([blur_separable_numpy(p[q], math.sqrt(q_acc) / s) for q in range(h)])
                q_acc = 0.0
            if h > 1:
                a_acc += 0.5 * (sig_heading_step / dh) ** 2
                if a_acc >= 0.02:
                    p = mix_headings_numpy(p, centres, s, min(a_acc, 0.25))
                    a_acc = 0.0
        # the likelihood of every slice with mass, its beams turned by the slice's heading offset
        live = [q for q in range(h) if p[q].max() > 0.0]
        ll = np.zeros((h, n * n))
        best = np.inf
        for q in live:
            o = offsets[k]
            rot = np.stack([cos_d[q] * o[:, 0] - sin_d[q] * o[:, 1], sin_d[q] * o[:, 0] + cos_d[q] * o[:, 1],
                            o[:, 2]], axis=1)
            ll[q], b = loglik_loose_numpy(grid_nodes_numpy(centres[q, 0], centres[q, 1], s, n), rot, nav_up[k],
                                          zmap, None, plain, sig_u, outside_sigma)
            best = min(best, b)
        flat = p.reshape(h, n * n).copy()
        held = flat > 0.0
        held[[q for q in range(h) if q not in live]] = False
        mx = ll[held].max() if held.any() else -np.inf
        flat[held] *= np.exp(ll[held] - mx)  # a node without mass stays 0
        p = (flat / flat[held].sum()).reshape(h, n, n)
        out.live[k] = len(live)
        # the estimate: the mixture's moments over the slices
        mom = np.array([slice_moments_numpy(p[q], centres[q, 0], centres[q, 1], s) for q in range(h)])
        me = mom[:, 0] @ mom[:, 1]
        mn = mom[:, 0] @ mom[:, 2]
        myaw = mom[:, 0] @ deltas
        ve = mom[:, 0] @ (mom[:, 3] + (mom[:, 1] - me) ** 2)
        vn = mom[:, 0] @ (mom[:, 4] + (mom[:, 2] - mn) ** 2)
        vyaw = dh * dh / 12.0 + mom[:, 0] @ (deltas - myaw) ** 2 if h > 1 else sig_heading0 * sig_heading0
        out.est[k] = me, mn, nav_yaw[k] + myaw
        out.var[k] = ve + s * s / 12.0, vn + s * s / 12.0, vyaw
        if best < np.inf:
            bad = bad + 1 if best > div_sigma * div_sigma else 0
        if bad >= div_steps:
            s = s0
            p, centres = pmf_init_numpy((len(deltas), n, n), deltas, me, mn, sig_heading0)
            q_acc = 0.0
            bad = 0
            out.reinit[k] = 1
            continue
        # re-gridding: the spacing follows the widest slice with mass, each slice re-centres on its mean
        wide = mom[:, 0] > 1e-3
        sig_max = math.sqrt(np.maximum(mom[wide, 3], mom[wide, 4]).max()) if wide.any() else 0.0
        s_t = max(s_min, 8.0 * sig_max / (n - 1))
        new_s = s_t if (s_t < 0.5 * s or s_t > 2.0 * s) else s
        p = p.copy()
        centres = centres.copy()
        for q in range(h):
            if mom[q, 0] < DEAD_MASS:
                p[q] = 0.0
                centres[q] = me, mn
                continue
            off = max(abs(mom[q, 1] - centres[q, 0]), abs(mom[q, 2] - centres[q, 1]))
            if new_s != s or off > 0.125 * n * s:
                moved = resample_grid_numpy(p[q], centres[q, 0], centres[q, 1], s, mom[q, 1], mom[q, 2], new_s)
                if moved.sum() > 0.0:  # the slice keeps its mass
                    p[q] = moved * (mom[q, 0] / moved.sum())
                centres[q] = mom[q, 1], mom[q, 2]
        s = new_s
    return out


# --------------------------------------------------------------------------------------
# TERCOM
# --------------------------------------------------------------------------------------
def _turned(ue, un, angle):
    """The vectors (ue, un) turned by ``angle``."""
    c, s = math.cos(angle), math.sin(angle)
    return c * ue - s * un, s * ue + c * un


def tercom_loop_numpy(d0, offsets, nav_up, start_e, start_n, zmap, settings) -> TercomOutputs:
    """Plain-numpy reference of ``tercom_loop(d0, offsets, nav_up, start_e, start_n, zmap, settings, out)``
    (module docstring): returns the :class:`~tanbench.filters.tercom.TercomOutputs` the loop fills."""
    zmap = MapArgs(*zmap)
    (profile_len, interval, metric, headings, window_max, fix_std, var0_pos, var0_heading, q_pos, q_heading, sig_u,
     div_sigma) = settings
    steps, m = offsets.shape[:2]
    out = TercomOutputs(np.empty((steps, 3)), np.empty((steps, 3)), np.zeros(steps, dtype=np.int64))
    res = 1.0 / min(zmap.inv_re, zmap.inv_rn)
    buf = np.full((3, profile_len, m), np.nan)  # east, north, measured height of the last profile_len updates
    pc_e, pc_n, dc = float(start_e), float(start_n), 0.0
    p_pos = p_fix = var0_pos
    p_walk = 0.0
    fix_e, fix_n = pc_e, pc_n
    p_head = var0_heading
    count = 0
    consistent = (0.5 * div_sigma) ** 2 * sig_u * sig_u
    for k in range(steps):
        if k > 0:
            te, tn = _turned(d0[k - 1, 0], d0[k - 1, 1], dc)
            pc_e += te
            pc_n += tn
            p_walk += q_pos
            p_head += q_heading
            p_pos = p_fix + p_walk + p_head * ((pc_e - fix_e) ** 2 + (pc_n - fix_n) ** 2)
        # this update's footprints: the profile's newest row, the oldest dropped
        oe, on = _turned(offsets[k, :, 0], offsets[k, :, 1], dc)
        newest = np.stack([pc_e + oe, pc_n + on, nav_up[k] + offsets[k, :, 2]])
        buf = np.concatenate([buf[:, 1:], newest[:, None]], axis=1)
        count = min(count + 1, profile_len)
        if count == profile_len and k % interval == 0:
            pe, pn, ph = collect_numpy(buf[0], buf[1], buf[2], count)
            if pe.shape[0] >= profile_len:
                window = min(max(3.0 * math.sqrt(p_pos), 3.0 * res), window_max)
                half = int(math.ceil(window / res))
                span = min(2.0 * math.sqrt(p_head), math.radians(45.0))
                deltas = np.linspace(-span, span, headings) if headings > 1 else np.zeros(1)
                side = 2 * half + 1
                msd, mad = profile_surface_numpy(pe, pn, ph, pc_e, pc_n, half, res, deltas, zmap)
                best, bd, bi, bj = best_numpy(msd if metric == MSD else mad)
                cm = surface_likelihood_moments_numpy(msd, deltas, half, res, count, sig_u)
                ambiguous = max(cm[2], cm[3]) > fix_std * fix_std
                edge = bi == 0 or bj == 0 or bi == side - 1 or bj == side - 1
                if best < np.inf and not ambiguous and not edge:
                    # the fine search around the best coarse candidate
                    dstep = deltas[1] - deltas[0] if deltas.shape[0] > 1 else 0.0
                    fd = np.array([deltas[bd] - 0.5 * dstep, deltas[bd], deltas[bd] + 0.5 * dstep]) if headings > 1 \
                        else np.zeros(1)
                    fstep, fh = res / 5.0, 5
                    cx, cy = (bj - half) * res, (bi - half) * res
                    fsd, fad = profile_surface_numpy(pe + cx, pn + cy, ph, pc_e + cx, pc_n + cy, fh, fstep, fd, zmap)
                    _, fbd, fbi, fbj = best_numpy(fsd if metric == MSD else fad)
                    fm = surface_likelihood_moments_numpy(fsd, fd, fh, fstep, count, sig_u)
                    if fsd[fbd, fbi, fbj] < consistent:
                        tx, ty, dd = cx + (fbj - fh) * fstep, cy + (fbi - fh) * fstep, fd[fbd]
                        # the corrected solution and its profile move with the fix
                        ue, un = _turned(buf[0] - pc_e, buf[1] - pc_n, dd)
                        buf = np.stack([pc_e + ue + tx, pc_n + un + ty, buf[2]])
                        pc_e += tx
                        pc_n += ty
                        dc += dd
                        p_fix = max(fm[2], fm[3]) + fstep * fstep / 12.0
                        p_pos = p_fix
                        p_walk = 0.0
                        fix_e, fix_n = pc_e, pc_n
                        if headings > 1:
                            p_head = min(p_head, max(cm[5], dstep * dstep / 12.0))
                        out.fixes[k] = 1
        out.est[k] = pc_e, pc_n, dc
        out.var[k] = p_pos, p_pos, p_head
    return out


# --------------------------------------------------------------------------------------
# iterated EKF
# --------------------------------------------------------------------------------------
def ekf_loop_numpy(x, p, inc_d0, inc_sz, offsets, nav_up, zmap, settings):
    """Plain-numpy reference of ``ekf_loop(x, p, inc_d0, inc_sz, offsets, nav_up, zmap, settings, out)``
    (module docstring): returns (the :class:`~tanbench.filters.ekf.EkfOutputs` the loop fills, the state and
    covariance the loop leaves in ``x`` and ``p``); ``x`` and ``p`` are not changed."""
    zmap = MapArgs(*zmap)
    x = np.array(x, dtype=float)
    p = np.array(p, dtype=float)
    steps = offsets.shape[0]
    out = EkfOutputs(np.empty((steps, NX)), np.empty((steps, NX)), np.zeros(steps, dtype=np.int64))
    res = 1.0 / min(zmap.inv_re, zmap.inv_rn)
    for k in range(steps):
        if k > 0:
            x, p = ekf_predict_numpy(x, p, inc_d0[k - 1, 0], inc_d0[k - 1, 1], inc_sz[k - 1], settings.q_pos,
                                     settings.q_delta, settings.q_bias)
        x, p, nis, _ = iekf_update_numpy(x, p, offsets[k], nav_up[k], zmap, res, settings.sig_u, settings.iterations,
                                         settings.gate)
        out.rejected[k] = 1 if nis > settings.gate else 0
        out.est[k] = x
        out.var[k] = np.diag(p)
    return out, x, p


# --------------------------------------------------------------------------------------
# marginalized PF
# --------------------------------------------------------------------------------------
def mpf_loop_numpy(x, rng, track, offsets, zmap, settings):
    """Plain-numpy reference of ``mpf_loop(x, rng, track, offsets, zmap, settings, out)`` (module docstring):
    returns (the :class:`~tanbench.filters.mpf.MpfOutputs` the loop fills, the cloud the loop leaves in
    ``x``), ``rng`` advanced as the loop advances it; ``x`` is not changed."""
    inc, nav_yaw, nav_up = track
    _, model, prior, rs, div = settings
    sig_pos, q_psi, q_eps, q_b, sig_u, outside_sigma = model
    zmap = MapArgs(*zmap)
    x = np.array(x, dtype=float)
    m = x.shape[1]
    steps = offsets.shape[0]
    out = MpfOutputs(np.empty((steps, N_MPF)), np.empty((steps, N_MPF)), np.empty(steps),
                     np.zeros(steps, dtype=np.int64))
    logw = np.zeros(m)
    bad = 0
    for k in range(steps):
        if k > 0:
            check_not_wound(k, (x[PSI], nav_yaw[k - 1]))
            x = mpf_propagate_numpy(x, inc[k - 1], nav_yaw[k - 1], fill_numpy(rng, (3, m), True), sig_pos, q_psi,
                                    q_eps, q_b)
        check_not_wound(k, (x[PSI], nav_yaw[k]))
        ll, best, x = mpf_loglik_update_numpy(x, offsets[k], nav_up[k], nav_yaw[k], *zmap, sig_u, outside_sigma)
        logw = logw + ll
        w, _ = normalize_log_weights_numpy(logw)
        mean, v, _ = weighted_estimate_numpy(x, w, PSI, nav_yaw[k])
        ess = 1.0 / np.sum(w * w)
        out.est[k] = mean
        out.var[k] = v
        out.ess[k] = ess
        if best < np.inf:
            bad = bad + 1 if best > div.sigma * div.sigma else 0
        if bad >= div.steps:
            x = init_mpf_numpy(x, rng, mean[E], mean[N], nav_yaw[k], *prior)
            logw = np.zeros(m)
            bad = 0
            out.reinit[k] = 1
            continue
        x, logw = resample_and_regularise_numpy(x, w, logw, ess, loop_draw(rng), rs, 3,
                                                 math.sqrt(v[E] + v[N]))
    return out, x

