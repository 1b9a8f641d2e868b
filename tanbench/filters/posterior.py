"""Regularisation sized to the posterior (issue 24, docs/filters.md section 5 item 2).

After resampling, the regularised rows (E, N, yaw and the two gyro biases by default) are
jittered with a Gaussian kernel whose covariance is h^2 Sigma, Sigma the cloud's weighted
covariance *before* the resampling (correlations included), shrunk towards the cloud's
mean so that the cloud's mean and covariance are kept (the Liu-West shrinkage of
``resample.shrink_jitter``, with the full covariance instead of each row's variance):

    x_r <- a x_r + (1 - a) mean_r + h (L z)_r,   L L^T = Sigma,   a = sqrt(1 - h^2),

h = bandwidth * h_opt, h_opt = (4 / ((d + 2) M))^(1 / (d + 4)) the Gaussian kernel's
optimal width (Musso, Oudjane & Le Gland 2001), d the number of regularised rows, M the
particles. The prototypes (docs/filters.md 4.3) settled on bandwidth 0.5: at h_opt every
particle is pulled 8 % towards the mean per resampling at 2000 particles, which merges the
modes of a multimodal cloud; at half of it, 2 %.

The yaw row's deviations are wrapped about a reference (the cloud's mean heading), as in
``estimate.weighted_estimate``; the shrinkage moves each particle's yaw by the wrapped
difference to the mean, so a particle's unwrapped yaw never jumps by 2 pi.

Kernels: :func:`weighted_covariance`, :func:`cholesky_small`, :func:`shrink_jitter_full`
and the end of an update that strings them together, :func:`resample_posterior`; each with
a plain-numpy reference (``*_numpy``) the tests check.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters.estimate import _wrap
from tanbench.filters.resample import SYSTEMATIC, _add_scaled, _shift_log_weights, gather_columns, resample_indices
from tanbench.filters.rng import fill_normals, fill_uniforms

REG_POSTERIOR = 3  # the Resampling bundle's kernel code (after options.REGULARISATION's)


def posterior_bandwidth(d: int, m: int, factor: float) -> float:
    """h = factor * (4 / ((d + 2) m))^(1 / (d + 4)), capped below 1 (the shrinkage needs h < 1)."""
    return min(factor * (4.0 / ((d + 2) * m)) ** (1.0 / (d + 4)), 0.999)


@nb.njit(cache=True)
def posterior_bandwidth_jit(d, m, factor):
    """:func:`posterior_bandwidth` for the jitted loops."""
    return min(factor * (4.0 / ((d + 2) * m)) ** (1.0 / (d + 4)), 0.999)


@nb.njit(cache=True)
def weighted_covariance(x, rows, w, yaw_row, yaw_ref, mean, cov):
    """Weighted mean (into ``mean`` (d,)) and covariance (``cov`` (d, d)) of rows ``rows`` of
    ``x`` (nrows, M) under normalised weights ``w``; the row ``yaw_row`` (if among ``rows``)
    as an angle: deviations from ``yaw_ref`` wrapped, the mean unwrapped about it.

    Deviations are taken about the first particle (the yaw row about ``yaw_ref``), which keeps
    the sums small at map coordinates, as in ``estimate.weighted_estimate``."""
    d = rows.shape[0]
    m = x.shape[1]
    ref = np.empty(d)
    dev = np.empty(d)
    for i in range(d):
        ref[i] = yaw_ref if rows[i] == yaw_row else x[rows[i], 0]
        mean[i] = 0.0
        for k in range(d):
            cov[i, k] = 0.0
    for j in range(m):
        wj = w[j]
        for i in range(d):
            v = x[rows[i], j] - ref[i]
            dev[i] = _wrap(v) if rows[i] == yaw_row else v
            mean[i] += wj * dev[i]
        for i in range(d):
            for k in range(i + 1):
                cov[i, k] += wj * dev[i] * dev[k]
    for i in range(d):
        for k in range(i + 1):
            c = cov[i, k] - mean[i] * mean[k]
            cov[i, k] = c
            cov[k, i] = c
        cov[i, i] = max(cov[i, i], 0.0)
    for i in range(d):
        mean[i] += ref[i]


def weighted_covariance_numpy(x, rows, w, yaw_row, yaw_ref):
    """Plain-numpy reference of :func:`weighted_covariance`: (mean, cov)."""
    rows = np.asarray(rows)
    ref = np.array([yaw_ref if r == yaw_row else x[r, 0] for r in rows])
    dev = x[rows] - ref[:, None]
    for i, r in enumerate(rows):
        if r == yaw_row:
            dev[i] = (dev[i] + np.pi) % (2 * np.pi) - np.pi
    mu = dev @ w
    cov = (dev * w) @ dev.T - np.outer(mu, mu)
    np.fill_diagonal(cov, np.maximum(np.diag(cov), 0.0))
    return mu + ref, cov


@nb.njit(cache=True)
def cholesky_small(cov, out):
    """Lower Cholesky factor of ``cov`` (d, d) into ``out``; where ``cov`` is not positive
    definite (a collapsed row, rounding), the diagonal factor sqrt(diag) instead. Returns
    True if the full factor was used."""
    d = cov.shape[0]
    for i in range(d):
        for k in range(d):
            out[i, k] = 0.0
    ok = True
    for i in range(d):
        for k in range(i + 1):
            s = cov[i, k]
            for p in range(k):
                s -= out[i, p] * out[k, p]
            if i == k:
                if not s > 1e-300:
                    ok = False
                    break
                out[i, i] = math.sqrt(s)
            else:
                out[i, k] = s / out[k, k]
        if not ok:
            break
    if not ok:
        for i in range(d):
            for k in range(d):
                out[i, k] = 0.0
            out[i, i] = math.sqrt(max(cov[i, i], 0.0))
    return ok


def cholesky_small_numpy(cov):
    """Plain-numpy reference of :func:`cholesky_small`: (factor, full factor used)."""
    try:
        return np.linalg.cholesky(cov), True
    except np.linalg.LinAlgError:
        return np.diag(np.sqrt(np.maximum(np.diag(cov), 0.0))), False


@nb.njit(cache=True)
def shrink_jitter_full(x, rows, yaw_row, mean, chol, h, noise):
    """x_r <- a x_r + (1 - a) mean_r + h (L z)_r on rows ``rows`` (a = sqrt(1 - h^2), ``chol``
    = L, ``noise`` = z (d, M) standard normals); the yaw row moves by the wrapped difference."""
    d = rows.shape[0]
    m = x.shape[1]
    a = math.sqrt(1.0 - h * h)
    for i in range(d):
        row = x[rows[i]]
        angle = rows[i] == yaw_row
        mu = mean[i]
        for j in range(m):
            s = 0.0
            for k in range(i + 1):
                s += chol[i, k] * noise[k, j]
            diff = _wrap(mu - row[j]) if angle else mu - row[j]
            row[j] = row[j] + (1.0 - a) * diff + h * s


def shrink_jitter_full_numpy(x, rows, yaw_row, mean, chol, h, noise):
    """Plain-numpy reference of :func:`shrink_jitter_full` (returns a new array)."""
    x = x.copy()
    rows = np.asarray(rows)
    a = math.sqrt(1.0 - h * h)
    jitter = h * (np.asarray(chol) @ noise)
    for i, r in enumerate(rows):
        diff = mean[i] - x[r]
        if r == yaw_row:
            diff = (diff + np.pi) % (2 * np.pi) - np.pi
        x[r] = x[r] + (1.0 - a) * diff + jitter[i]
    return x


@nb.njit(cache=True)
def resample_posterior(x, w, logw, ess, rng, rs, yaw_row, yaw_ref, spread, uni, idx, scratch):
    """The end of an update with the posterior-sized kernel (``rs.kind`` posterior, ``rs.size``
    the bandwidth factor on h_opt): as ``resample.resample_and_regularise``, but the
    regularisation's covariance is the weighted one of the cloud before resampling, and the
    jitter is correlated (:func:`shrink_jitter_full`). Random numbers: the resampling's
    uniforms, then one block of (d, M) normals, then (if the cloud is below ``rs.min_spread``)
    the re-spread's two rows."""
    m = x.shape[1]
    _shift_log_weights(logw)
    if ess >= rs.ess_threshold * m:
        return
    resample_posterior_into(x, w, rng, rs, yaw_row, yaw_ref, spread, uni, idx, scratch, x)
    logw[:] = 0.0


