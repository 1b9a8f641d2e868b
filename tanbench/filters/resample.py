"""Weights and resampling: log-sum-exp normalisation, ESS, four resampling schemes, roughening.

Each scheme maps normalised weights and uniform draws (supplied by the caller, so the
jitted kernels and their numpy references see the same random numbers) to ancestor
indices:

* multinomial (Algorithm 1, lines 8-11): M independent uniforms, each an index by inverse CDF;
* systematic (default): one uniform u, points (u + k) / M;
* stratified: one uniform per stratum, points (u_k + k) / M;
* residual: floor(M w_k) copies of each particle, the rest multinomially on the residuals.

After resampling, duplicated particles are spread out again (regularisation), above all
in the states with zero or tiny process noise (gyro biases, heading):

* ``shrink_jitter`` (default, Liu & West 2001): x <- a x + (1 - a) mean + h std N(0, 1)
  with a = sqrt(1 - h^2), which keeps the cloud's mean and variance unchanged. A
  weakly observable bias (the x gyro's, whose heading effect scales with sin(roll)) is
  then neither collapsed nor inflated;
* ``roughen`` (Gordon et al. 1993): x <- x + K range M^(-1/d) N(0, 1). It adds variance
  at every resampling and, for a state the measurements barely constrain, the range
  grows geometrically; it is kept for comparison.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters.rng import resampling_draws
from tanbench.options import REGULARISATION, RESAMPLING

SYSTEMATIC, MULTINOMIAL, STRATIFIED, RESIDUAL = (RESAMPLING[k] for k in ("systematic", "multinomial",
                                                                         "stratified", "residual"))
REG_NONE, REG_LIU_WEST, REG_GORDON = (REGULARISATION[k] for k in ("none", "liu-west", "gordon"))


@nb.njit(cache=True)
def max_log_weight(logw):
    """The largest log-weight (-inf for none; NaN entries are passed over)."""
    mx = -np.inf
    for j in range(logw.shape[0]):
        if logw[j] > mx:
            mx = logw[j]
    return mx


@nb.njit(cache=True)
def exp_weights(logw, mx, w):
    """Unnormalised weights ``w = exp(logw - mx)``; returns their sum."""
    total = 0.0
    for j in range(logw.shape[0]):
        w[j] = math.exp(logw[j] - mx)
        total += w[j]
    return total


@nb.njit(cache=True)
def normalize_log_weights(logw, w):
    """Normalised weights into ``w`` from log-weights; returns log of the mean likelihood."""
    mx = max_log_weight(logw)
    total = exp_weights(logw, mx, w)
    for j in range(logw.shape[0]):
        w[j] /= total
    return mx + math.log(total / logw.shape[0])


@nb.njit(cache=True)
def normalise_with_ess(logw, mx, w):
    """:func:`normalize_log_weights` into ``w`` given the largest log-weight ``mx``, with the
    :func:`effective_sample_size` of the result (returned) computed in the dividing pass:
    the same numbers as the two kernels, in two passes instead of four."""
    total = exp_weights(logw, mx, w)
    sum_sq = 0.0
    for j in range(logw.shape[0]):
        w[j] /= total
        sum_sq += w[j] * w[j]
    return 1.0 / sum_sq


@nb.njit(cache=True)
def add_log_weights(logw, ll):
    """``logw += ll``; returns the largest log-weight (as :func:`max_log_weight`)."""
    mx = -np.inf
    for j in range(logw.shape[0]):
        logw[j] += ll[j]
        if logw[j] > mx:
            mx = logw[j]
    return mx


def normalize_log_weights_numpy(logw):
    """Plain-numpy reference: (normalised weights, log mean likelihood)."""
    mx = logw.max()
    w = np.exp(logw - mx)
    total = w.sum()
    return w / total, mx + math.log(total / logw.size)


@nb.njit(cache=True)
def effective_sample_size(w):
    """1 / sum(w^2) of normalised weights."""
    s = 0.0
    for j in range(w.shape[0]):
        s += w[j] * w[j]
    return 1.0 / s


@nb.njit(cache=True)
def _sweep(w, points, idx):
    """Ancestors for sorted ``points`` in [0, 1) by one pass over the cumulative weights."""
    m = w.shape[0]
    c = w[0]
    i = 0
    for k in range(points.shape[0]):
        while points[k] > c and i < m - 1:
            i += 1
            c += w[i]
        idx[k] = i


@nb.njit(cache=True)
def resample_indices(scheme, w, uniforms, idx):
    """Ancestor indices into ``idx`` (M,) for weights ``w`` using ``uniforms`` (M,) in [0, 1)."""
    m = w.shape[0]
    points = np.empty(m)
    if scheme == SYSTEMATIC:
        for k in range(m):
            points[k] = (uniforms[0] + k) / m
        _sweep(w, points, idx)
    elif scheme == STRATIFIED:
        for k in range(m):
            points[k] = (uniforms[k] + k) / m
        _sweep(w, points, idx)
    elif scheme == MULTINOMIAL:
        cdf = np.cumsum(w)
        cdf[m - 1] = 1.0
        for k in range(m):
            idx[k] = min(np.searchsorted(cdf, uniforms[k], side="right"), m - 1)
    else:  # residual
        k = 0
        resid = np.empty(m)
        for i in range(m):
            copies = int(math.floor(m * w[i]))
            for _ in range(copies):
                idx[k] = i
                k += 1
            resid[i] = m * w[i] - copies
        rest = m - k
        if rest > 0:
            cdf = np.cumsum(resid)
            total = cdf[m - 1]
            for r in range(rest):
                idx[k + r] = min(np.searchsorted(cdf, uniforms[r] * total, side="right"), m - 1)


def resample_indices_numpy(scheme, w, uniforms):
    """Plain-numpy reference of :func:`resample_indices`."""
    m = w.size
    cdf = np.cumsum(w)
    if scheme in (SYSTEMATIC, STRATIFIED):
        points = (uniforms[0] + np.arange(m)) / m if scheme == SYSTEMATIC else (uniforms + np.arange(m)) / m
        return np.minimum(np.searchsorted(cdf, points, side="left"), m - 1)
    if scheme == MULTINOMIAL:
        cdf[-1] = 1.0
        return np.minimum(np.searchsorted(cdf, uniforms, side="right"), m - 1)
    copies = np.floor(m * w).astype(np.int64)
    idx = np.repeat(np.arange(m), copies)
    rest = m - idx.size
    resid = m * w - copies
    rcdf = np.cumsum(resid)
    extra = np.minimum(np.searchsorted(rcdf, uniforms[:rest] * rcdf[-1], side="right"), m - 1)
    return np.concatenate([idx, extra])


@nb.njit(cache=True)
def apply_resample(x, idx, scratch):
    """Replace the rows of ``x`` by ``x[idx]`` (``scratch`` is a same-shaped buffer)."""
    for k in range(idx.shape[0]):
        for c in range(x.shape[1]):
            scratch[k, c] = x[idx[k], c]
    for k in range(x.shape[0]):
        for c in range(x.shape[1]):
            x[k, c] = scratch[k, c]


@nb.njit(cache=True)
def roughen(x, cols, k_rough, dim, noise):
    """Add N(0, (K * range * M^(-1/dim))^2) to columns ``cols``; ``noise`` (M, len(cols))."""
    m = x.shape[0]
    factor = k_rough * m ** (-1.0 / dim)
    for ci in range(cols.shape[0]):
        c = cols[ci]
        lo = np.inf
        hi = -np.inf
        for j in range(m):
            v = x[j, c]
            if v < lo:
                lo = v
            if v > hi:
                hi = v
        s = factor * (hi - lo)
        for j in range(m):
            x[j, c] += s * noise[j, ci]


def roughen_numpy(x, cols, k_rough, dim, noise):
    """Plain-numpy reference of :func:`roughen` (returns a new array)."""
    x = x.copy()
    spread = x[:, cols].max(axis=0) - x[:, cols].min(axis=0)
    x[:, cols] += k_rough * x.shape[0] ** (-1.0 / dim) * spread * noise
    return x


@nb.njit(cache=True)
def shrink_jitter(x, cols, h, noise):
    """Liu-West kernel jitter of columns ``cols``: mean and variance preserving; ``noise`` (M, len(cols))."""
    m = x.shape[0]
    a = math.sqrt(1.0 - h * h)
    for ci in range(cols.shape[0]):
        c = cols[ci]
        mean = 0.0
        for j in range(m):
            mean += x[j, c]
        mean /= m
        var = 0.0
        for j in range(m):
            var += (x[j, c] - mean) ** 2
        s = h * math.sqrt(var / m)
        for j in range(m):
            x[j, c] = a * x[j, c] + (1.0 - a) * mean + s * noise[j, ci]


def shrink_jitter_numpy(x, cols, h, noise):
    """Plain-numpy reference of :func:`shrink_jitter` (returns a new array)."""
    x = x.copy()
    v = x[:, cols]
    a = math.sqrt(1.0 - h * h)
    x[:, cols] = a * v + (1 - a) * v.mean(axis=0) + h * v.std(axis=0) * noise
    return x


@nb.njit(cache=True)
def regularise(x, rng, kind, cols, size, dim):
    """Draw the jitter from ``rng`` and apply ``shrink_jitter`` (h = size) or ``roughen`` (K = size)."""
    if kind == REG_NONE:
        return
    noise = np.empty((x.shape[0], cols.shape[0]))
    for j in range(x.shape[0]):
        for c in range(cols.shape[0]):
            noise[j, c] = rng.standard_normal()
    if kind == REG_LIU_WEST:
        shrink_jitter(x, cols, size, noise)
    else:
        roughen(x, cols, size, dim, noise)


@nb.njit(cache=True)
def resample_and_regularise(x, w, logw, ess, rng, rs, dim, spread, uni, idx, scratch):
    """The end of an update, shared by the filters: keep log-weights bounded; if the ESS is
    below ``rs.ess_threshold * M`` resample, regularise ``rs.cols`` and, if the horizontal
    cloud (columns 0 and 1, std ``spread``) has collapsed below ``rs.min_spread``, re-spread
    it. ``rs`` is a :class:`tanbench.filters.params.Resampling`."""
    m = x.shape[0]
    mx = logw.max()
    for j in range(m):
        logw[j] -= mx
    if ess >= rs.ess_threshold * m:
        return
    for j in range(resampling_draws(rng, rs.scheme == SYSTEMATIC, m)):
        uni[j] = rng.random()
    resample_indices(rs.scheme, w, uni, idx)
    apply_resample(x, idx, scratch)
    regularise(x, rng, rs.kind, rs.cols, rs.size, dim)
    logw[:] = 0.0
    if spread < rs.min_spread:
        s = rs.min_spread / math.sqrt(2.0)
        for j in range(m):
            x[j, 0] += s * rng.standard_normal()
            x[j, 1] += s * rng.standard_normal()
