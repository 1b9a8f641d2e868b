"""Measurement likelihood (Eqs. 15-20): terrain altitude innovations of the sonar beams.

For beam i with unit vector a_i (body frame) and measured range r_i, a particle with
attitude Theta predicts the bottom at its position plus C_b^n(Theta) a_i r_i (Eqs. 15,
17); the innovation is the predicted bottom's height minus the navigation map's height
under it. Eq. 20's |R| is read as per-component variances, so

    log p(y | x) = -1/2 [ (dE^2 + dN^2) / sigma_d^2 + sum_i dU_i^2 / sigma_U^2 ] + const.

Log-likelihoods are returned, never raw likelihoods, so nothing underflows. A beam
whose footprint falls off the map (NaN) is charged ``outside_sigma`` sigmas; a beam
without a range (no bottom lock, NaN) is skipped. Each kernel returns the smallest
per-beam mean squared normalised terrain innovation over the particles, the
filter's divergence statistic.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.state import E, N, PITCH, ROLL, U, YAW
from tanbench.filters.trig import attitude_reference, particle_sin_cos
from tanbench.options import LIKELIHOOD
from tanbench.terrain.grid import bilinear, bilinear_numpy, bilinear_pair, stack_grids
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy


@nb.njit(cache=True, inline="always")
def beam_constants(sig_u, sig_d, outside_sigma):
    """(sig_u^2, 1 / sig_u^2, 1 / sig_d^2, (outside_sigma sig_u)^2, outside_sigma^2): the
    per-update constants of the likelihood kernels.

    This and the ``*_particle`` functions below are inlined into their callers and take the
    callers' floating-point flags: call them from ``fastmath=FASTMATH`` kernels only (the
    array kernels here and the filter loops' fused passes), so that the fused passes
    compute exactly what the array kernels compute."""
    su2 = sig_u * sig_u
    return su2, 1.0 / su2, 1.0 / (sig_d * sig_d), (outside_sigma * sig_u) ** 2, outside_sigma * outside_sigma


@nb.njit(cache=True, inline="always")
def _particle_dcm(x, j, att):
    """C_b^n of particle ``j``'s attitude, each angle as the reference ``att`` plus an offset."""
    st, ct, sg, cg, sp, cp = particle_sin_cos(x, j, att)
    return (cg * cp - st * sg * sp, -ct * sp, sg * cp + st * cg * sp,
            cg * sp + st * sg * cp, ct * cp, sg * sp - st * cg * cp,
            -ct * sg, st, ct * cg)


@nb.njit(cache=True, inline="always")
def _footprint(x, j, dcm, vec, i):
    """(east, north, up) of beam ``i``'s footprint (``vec`` from :func:`beam_vectors`) seen from
    particle ``j`` with its attitude matrix ``dcm`` (:func:`_particle_dcm`)."""
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = dcm
    a0 = vec[i, 0]
    a1 = vec[i, 1]
    a2 = vec[i, 2]
    return (x[j, E] + c00 * a0 + c01 * a1 + c02 * a2,
            x[j, N] + c10 * a0 + c11 * a1 + c12 * a2,
            x[j, U] + c20 * a0 + c21 * a1 + c22 * a2)


@nb.njit(cache=True)
def beam_vectors(beams, ranges):
    """(n, 3) beam vectors times ranges, body frame, of the n beams with a range (not NaN), in
    beam order: what the per-particle kernels below loop over."""
    used = 0
    for i in range(ranges.shape[0]):
        if ranges[i] == ranges[i]:
            used += 1
    vec = np.empty((used, 3))
    k = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if r == r:
            vec[k, 0] = beams[i, 0] * r
            vec[k, 1] = beams[i, 1] * r
            vec[k, 2] = beams[i, 2] * r
            k += 1
    return vec


@nb.njit(cache=True, inline="always")
def loglik_tight_particle(x, j, vec, z, e0, n0, inv_re, inv_rn, inv_u2, outside_sq, att,
                          dist_e, dist_n, inv_d2):
    """(log-likelihood, chi^2) of particle ``j`` for :func:`loglik_tight` (and the fused filter
    loop): ``vec`` from :func:`beam_vectors`, ``att`` from :func:`attitude_reference`, ``dist_*``
    its distance innovations."""
    dcm = _particle_dcm(x, j, att)
    sq = 0.0
    for i in range(vec.shape[0]):
        pe, pn, pu = _footprint(x, j, dcm, vec, i)
        h = bilinear(z, e0, n0, inv_re, inv_rn, pe, pn)
        if h == h:
            sq += (pu - h) * (pu - h)
        else:
            sq += outside_sq
    chi = sq * inv_u2
    return -0.5 * (chi + (dist_e ** 2 + dist_n ** 2) * inv_d2), chi