@nb.njit(cache=True)
def resample_posterior_into(x, w, rng, rs, yaw_row, yaw_ref, spread, uni, idx, scratch, out):
    """:func:`resample_posterior`'s resampling and jitter, whatever the ESS, into ``out`` (rows, n): n =
    ``idx.shape[0]`` draws from the M columns of ``x`` under weights ``w`` (n = M, and ``out`` ``x`` itself,
    but for an adaptive count, ``filters/kld.py``; ``out`` may then share ``x``'s memory: every draw is
    gathered into ``scratch`` (rows, n) before ``out`` is written). The kernel's width is h_opt for n."""
    n = idx.shape[0]
    d = rs.cols.shape[0]
    mean = np.empty(d)
    cov = np.empty((d, d))
    chol = np.empty((d, d))
    weighted_covariance(x, rs.cols, w, yaw_row, yaw_ref, mean, cov)
    cholesky_small(cov, chol)
    draws = uni[:1] if rs.scheme == SYSTEMATIC else uni
    fill_uniforms(rng, draws)
    resample_indices(rs.scheme, w, uni, idx)
    gather_columns(x, idx, scratch, out)
    noise = scratch[:d]
    fill_normals(rng, noise)
    shrink_jitter_full(out, rs.cols, yaw_row, mean, chol, posterior_bandwidth_jit(d, n, rs.size), noise)
    if spread < rs.min_spread:
        noise2 = scratch[:2]
        fill_normals(rng, noise2)
        s = rs.min_spread / math.sqrt(2.0)
        _add_scaled(out[0], s, noise2[0])
        _add_scaled(out[1], s, noise2[1])
