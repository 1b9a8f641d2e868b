"""The filter's estimate: weighted mean (MMSE) and weighted covariance of the particles.

The yaw column is averaged as an angle: deviations from ``yaw_ref`` are wrapped to
(-pi, pi] before weighting, so a cloud straddling +-180 deg averages correctly; the
returned mean yaw is unwrapped around ``yaw_ref``.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH


@nb.njit(cache=True, fastmath=FASTMATH)
def weighted_estimate(x, w, yaw_col, yaw_ref, mean, var, cov_en):
    """Fill ``mean``/``var`` (ncols,) and ``cov_en`` (2, 2) from particles ``x`` and weights ``w``.

    One pass of weighted first and second moments about the first particle (shifting
    keeps the sums small, so E[x^2] - E[x]^2 loses no precision at map coordinates).
    """
    m, nc = x.shape
    ref = np.empty(nc)
    for c in range(nc):
        ref[c] = x[0, c]
        mean[c] = 0.0
        var[c] = 0.0
    if yaw_col >= 0:
        ref[yaw_col] = 0.0
    cen = 0.0
    for j in range(m):
        wj = w[j]
        for c in range(nc):
            if c == yaw_col:
                v = _wrap(x[j, c] - yaw_ref)
            else:
                v = x[j, c] - ref[c]
            mean[c] += wj * v
            var[c] += wj * v * v
        cen += wj * (x[j, 0] - ref[0]) * (x[j, 1] - ref[1])
    for c in range(nc):
        var[c] = max(var[c] - mean[c] * mean[c], 0.0)
    cen -= mean[0] * mean[1]
    for c in range(nc):
        mean[c] += ref[c]
    if yaw_col >= 0:
        mean[yaw_col] += yaw_ref
    cov_en[0, 0] = var[0]
    cov_en[1, 1] = var[1]
    cov_en[0, 1] = cen
    cov_en[1, 0] = cen


@nb.njit(cache=True, inline="always")
def _wrap(a):
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


def weighted_estimate_numpy(x, w, yaw_col, yaw_ref):
    """Plain-numpy reference: (mean, var, cov_en)."""
    v = x.copy()
    if yaw_col >= 0:
        v[:, yaw_col] = (v[:, yaw_col] - yaw_ref + np.pi) % (2 * np.pi) - np.pi
    mean = w @ v
    d = v - mean
    var = w @ (d * d)
    cen = w @ (d[:, 0] * d[:, 1])
    if yaw_col >= 0:
        mean[yaw_col] += yaw_ref
    return mean, var, np.array([[var[0], cen], [cen, var[1]]])