@nb.njit(cache=True, fastmath=FASTMATH)
def loglik_tight(x, beams, ranges, z, e0, n0, inv_re, inv_rn, sig_u, outside_sigma,
                 dist_innov, sig_d, ref_pitch, ref_roll, ref_yaw, out):
    """Fill ``out`` (M,) with each particle's log-likelihood; return the best chi^2 per beam.

    ``ref_*`` (the navigation attitude) only speed up the trigonometry: each particle's
    angles are evaluated as reference plus a usually small offset (``trig.sin_cos_about``).
    """
    vec = beam_vectors(beams, ranges)
    used = vec.shape[0]
    _, inv_u2, inv_d2, outside_sq, _ = beam_constants(sig_u, sig_d, outside_sigma)
    att = attitude_reference(ref_pitch, ref_roll, ref_yaw)
    best = np.inf
    for j in range(x.shape[0]):
        ll, chi = loglik_tight_particle(x, j, vec, z, e0, n0, inv_re, inv_rn, inv_u2, outside_sq, att,
                                        dist_innov[j, 0], dist_innov[j, 1], inv_d2)
        if used > 0 and chi / used < best:
            best = chi / used
        out[j] = ll
    return best


def loglik_tight_numpy(x, beams, ranges, z, e0, n0, inv_re, inv_rn, sig_u, outside_sigma, dist_innov, sig_d):
    """Plain-numpy reference of :func:`loglik_tight`: returns (loglik (M,), best chi^2 per beam)."""
    c = dcm_body_to_nav_numpy(x[:, PITCH], x[:, ROLL], x[:, YAW])  # (M, 3, 3)
    ok = ~np.isnan(ranges)
    vec = beams[ok] * ranges[ok][:, None]  # (m', 3)
    p = x[:, None, [E, N, U]] + np.einsum("mij,bj->mbi", c, vec)  # (M, m', 3)
    h = bilinear_numpy(z, e0, n0, inv_re, inv_rn, p[..., 0], p[..., 1])
    sq = np.where(np.isnan(h), (outside_sigma * sig_u) ** 2, (p[..., 2] - h) ** 2).sum(axis=1)
    chi = sq / sig_u**2
    loglik = -0.5 * (chi + (dist_innov**2).sum(axis=1) / sig_d**2)
    best = (chi / ok.sum()).min() if ok.any() else np.inf
    return loglik, best


@nb.njit(cache=True)
def used_offsets(offsets):
    """The rows of beam offsets ``offsets`` (m, 3) with a range (third column not NaN), in order."""
    used = 0
    for i in range(offsets.shape[0]):
        if offsets[i, 2] == offsets[i, 2]:
            used += 1
    out = np.empty((used, 3))
    k = 0
    for i in range(offsets.shape[0]):
        if offsets[i, 2] == offsets[i, 2]:
            out[k, 0] = offsets[i, 0]
            out[k, 1] = offsets[i, 1]
            out[k, 2] = offsets[i, 2]
            k += 1
    return out


@nb.njit(cache=True, inline="always")
def loglik_loose_particle(x, j, offsets, up, z, e0, n0, inv_re, inv_rn, inv_u2, outside_sq):
    """(log-likelihood, chi^2) of particle ``j`` for :func:`loglik_loose`; ``offsets``: the
    beams with a range (:func:`used_offsets`)."""
    sq = 0.0
    for i in range(offsets.shape[0]):
        h = bilinear(z, e0, n0, inv_re, inv_rn, x[j, 0] + offsets[i, 0], x[j, 1] + offsets[i, 1])
        if h == h:
            d = up + offsets[i, 2] - h
            sq += d * d
        else:
            sq += outside_sq
    chi = sq * inv_u2
    return -0.5 * chi, chi


