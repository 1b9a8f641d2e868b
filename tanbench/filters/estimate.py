"""The filter's estimate: weighted mean (MMSE) and weighted covariance of the particles.

Particles are the columns of ``x`` (a row per state). The yaw row is averaged as an
angle: deviations from ``yaw_ref`` are wrapped to (-pi, pi] before weighting, so a cloud
straddling +-180 deg averages correctly; the returned mean yaw is unwrapped around
``yaw_ref``.

The sums run over four interleaved accumulators, added in a fixed order at the end: four
independent chains keep the adder busy (a single chain waits on each addition), and the
order, hence every last bit, is the same on every machine and in every process (a
vectorising compiler would choose the order by the machine's vector width). The four chains
are the four lanes of one 256-bit vector (``vecmath.lane_moments``, ``lane_wrapped_moments``,
``lane_cross``: LLVM left the scalar chains scalar): the same operations on the same elements in the same order,
so the same bits as the scalar loops (:func:`weighted_moments_scalar`,
:func:`weighted_cross_scalar`, the tests' check), four elements an instruction.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from tanbench.filters import FASTMATH
from tanbench.filters.vecmath import lane_cross, lane_moments, lane_wrapped_moments


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _wrap(a):
    # np.floor, a float: numba's math.floor returns an integer (two conversions per particle); the
    # same value for any finite angle (an infinite one now gives NaN, as numpy's reference does)
    return a - 2.0 * math.pi * np.floor((a + math.pi) / (2.0 * math.pi))


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _deviation(v, ref, angle):
    return _wrap(v - ref) if angle else v - ref


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _finish_moments(a, b, row, w, ref, angle, m4):
    """The four chains' sums ``a`` (of w d) and ``b`` (of w d^2) with the elements after the first ``m4``
    added to chain 0, then the chains added in the fixed order."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    for j in range(m4, row.shape[0]):
        d = _deviation(row[j], ref, angle)
        a0 += w[j] * d
        b0 += w[j] * d * d
    return (a0 + a1) + (a2 + a3), (b0 + b1) + (b2 + b3)


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _finish_cross(a, xe, xn, w, ref_e, ref_n, m4):
    """The four chains' sums ``a`` of w (xe - ref_e) (xn - ref_n) with the elements after the first ``m4``
    added to chain 0, then the chains added in the fixed order."""
    a0, a1, a2, a3 = a
    for j in range(m4, w.shape[0]):
        a0 += w[j] * (xe[j] - ref_e) * (xn[j] - ref_n)
    return (a0 + a1) + (a2 + a3)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def weighted_moments(row, w, ref, angle):
    """(sum w d, sum w d^2) of the deviations d = row - ref (wrapped, if ``angle``): four chains as
    the lanes of ``vecmath.lane_moments`` (``lane_wrapped_moments``), then the last elements."""
    m = row.shape[0]
    m4 = m - m % 4
    if angle:
        a0, a1, a2, a3, b0, b1, b2, b3 = lane_wrapped_moments(row, w, ref, m4 // 4)
    else:
        a0, a1, a2, a3, b0, b1, b2, b3 = lane_moments(row, w, ref, m4 // 4)
    return _finish_moments((a0, a1, a2, a3), (b0, b1, b2, b3), row, w, ref, angle, m4)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def weighted_moments_scalar(row, w, ref, angle):
    """:func:`weighted_moments` as four scalar chains (the tests' check of the lanes)."""
    m = row.shape[0]
    m4 = m - m % 4
    a0 = a1 = a2 = a3 = 0.0
    b0 = b1 = b2 = b3 = 0.0
    for j in range(0, m4, 4):
        d0 = _deviation(row[j], ref, angle)
        d1 = _deviation(row[j + 1], ref, angle)
        d2 = _deviation(row[j + 2], ref, angle)
        d3 = _deviation(row[j + 3], ref, angle)
        a0 += w[j] * d0
        a1 += w[j + 1] * d1
        a2 += w[j + 2] * d2
        a3 += w[j + 3] * d3
        b0 += w[j] * d0 * d0
        b1 += w[j + 1] * d1 * d1
        b2 += w[j + 2] * d2 * d2
        b3 += w[j + 3] * d3 * d3
    return _finish_moments((a0, a1, a2, a3), (b0, b1, b2, b3), row, w, ref, angle, m4)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def weighted_cross(xe, xn, w, ref_e, ref_n):
    """sum w (xe - ref_e) (xn - ref_n): four chains as the lanes of ``vecmath.lane_cross``, then the
    last elements."""
    m = w.shape[0]
    m4 = m - m % 4
    return _finish_cross(lane_cross(xe, xn, w, ref_e, ref_n, m4 // 4), xe, xn, w, ref_e, ref_n, m4)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def weighted_cross_scalar(xe, xn, w, ref_e, ref_n):
    """:func:`weighted_cross` as four scalar chains (the tests' check of the lanes)."""
    m = w.shape[0]
    m4 = m - m % 4
    a0 = a1 = a2 = a3 = 0.0
    for j in range(0, m4, 4):
        a0 += w[j] * (xe[j] - ref_e) * (xn[j] - ref_n)
        a1 += w[j + 1] * (xe[j + 1] - ref_e) * (xn[j + 1] - ref_n)
        a2 += w[j + 2] * (xe[j + 2] - ref_e) * (xn[j + 2] - ref_n)
        a3 += w[j + 3] * (xe[j + 3] - ref_e) * (xn[j + 3] - ref_n)
    return _finish_cross((a0, a1, a2, a3), xe, xn, w, ref_e, ref_n, m4)


@nb.njit(cache=True, fastmath=FASTMATH)
def weighted_estimate(x, w, yaw_row, yaw_ref, mean, var, cov_en):
    """Fill ``mean``/``var`` (nrows,) and ``cov_en`` (2, 2) from particles ``x`` (nrows, M) and
    normalised weights ``w``.

    Weighted first and second moments about the first particle (shifting keeps the sums
    small, so E[x^2] - E[x]^2 loses no precision at map coordinates); the yaw row
    (``yaw_row`` >= 0) about ``yaw_ref``, wrapped.
    """
    for c in range(x.shape[0]):
        angle = c == yaw_row
        ref = yaw_ref if angle else x[c, 0]
        s1, s2 = weighted_moments(x[c], w, ref, angle)
        mean[c] = s1
        var[c] = max(s2 - s1 * s1, 0.0)
    ref_e = x[0, 0]
    ref_n = x[1, 0]
    cen = weighted_cross(x[0], x[1], w, ref_e, ref_n) - mean[0] * mean[1]
    for c in range(x.shape[0]):
        mean[c] += yaw_ref if c == yaw_row else x[c, 0]
    cov_en[0, 0] = var[0]
    cov_en[1, 1] = var[1]
    cov_en[0, 1] = cen
    cov_en[1, 0] = cen


def weighted_estimate_numpy(x, w, yaw_row, yaw_ref):
    """Plain-numpy reference: (mean, var, cov_en); ``x`` (nrows, M)."""
    v = x.copy()
    if yaw_row >= 0:
        v[yaw_row] = (v[yaw_row] - yaw_ref + np.pi) % (2 * np.pi) - np.pi
    mean = v @ w
    d = v - mean[:, None]
    var = (d * d) @ w
    cen = (d[0] * d[1]) @ w
    if yaw_row >= 0:
        mean[yaw_row] += yaw_ref
    return mean, var, np.array([[var[0], cen], [cen, var[1]]])
