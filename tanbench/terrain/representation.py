"""What a navigation map cannot represent: a per-node variance from the map's own relief.

A map node stands for a cell of side ``res``; where the seafloor slopes, the height
under a beam's footprint differs from the map's interpolated height by about the slope
times the footprint's unknown position inside the cell. A footprint uniformly placed in
a cell of side ``res`` is off its centre by res / sqrt(12) (std) on each axis, so the
representation error is ``c |grad h| res`` with ``c = 1 / sqrt(12)`` by default
(``filter.map_slope_factor``). The declared map-level error (``terrain.map_error_m``,
what a survey states about its gridded levels, as TRN's map variance does) adds to it:

    var_node = (c |grad h| res)^2 + map_error^2

The gradient is the map's own (central differences, one-sided at the edges and next to
holes), never the truth's. The filters add the sonar's variance beam by beam
(``filters/likelihood.py``, the map-aware kernels).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _diff(a_minus, a0, a_plus, step):
    """Central difference, one-sided where a neighbour is missing (NaN); 0 if both are."""
    if a_minus == a_minus and a_plus == a_plus:
        return (a_plus - a_minus) / (2.0 * step)
    if a_plus == a_plus:
        return (a_plus - a0) / step
    if a_minus == a_minus:
        return (a0 - a_minus) / step
    return 0.0


@nb.njit(cache=True)
def representation_variance(z, res_e, res_n, slope_factor, map_error, out):
    """Fill ``out`` (ny, nx) with each node's map variance; NaN where ``z`` is NaN."""
    ny, nx = z.shape
    res = max(res_e, res_n)
    base = map_error * map_error
    for i in range(ny):
        for j in range(nx):
            h = z[i, j]
            if h != h:
                out[i, j] = np.nan
                continue
            w = z[i, j - 1] if j > 0 else np.nan
            e = z[i, j + 1] if j < nx - 1 else np.nan
            s = z[i - 1, j] if i > 0 else np.nan
            n = z[i + 1, j] if i < ny - 1 else np.nan
            ge = _diff(w, h, e, res_e)
            gn = _diff(s, h, n, res_n)
            slope = math.sqrt(ge * ge + gn * gn)
            out[i, j] = (slope_factor * slope * res) ** 2 + base


def representation_variance_numpy(z, res_e, res_n, slope_factor, map_error):
    """Plain-numpy reference of :func:`representation_variance`."""
    pad = np.pad(z, 1, constant_values=np.nan)
    h = pad[1:-1, 1:-1]

    def grad(minus, plus, step):
        both = ~np.isnan(minus) & ~np.isnan(plus)
        g = np.where(both, (plus - minus) / (2 * step), np.nan)
        g = np.where(~both & ~np.isnan(plus), (plus - h) / step, g)
        g = np.where(~both & np.isnan(plus) & ~np.isnan(minus), (h - minus) / step, g)
        return np.nan_to_num(g, nan=0.0)

    ge = grad(pad[1:-1, :-2], pad[1:-1, 2:], res_e)
    gn = grad(pad[:-2, 1:-1], pad[2:, 1:-1], res_n)
    var = (slope_factor * np.hypot(ge, gn) * max(res_e, res_n)) ** 2 + map_error**2
    return np.where(np.isnan(z), np.nan, var)


def map_variance_grid(nmap, slope_factor: float, map_error: float) -> np.ndarray:
    """The representation-variance grid of a navigation :class:`~tanbench.terrain.grid.Map`."""
    out = np.empty_like(nmap.z)
    representation_variance(np.ascontiguousarray(nmap.z), float(nmap.res_e), float(nmap.res_n),
                            float(slope_factor), float(map_error), out)
    return out