@nb.njit(cache=True, fastmath=FASTMATH)
def loglik_loose(x, offsets, up, z, e0, n0, inv_re, inv_rn, sig_u, outside_sigma, out):
    """Loose filter: beams projected once with the navigation attitude, ``offsets`` (m, 3) in m.

    Rows of ``offsets`` with NaN are beams without a range and are skipped.
    """
    rows = used_offsets(offsets)
    used = rows.shape[0]
    _, inv_u2, _, outside_sq, _ = beam_constants(sig_u, 1.0, outside_sigma)
    best = np.inf
    for j in range(x.shape[0]):
        ll, chi = loglik_loose_particle(x, j, rows, up, z, e0, n0, inv_re, inv_rn, inv_u2, outside_sq)
        if used > 0 and chi / used < best:
            best = chi / used
        out[j] = ll
    return best


def loglik_loose_numpy(x, offsets, up, z, e0, n0, inv_re, inv_rn, sig_u, outside_sigma):
    """Plain-numpy reference of :func:`loglik_loose`: returns (loglik (M,), best chi^2 per beam)."""
    ok = ~np.isnan(offsets[:, 2])
    o = offsets[ok]
    h = bilinear_numpy(z, e0, n0, inv_re, inv_rn, x[:, 0:1] + o[:, 0], x[:, 1:2] + o[:, 1])
    sq = np.where(np.isnan(h), (outside_sigma * sig_u) ** 2, (up + o[:, 2] - h) ** 2).sum(axis=1)
    chi = sq / sig_u**2
    best = (chi / ok.sum()).min() if ok.any() else np.inf
    return -0.5 * chi, best


# --------------------------------------------------------------------------------------
# Map-aware, robust likelihoods (docs/model.md, Section 6.3)
#
# Each beam's variance is the sonar's plus the navigation map's variance at the beam's
# footprint (``terrain/representation.py``: slope x resolution plus the declared map
# error), interpolated like the map. Because that variance depends on where a particle
# puts the footprint, its log-normaliser stays in the log-likelihood:
#
#   Gaussian:  log p = -1/2 [ d^2 / v + log(v / sigma_U^2) ]
#   Student-t: log p = -(nu + 1)/2 log(1 + d^2 / (nu v)) - 1/2 log(v / sigma_U^2)
#
# (constants dropped; with a zero variance grid the Gaussian reduces to the plain kernels
# above). The Student-t's heavy tails bound the pull of one wild range (outliers,
# multipath, fish). A footprint off the map is charged ``outside_sigma`` of its sigma.
# The divergence statistic is the mean d^2 / v per beam of the best particle.
# --------------------------------------------------------------------------------------
LIK_GAUSSIAN, LIK_STUDENT = LIKELIHOOD["gaussian"], LIKELIHOOD["student-t"]


# The jitted kernels sum the beams' log-densities as logs of products: one log per particle
# for the normalisers and one for the Student-t terms, instead of one or two per beam (the
# logs were most of the likelihood's cost). Each factor is >= 1; a product past
# PRODUCT_LOG_AT is moved into the log sum, so nothing overflows whatever the beam count.
PRODUCT_LOG_AT = 1e150


@nb.njit(cache=True, inline="always")
def _beam_terms_add(acc, q, v, inv_u2, kind, nu):
    """Add one beam (normalised squared innovation ``q`` = d^2 / v, variance ``v``) to the
    density accumulator ``acc`` = (log sum, normaliser product, Student-t product, Gaussian
    quadratic sum). The caller divides once and adds the same ``q`` to its chi^2."""
    logs, norm, student, quad = acc
    norm *= v * inv_u2
    if kind == LIK_STUDENT:
        student *= 1.0 + q * (1.0 / nu)
    else:
        quad += -0.5 * q
    if norm > PRODUCT_LOG_AT:
        logs += -0.5 * math.log(norm)
        norm = 1.0
    if student > PRODUCT_LOG_AT:
        logs += -0.5 * (nu + 1.0) * math.log(student)
        student = 1.0
    return logs, norm, student, quad


@nb.njit(cache=True, inline="always")
def _beam_terms_total(acc, kind, nu):
    """The sum of the beams' log-densities (constants dropped) from the accumulator."""
    logs, norm, student, quad = acc
    total = logs - 0.5 * math.log(norm) + quad
    if kind == LIK_STUDENT:
        total += -0.5 * (nu + 1.0) * math.log(student)
    return total


