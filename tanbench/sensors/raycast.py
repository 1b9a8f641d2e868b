"""Sonar beam ranges: where a ray from the vehicle first meets the true seafloor.

The ray p + s u (u a unit vector pointing down-ish) is marched in steps of
``step`` metres until it passes below the bilinear seafloor, then the crossing is
refined by bisection (60 halvings: far below a millimetre). Bilinear interpolation
reproduces planes exactly, so on an analytic plane or slope the range is exact to
rounding. A ray that leaves the map, or finds no bottom within ``max_range``, gives NaN.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from tanbench.terrain.grid import bilinear, bilinear_numpy

BISECTIONS = 60


@nb.njit(cache=True)
def cast_ray(z, e0, n0, inv_re, inv_rn, pe, pn, pu, ue, un, uu, max_range, step):
    """Range along (ue, un, uu) from (pe, pn, pu) to the seafloor, metres; NaN if none."""
    h = bilinear(z, e0, n0, inv_re, inv_rn, pe, pn)
    if not (pu - h > 0.0):  # off the map (NaN) or not above the bottom
        return np.nan
    s0 = 0.0
    nsteps = int(max_range / step) + 1
    for k in range(1, nsteps + 1):
        s1 = k * step
        if s1 > max_range:
            s1 = max_range
        h = bilinear(z, e0, n0, inv_re, inv_rn, pe + s1 * ue, pn + s1 * un)
        if h != h:
            return np.nan
        if pu + s1 * uu - h <= 0.0:
            lo = s0
            hi = s1
            for _ in range(BISECTIONS):
                mid = 0.5 * (lo + hi)
                hm = bilinear(z, e0, n0, inv_re, inv_rn, pe + mid * ue, pn + mid * un)
                if pu + mid * uu - hm > 0.0:
                    lo = mid
                else:
                    hi = mid
            return 0.5 * (lo + hi)
        s0 = s1
        if s1 >= max_range:
            break
    return np.nan


@nb.njit(cache=True)
def cast_rays(z, e0, n0, inv_re, inv_rn, origins, dirs, max_range, step, out):
    """:func:`cast_ray` for rows of ``origins`` (k, 3) and ``dirs`` (k, 3) into ``out`` (k,)."""
    for k in range(origins.shape[0]):
        out[k] = cast_ray(z, e0, n0, inv_re, inv_rn, origins[k, 0], origins[k, 1], origins[k, 2],
                          dirs[k, 0], dirs[k, 1], dirs[k, 2], max_range, step)


def cast_rays_numpy(z, e0, n0, inv_re, inv_rn, origins, dirs, max_range, step):
    """Plain-numpy reference of :func:`cast_rays`: the same march and bisection, vectorised."""
    origins = np.asarray(origins, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64)
    k = origins.shape[0]
    nsteps = int(max_range / step) + 1
    s = np.minimum(np.arange(0, nsteps + 1) * step, max_range)  # (m,)
    pe = origins[:, 0:1] + s * dirs[:, 0:1]
    pn = origins[:, 1:2] + s * dirs[:, 1:2]
    h = bilinear_numpy(z, e0, n0, inv_re, inv_rn, pe, pn)
    clearance = origins[:, 2:3] + s * dirs[:, 2:3] - h
    below = ~(clearance > 0)  # NaN counts as "stop here"
    first = np.where(below.any(axis=1), below.argmax(axis=1), -1)
    out = np.full(k, np.nan)
    rows = np.nonzero(first > 0)[0]
    idx = first[rows]
    valid = ~np.isnan(h[rows, idx])
    rows, idx = rows[valid], idx[valid]
    lo, hi = s[idx - 1], s[idx]
    o, d = origins[rows], dirs[rows]
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        hm = bilinear_numpy(z, e0, n0, inv_re, inv_rn, o[:, 0] + mid * d[:, 0], o[:, 1] + mid * d[:, 1])
        above = o[:, 2] + mid * d[:, 2] - hm > 0
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    out[rows] = 0.5 * (lo + hi)
    return out
