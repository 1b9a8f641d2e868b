"""Weights and resampling: log-sum-exp normalisation, ESS, four resampling schemes, roughening.

Particles are the columns of ``x`` (a row per state). Sums run over four interleaved
accumulators added in a fixed order (``estimate.py`` says why); the exponentials are
``vecmath.exp_nonpositive``, so the weight loops compile to SIMD instructions.

Each scheme maps normalised weights and uniform draws (supplied by the caller, so the
jitted kernels and their numpy references see the same random numbers) to ancestor
indices:

* multinomial (Algorithm 1, lines 8-11): M independent uniforms, each an index by inverse CDF;
  the M uniforms are turned into their order statistics directly (Bentley & Saxe 1980:
  the largest is U^(1/M), each next the previous times U^(1/k)), so one pass over the
  cumulative weights serves them all, as for the systematic scheme (a binary search per
  uniform cost a dozen mispredicted branches per particle);
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
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.rng import fill_normals, fill_uniforms
from tanbench.filters.vecmath import exp_nonpositive, lane_first_max, lane_sums, lane_sums_sq, log_positive
from tanbench.options import REGULARISATION, RESAMPLING

# resampling when ESS < ess_threshold * M, then regularisation of ``cols`` with kernel
# ``kind`` of size ``size``; a horizontal cloud below ``min_spread`` m std is re-spread
Resampling = namedtuple("Resampling", "scheme ess_threshold kind cols size min_spread")


def resampling_of(f, regularised_cols: np.ndarray) -> Resampling:
    """The :class:`Resampling` bundle of a ``FilterSpec`` ``f`` (its regularised state rows ``regularised_cols``)."""
    size = f.roughening if f.regularisation == "gordon" else f.regularisation_h
    return Resampling(RESAMPLING[f.resampling], f.ess_threshold, REGULARISATION[f.regularisation],
                      regularised_cols, size, f.min_spread_m)

SYSTEMATIC, MULTINOMIAL, STRATIFIED, RESIDUAL = (RESAMPLING[k] for k in ("systematic", "multinomial",
                                                                         "stratified", "residual"))
REG_NONE, REG_LIU_WEST, REG_GORDON = (REGULARISATION[k] for k in ("none", "liu-west", "gordon"))


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _finish_sum(s0, s1, s2, s3, a, m4, square):
    """Four chains' sums of a (or a^2) with the elements after the first ``m4`` added to chain 0,
    then the chains added in the fixed order."""
    for j in range(m4, a.shape[0]):
        s0 += a[j] * a[j] if square else a[j]
    return (s0 + s1) + (s2 + s3)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def sum4(a):
    """sum(a) over four interleaved accumulators, added in a fixed order: the accumulators are the
    lanes of ``vecmath.lane_sums`` (the same bits as :func:`sum4_scalar`)."""
    m4 = a.shape[0] - a.shape[0] % 4
    s0, s1, s2, s3 = lane_sums(a, m4 // 4)
    return _finish_sum(s0, s1, s2, s3, a, m4, False)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def sum_sq4(a):
    """sum(a^2), as :func:`sum4` (``vecmath.lane_sums_sq``; the same bits as :func:`sum_sq4_scalar`)."""
    m4 = a.shape[0] - a.shape[0] % 4
    s0, s1, s2, s3 = lane_sums_sq(a, m4 // 4)
    return _finish_sum(s0, s1, s2, s3, a, m4, True)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def sum4_scalar(a):
    """:func:`sum4` as four scalar chains (the tests' check of the lanes)."""
    m4 = a.shape[0] - a.shape[0] % 4
    s0 = s1 = s2 = s3 = 0.0
    for j in range(0, m4, 4):
        s0 += a[j]
        s1 += a[j + 1]
        s2 += a[j + 2]
        s3 += a[j + 3]
    return _finish_sum(s0, s1, s2, s3, a, m4, False)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def sum_sq4_scalar(a):
    """:func:`sum_sq4` as four scalar chains (the tests' check of the lanes)."""
    m4 = a.shape[0] - a.shape[0] % 4
    s0 = s1 = s2 = s3 = 0.0
    for j in range(0, m4, 4):
        s0 += a[j] * a[j]
        s1 += a[j + 1] * a[j + 1]
        s2 += a[j + 2] * a[j + 2]
        s3 += a[j + 3] * a[j + 3]
    return _finish_sum(s0, s1, s2, s3, a, m4, True)


@nb.njit(cache=True)
def max_log_weight(logw):
    """The largest log-weight (-inf for none; NaN entries are passed over): the first occurrence in index
    order, as :func:`max_log_weight_scalar` finds it (which matters only for the sign of a zero), from
    the four lanes of ``vecmath.lane_first_max``."""
    m4 = logw.shape[0] - logw.shape[0] % 4
    m0, m1, m2, m3, j0, j1, j2, j3 = lane_first_max(logw, m4 // 4)
    mx, at = m0, j0
    for m, j in ((m1, j1), (m2, j2), (m3, j3)):
        if m > mx or (m == mx and j < at):
            mx, at = m, j
    for j in range(m4, logw.shape[0]):
        if logw[j] > mx:
            mx = logw[j]
    return mx


@nb.njit(cache=True)
def max_log_weight_scalar(logw):
    """:func:`max_log_weight` element by element (the tests' check of the lanes)."""
    mx = -np.inf
    for j in range(logw.shape[0]):
        if logw[j] > mx:
            mx = logw[j]
    return mx


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def exp_weights(logw, mx, w):
    """Unnormalised weights ``w = exp(logw - mx)``; returns their sum."""
    for j in range(logw.shape[0]):
        w[j] = exp_nonpositive(logw[j] - mx)
    return sum4(w)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _divide(w, total):
    inv = 1.0 / total
    for j in range(w.shape[0]):
        w[j] *= inv


@nb.njit(cache=True)
def normalize_log_weights(logw, w):
    """Normalised weights into ``w`` from log-weights; returns log of the mean likelihood."""
    mx = max_log_weight(logw)
    total = exp_weights(logw, mx, w)
    _divide(w, total)
    return mx + math.log(total / logw.shape[0])


@nb.njit(cache=True)
def normalise_with_ess(logw, mx, w):
    """:func:`normalize_log_weights` into ``w`` given the largest log-weight ``mx``; returns the
    :func:`effective_sample_size` of the result."""
    total = exp_weights(logw, mx, w)
    _divide(w, total)
    return effective_sample_size(w)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _add(logw, ll):
    for j in range(logw.shape[0]):
        logw[j] += ll[j]


@nb.njit(cache=True)
def add_log_weights(logw, ll):
    """``logw += ll``; returns the largest log-weight (as :func:`max_log_weight`)."""
    _add(logw, ll)
    return max_log_weight(logw)


def normalize_log_weights_numpy(logw):
    """Plain-numpy reference: (normalised weights, log mean likelihood)."""
    mx = logw.max()
    w = np.exp(logw - mx)
    total = w.sum()
    return w / total, mx + math.log(total / logw.size)


@nb.njit(cache=True)
def effective_sample_size(w):
    """1 / sum(w^2) of normalised weights."""
    return 1.0 / sum_sq4(w)


@nb.njit(cache=True)
def _sweep(w, points, idx):
    """Ancestors for sorted ``points`` in [0, 1): the first particle whose cumulative weight
    reaches each point, by one merge of the points with the cumulative weights. Each step
    either assigns the next point (to particle ``i``) or moves to the next particle, by
    arithmetic rather than a branch: which of the two happens is as random as the weights,
    and a mispredicted branch per particle cost more than the rest of the resampling."""
    m = w.shape[0]
    n = points.shape[0]
    c = w[0]
    i = 0
    k = 0
    while k < n:
        take = (points[k] <= c) | (i == m - 1)
        idx[k] = i
        k += 1 if take else 0
        step = 0 if take else 1
        i += step
        c += w[min(i, m - 1)] if step else 0.0



@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def sorted_uniforms(u, out):
    """The order statistics (ascending) of m uniforms in [0, 1), made from the m uniforms ``u``:
    out[k] = prod_{i >= k} V_i^(1 / (i + 1)), V = 1 - u (Bentley & Saxe 1980)."""
    m = u.shape[0]
    for k in range(m):
        out[k] = log_positive(1.0 - u[k]) / (k + 1)
    acc = 0.0
    for k in range(m - 1, -1, -1):
        acc += out[k]
        out[k] = acc
    for k in range(m):
        out[k] = exp_nonpositive(out[k])


def sorted_uniforms_numpy(u):
    """Plain-numpy reference of :func:`sorted_uniforms`."""
    logs = np.log1p(-np.asarray(u)) / np.arange(1, len(u) + 1)
    return np.exp(np.cumsum(logs[::-1])[::-1])


@nb.njit(cache=True)
def resample_indices(scheme, w, uniforms, idx):
    """Ancestor indices into ``idx`` (n,) for weights ``w`` (M,) using ``uniforms`` (n,) in [0, 1):
    n draws from M particles (n = M but for an adaptive count, ``filters/kld.py``)."""
    m = w.shape[0]
    n = idx.shape[0]
    points = np.empty(n)
    if scheme == SYSTEMATIC:
        for k in range(n):
            points[k] = (uniforms[0] + k) / n
        _sweep(w, points, idx)
    elif scheme == STRATIFIED:
        for k in range(n):
            points[k] = (uniforms[k] + k) / n
        _sweep(w, points, idx)
    elif scheme == MULTINOMIAL:
        sorted_uniforms(uniforms[:n], points)
        _sweep(w, points, idx)
    else:  # residual
        k = 0
        resid = np.empty(m)
        for i in range(m):
            copies = int(math.floor(n * w[i]))
            for _ in range(copies):
                if k < n:
                    idx[k] = i
                    k += 1
            resid[i] = n * w[i] - copies
        rest = n - k
        if rest > 0:
            cdf = np.cumsum(resid)
            total = cdf[m - 1]
            for r in range(rest):
                idx[k + r] = min(np.searchsorted(cdf, uniforms[r] * total, side="right"), m - 1)


def resample_indices_numpy(scheme, w, uniforms, n=None):
    """Plain-numpy reference of :func:`resample_indices` (``n`` draws, M = len(w) by default)."""
    m = w.size
    n = m if n is None else n
    cdf = np.cumsum(w)
    if scheme in (SYSTEMATIC, STRATIFIED):
        points = (uniforms[0] + np.arange(n)) / n if scheme == SYSTEMATIC else (uniforms[:n] + np.arange(n)) / n
        return np.minimum(np.searchsorted(cdf, points, side="left"), m - 1)
    if scheme == MULTINOMIAL:
        return np.minimum(np.searchsorted(cdf, sorted_uniforms_numpy(uniforms[:n]), side="left"), m - 1)
    copies = np.floor(n * w).astype(np.int64)
    idx = np.repeat(np.arange(m), copies)[:n]
    rest = n - idx.size
    resid = n * w - copies
    rcdf = np.cumsum(resid)
    extra = np.minimum(np.searchsorted(rcdf, uniforms[:rest] * rcdf[-1], side="right"), m - 1)
    return np.concatenate([idx, extra])


@nb.njit(cache=True)
def apply_resample(x, idx, scratch):
    """Replace the columns of ``x`` (nrows, M) by ``x[:, idx]`` (``scratch`` is a same-shaped buffer)."""
    gather_columns(x, idx, scratch, x)


@nb.njit(cache=True, error_model="numpy")
def gather_columns(x, idx, scratch, out):
    """``out`` (nrows, n) = ``x[:, idx]`` through ``scratch`` (nrows, n): every column is gathered before ``out``
    is written, so ``out`` may be ``x`` itself or share its memory (the adaptive count's new cloud)."""
    for c in range(x.shape[0]):
        row = x[c]
        tmp = scratch[c]
        for k in range(idx.shape[0]):
            tmp[k] = row[idx[k]]
    for c in range(out.shape[0]):
        row = out[c]
        tmp = scratch[c]
        for k in range(idx.shape[0]):
            row[k] = tmp[k]


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _row_range(row):
    lo = np.inf
    hi = -np.inf
    for j in range(row.shape[0]):
        lo = min(lo, row[j])
        hi = max(hi, row[j])
    return lo, hi


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _add_scaled(row, s, noise):
    for j in range(row.shape[0]):
        row[j] += s * noise[j]


@nb.njit(cache=True)
def roughen(x, rows, k_rough, dim, noise):
    """Add N(0, (K * range * M^(-1/dim))^2) to rows ``rows`` of ``x``; ``noise`` (len(rows), M)."""
    factor = k_rough * x.shape[1] ** (-1.0 / dim)
    for ci in range(rows.shape[0]):
        lo, hi = _row_range(x[rows[ci]])
        _add_scaled(x[rows[ci]], factor * (hi - lo), noise[ci])


def roughen_numpy(x, rows, k_rough, dim, noise):
    """Plain-numpy reference of :func:`roughen` (returns a new array)."""
    x = x.copy()
    spread = x[rows].max(axis=1) - x[rows].min(axis=1)
    x[rows] += k_rough * x.shape[1] ** (-1.0 / dim) * spread[:, None] * noise
    return x


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _shrink_row(row, a, shift, s, noise):
    for j in range(row.shape[0]):
        row[j] = a * row[j] + shift + s * noise[j]


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _centred_sum_sq(row, mean):
    m = row.shape[0]
    m4 = m - m % 4
    s0 = s1 = s2 = s3 = 0.0
    for j in range(0, m4, 4):
        s0 += (row[j] - mean) ** 2
        s1 += (row[j + 1] - mean) ** 2
        s2 += (row[j + 2] - mean) ** 2
        s3 += (row[j + 3] - mean) ** 2
    for j in range(m4, m):
        s0 += (row[j] - mean) ** 2
    return (s0 + s1) + (s2 + s3)


@nb.njit(cache=True)
def shrink_jitter(x, rows, h, noise):
    """Liu-West kernel jitter of rows ``rows``: mean and variance preserving; ``noise`` (len(rows), M)."""
    m = x.shape[1]
    a = math.sqrt(1.0 - h * h)
    for ci in range(rows.shape[0]):
        row = x[rows[ci]]
        mean = sum4(row) / m
        s = h * math.sqrt(_centred_sum_sq(row, mean) / m)
        _shrink_row(row, a, (1.0 - a) * mean, s, noise[ci])


def shrink_jitter_numpy(x, rows, h, noise):
    """Plain-numpy reference of :func:`shrink_jitter` (returns a new array)."""
    x = x.copy()
    v = x[rows]
    a = math.sqrt(1.0 - h * h)
    x[rows] = a * v + (1 - a) * v.mean(axis=1, keepdims=True) + h * v.std(axis=1, keepdims=True) * noise
    return x


@nb.njit(cache=True)
def regularise(x, rng, kind, rows, size, dim):
    """Draw the jitter from ``rng`` (``rng.fill_normals``: (len(rows), M), row by row) and apply
    ``shrink_jitter`` (h = size) or ``roughen`` (K = size)."""
    if kind == REG_NONE:
        return
    noise = np.empty((rows.shape[0], x.shape[1]))
    fill_normals(rng, noise)
    if kind == REG_LIU_WEST:
        shrink_jitter(x, rows, size, noise)
    else:
        roughen(x, rows, size, dim, noise)


def regularise_numpy(x, draw, kind, rows, size, dim):
    """Plain-numpy reference of :func:`regularise` (returns a new array): the jitter's (len(rows), M)
    normals from ``draw(n, normal)``, the kernel's generator's next numbers (``rng.fills_numpy``)."""
    x = np.array(x, dtype=float)
    if kind == REG_NONE:
        return x
    noise = draw(np.shape(rows)[0] * x.shape[1], True).reshape(np.shape(rows)[0], x.shape[1])
    if kind == REG_LIU_WEST:
        return shrink_jitter_numpy(x, rows, size, noise)
    return roughen_numpy(x, rows, size, dim, noise)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _shift_log_weights(logw):
    mx = max_log_weight(logw)
    for j in range(logw.shape[0]):
        logw[j] -= mx


@nb.njit(cache=True)
def resample_and_regularise(x, w, logw, ess, rng, rs, dim, spread, uni, idx, scratch):
    """The end of an update, shared by the filters: keep log-weights bounded; if the ESS is
    below ``rs.ess_threshold * M`` resample (drawing one uniform for the systematic scheme, M
    for the others), regularise rows ``rs.cols`` and, if the horizontal cloud (rows 0 and 1,
    std ``spread``) has collapsed below ``rs.min_spread``, re-spread it. ``rs`` is a
    :class:`Resampling`."""
    m = x.shape[1]
    _shift_log_weights(logw)
    if ess >= rs.ess_threshold * m:
        return
    draws = uni[:1] if rs.scheme == SYSTEMATIC else uni
    fill_uniforms(rng, draws)
    resample_indices(rs.scheme, w, uni, idx)
    apply_resample(x, idx, scratch)
    regularise(x, rng, rs.kind, rs.cols, rs.size, dim)
    logw[:] = 0.0
    if spread < rs.min_spread:
        noise = scratch[:2]
        fill_normals(rng, noise)
        s = rs.min_spread / math.sqrt(2.0)
        _add_scaled(x[0], s, noise[0])
        _add_scaled(x[1], s, noise[1])


def resample_and_regularise_numpy(x, w, logw, ess, draw, rs, dim, spread):
    """Plain-numpy reference of :func:`resample_and_regularise`: returns (new x, new log-weights).
    ``draw(n, normal)`` gives the kernel's generator's next ``n`` standard normals (``normal``) or
    uniforms in [0, 1), fill after fill (``rng.fills_numpy``): the kernel fills one uniform
    (systematic) or M, then the jitter's (len(rs.cols), M) normals, then the re-spread's (2, M)."""
    x = np.array(x, dtype=np.float64)
    m = x.shape[1]
    finite = logw[~np.isnan(logw)]  # NaN log-weights are passed over by the largest one
    with np.errstate(invalid="ignore"):  # -inf less -inf: NaN, as the kernel's
        logw = logw - (finite.max() if finite.size else -np.inf)
    if ess >= rs.ess_threshold * m:
        return x, logw
    uniforms = draw(1 if rs.scheme == SYSTEMATIC else m, False)
    x = x[:, resample_indices_numpy(rs.scheme, w, uniforms)]
    x = regularise_numpy(x, draw, rs.kind, rs.cols, rs.size, dim)
    if spread < rs.min_spread:
        x[:2] += rs.min_spread / math.sqrt(2.0) * draw(2 * m, True).reshape(2, m)
    return x, np.zeros_like(logw)