def _beam_logpdf_numpy(d2, v, sig_u, kind, nu):
    norm = -0.5 * np.log(v / sig_u**2)
    if kind == LIK_STUDENT:
        return -0.5 * (nu + 1.0) * np.log1p(d2 / (nu * v)) + norm
    return -0.5 * d2 / v + norm


@nb.njit(cache=True, inline="always")
def loglik_tight_mapaware_particle(x, j, vec, zv, e0, n0, inv_re, inv_rn, su2, inv_u2, out2, att,
                                   kind, nu, dist_e, dist_n, inv_d2):
    """(log-likelihood, sum of d^2 / v) of particle ``j`` for :func:`loglik_tight_mapaware`;
    ``zv``: the map and its variance grid interleaved (``grid.stack_grids``)."""
    dcm = _particle_dcm(x, j, att)
    acc = (0.0, 1.0, 1.0, 0.0)
    chi = 0.0
    for i in range(vec.shape[0]):
        pe, pn, pu = _footprint(x, j, dcm, vec, i)
        h, mv = bilinear_pair(zv, e0, n0, inv_re, inv_rn, pe, pn)
        if h == h and mv == mv:
            v = su2 + mv
            q = (pu - h) * (pu - h) / v
            acc = _beam_terms_add(acc, q, v, inv_u2, kind, nu)
            chi += q
        else:
            acc = _beam_terms_add(acc, out2, su2, inv_u2, kind, nu)
            chi += out2
    return _beam_terms_total(acc, kind, nu) - 0.5 * (dist_e ** 2 + dist_n ** 2) * inv_d2, chi


@nb.njit(cache=True)
def loglik_tight_mapaware(x, beams, ranges, z, mvar, e0, n0, inv_re, inv_rn, sig_u, outside_sigma,
                          dist_innov, sig_d, ref_pitch, ref_roll, ref_yaw, kind, nu, out):
    """:func:`loglik_tight` with per-beam variance ``sig_u^2 + mvar`` at the footprint and a
    Gaussian or Student-t beam density; returns the best mean d^2 / v per beam.

    ``mvar`` has the shape and nodes of ``z``; the grids are interleaved first
    (:func:`loglik_tight_mapaware_stacked` takes them so, as the filter loop does once per run).
    """
    return loglik_tight_mapaware_stacked(x, beams, ranges, stack_grids(z, mvar), e0, n0, inv_re, inv_rn, sig_u,
                                         outside_sigma, dist_innov, sig_d, ref_pitch, ref_roll, ref_yaw, kind, nu, out)


@nb.njit(cache=True, fastmath=FASTMATH)
def loglik_tight_mapaware_stacked(x, beams, ranges, zv, e0, n0, inv_re, inv_rn, sig_u, outside_sigma,
                                  dist_innov, sig_d, ref_pitch, ref_roll, ref_yaw, kind, nu, out):
    """:func:`loglik_tight_mapaware` on the interleaved map and variance grid ``zv``."""
    vec = beam_vectors(beams, ranges)
    used = vec.shape[0]
    su2, inv_u2, inv_d2, _, out2 = beam_constants(sig_u, sig_d, outside_sigma)
    att = attitude_reference(ref_pitch, ref_roll, ref_yaw)
    best = np.inf
    for j in range(x.shape[0]):
        ll, chi = loglik_tight_mapaware_particle(x, j, vec, zv, e0, n0, inv_re, inv_rn, su2, inv_u2,
                                                 out2, att, kind, nu, dist_innov[j, 0], dist_innov[j, 1], inv_d2)
        if used > 0 and chi / used < best:
            best = chi / used
        out[j] = ll
    return best


def loglik_tight_mapaware_numpy(x, beams, ranges, z, mvar, e0, n0, inv_re, inv_rn, sig_u, outside_sigma,
                                dist_innov, sig_d, kind, nu):
    """Plain-numpy reference of :func:`loglik_tight_mapaware`: (loglik (M,), best)."""
    c = dcm_body_to_nav_numpy(x[:, PITCH], x[:, ROLL], x[:, YAW])
    ok = ~np.isnan(ranges)
    vec = beams[ok] * ranges[ok][:, None]
    p = x[:, None, [E, N, U]] + np.einsum("mij,bj->mbi", c, vec)
    return _mapaware_terms(p[..., 0], p[..., 1], p[..., 2], z, mvar, e0, n0, inv_re, inv_rn, sig_u,
                           outside_sigma, kind, nu, ok.sum(), (dist_innov**2).sum(axis=1) / sig_d**2)


def _mapaware_terms(pe, pn, pu, z, mvar, e0, n0, inv_re, inv_rn, sig_u, outside_sigma, kind, nu, used, dist_chi):
    h = bilinear_numpy(z, e0, n0, inv_re, inv_rn, pe, pn)
    mv = bilinear_numpy(mvar, e0, n0, inv_re, inv_rn, pe, pn)
    off = np.isnan(h) | np.isnan(mv)
    v = np.where(off, sig_u**2, sig_u**2 + np.nan_to_num(mv))
    d2 = np.where(off, outside_sigma**2 * sig_u**2, (pu - np.nan_to_num(h)) ** 2)
    ll = _beam_logpdf_numpy(d2, v, sig_u, kind, nu).sum(axis=1)
    chi = (d2 / v).sum(axis=1)
    best = (chi / used).min() if used else np.inf
    return ll - 0.5 * dist_chi, best


@nb.njit(cache=True, inline="always")
def loglik_loose_mapaware_particle(x, j, offsets, up, zv, e0, n0, inv_re, inv_rn, su2, inv_u2, out2, kind, nu):
    """(log-likelihood, sum of d^2 / v) of particle ``j`` for :func:`loglik_loose_mapaware`
    (``zv`` as in :func:`loglik_tight_mapaware_particle`)."""
    acc = (0.0, 1.0, 1.0, 0.0)
    chi = 0.0
    for i in range(offsets.shape[0]):
        pe = x[j, 0] + offsets[i, 0]
        pn = x[j, 1] + offsets[i, 1]
        h, mv = bilinear_pair(zv, e0, n0, inv_re, inv_rn, pe, pn)
        if h == h and mv == mv:
            v = su2 + mv
            d = up + offsets[i, 2] - h
            q = d * d / v
            acc = _beam_terms_add(acc, q, v, inv_u2, kind, nu)
            chi += q
        else:
            acc = _beam_terms_add(acc, out2, su2, inv_u2, kind, nu)
            chi += out2
    return _beam_terms_total(acc, kind, nu), chi


@nb.njit(cache=True)
def loglik_loose_mapaware(x, offsets, up, z, mvar, e0, n0, inv_re, inv_rn, sig_u, outside_sigma, kind, nu, out):
    """:func:`loglik_loose` with the map-aware variance and a Gaussian or Student-t beam density
    (``mvar`` on the nodes of ``z``; interleaved first, as in :func:`loglik_tight_mapaware`)."""
    return loglik_loose_mapaware_stacked(x, offsets, up, stack_grids(z, mvar), e0, n0, inv_re, inv_rn, sig_u,
                                         outside_sigma, kind, nu, out)


@nb.njit(cache=True, fastmath=FASTMATH)
def loglik_loose_mapaware_stacked(x, offsets, up, zv, e0, n0, inv_re, inv_rn, sig_u, outside_sigma, kind, nu, out):
    """:func:`loglik_loose_mapaware` on the interleaved map and variance grid ``zv``."""
    rows = used_offsets(offsets)
    used = rows.shape[0]
    su2, inv_u2, _, _, out2 = beam_constants(sig_u, 1.0, outside_sigma)
    best = np.inf
    for j in range(x.shape[0]):
        ll, chi = loglik_loose_mapaware_particle(x, j, rows, up, zv, e0, n0, inv_re, inv_rn, su2, inv_u2,
                                                 out2, kind, nu)
        if used > 0 and chi / used < best:
            best = chi / used
        out[j] = ll
    return best


def loglik_loose_mapaware_numpy(x, offsets, up, z, mvar, e0, n0, inv_re, inv_rn, sig_u, outside_sigma, kind, nu):
    """Plain-numpy reference of :func:`loglik_loose_mapaware`: (loglik (M,), best)."""
    ok = ~np.isnan(offsets[:, 2])
    o = offsets[ok]
    pe = x[:, 0:1] + o[:, 0]
    pn = x[:, 1:2] + o[:, 1]
    pu = np.broadcast_to(up + o[:, 2], pe.shape)
    return _mapaware_terms(pe, pn, pu, z, mvar, e0, n0, inv_re, inv_rn, sig_u, outside_sigma, kind, nu,
                           ok.sum(), np.zeros(x.shape[0]))
