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

The slope term is a nearest-node lookup's error; the filters interpolate the map bilinearly,
which follows a sloping plane exactly. ``filter.map_representation: bilinear`` charges
bilinear interpolation's own error instead (:func:`interpolation_variance`): between nodes
of spacing res a surface with second derivatives h_ee, h_nn is missed by
-1/2 t (1 - t) res^2 h_ee - 1/2 s (1 - s) res^2 h_nn at the cell fractions (t, s) (the twist
h_en is interpolated exactly); over a footprint uniformly placed in the cell
(E[t^2 (1 - t)^2] = 1/30, E[t (1 - t)] = 1/6) the mean square is

    var_node = 1/4 [ (D_ee^2 + D_nn^2) / 30 + D_ee D_nn / 18 ] + map_error^2

with D the map's own second differences in metres (D_ee = z[i, j-1] - 2 z[i, j] + z[i, j+1]
= res^2 h_ee; 0 along an axis where a neighbour is missing). What the map's nodes cannot
show (relief finer than res) is the declared map error's to cover.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.arrays import read_only


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
def _neighbours(z, i, j):
    """The four neighbours (west, east, south, north) of node (i, j); NaN beyond the grid."""
    ny, nx = z.shape
    w = z[i, j - 1] if j > 0 else np.nan
    e = z[i, j + 1] if j < nx - 1 else np.nan
    s = z[i - 1, j] if i > 0 else np.nan
    n = z[i + 1, j] if i < ny - 1 else np.nan
    return w, e, s, n


@nb.njit(cache=True)
def _second(a_minus, a0, a_plus):
    """Second difference a_minus - 2 a0 + a_plus; 0 where a neighbour is missing (NaN)."""
    if a_minus == a_minus and a_plus == a_plus:
        return a_minus - 2.0 * a0 + a_plus
    return 0.0


@nb.njit(cache=True)
def _node_variances(z, res_e, res_n, slope_factor, map_error, bilinear, out):
    """Fill ``out`` (ny, nx) with each node's map variance, the slope term or (``bilinear``) bilinear
    interpolation's own error, plus ``map_error``^2; NaN where ``z`` is NaN."""
    ny, nx = z.shape
    res = max(res_e, res_n)
    base = map_error * map_error
    for i in range(ny):
        for j in range(nx):
            h = z[i, j]
            if h != h:
                out[i, j] = np.nan
                continue
            w, e, s, n = _neighbours(z, i, j)
            if bilinear:
                dee = _second(w, h, e)
                dnn = _second(s, h, n)
                out[i, j] = 0.25 * ((dee * dee + dnn * dnn) / 30.0 + dee * dnn / 18.0) + base
            else:
                ge = _diff(w, h, e, res_e)
                gn = _diff(s, h, n, res_n)
                slope = math.sqrt(ge * ge + gn * gn)
                out[i, j] = (slope_factor * slope * res) ** 2 + base


@nb.njit(cache=True)
def representation_variance(z, res_e, res_n, slope_factor, map_error, out):
    """Fill ``out`` (ny, nx) with each node's map variance; NaN where ``z`` is NaN."""
    _node_variances(z, res_e, res_n, slope_factor, map_error, False, out)


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


@nb.njit(cache=True)
def interpolation_variance(z, map_error, out):
    """Fill ``out`` (ny, nx) with each node's bilinear-interpolation variance (module docstring)
    plus ``map_error``^2; NaN where ``z`` is NaN."""
    _node_variances(z, 1.0, 1.0, 0.0, map_error, True, out)


def interpolation_variance_numpy(z, map_error):
    """Plain-numpy reference of :func:`interpolation_variance`."""
    pad = np.pad(z, 1, constant_values=np.nan)
    h = pad[1:-1, 1:-1]
    dee = np.nan_to_num(pad[1:-1, :-2] - 2 * h + pad[1:-1, 2:], nan=0.0)
    dnn = np.nan_to_num(pad[:-2, 1:-1] - 2 * h + pad[2:, 1:-1], nan=0.0)
    var = 0.25 * ((dee**2 + dnn**2) / 30.0 + dee * dnn / 18.0) + map_error**2
    return np.where(np.isnan(z), np.nan, var)


def map_variance_grid(nmap, slope_factor: float, map_error: float, representation: str = "slope") -> np.ndarray:
    """The representation-variance grid of a navigation :class:`~tanbench.terrain.grid.Map`:
    the slope term (``representation: slope``) or bilinear interpolation's (``bilinear``)."""
    out = np.empty_like(nmap.z)
    z = read_only(np.ascontiguousarray(nmap.z))
    if representation == "bilinear":
        interpolation_variance(z, float(map_error), out)
    elif representation == "slope":
        representation_variance(z, float(nmap.res_e), float(nmap.res_n), float(slope_factor), float(map_error), out)
    else:
        raise ValueError(f"unknown map representation {representation!r}")
    return out


def filter_map_variance(f, nmap) -> np.ndarray:
    """The map variance grid a ``FilterSpec`` ``f`` charges on ``nmap`` (``filter.map_representation``,
    ``filter.map_slope_factor``, the map's declared ``map_error_m``)."""
    return map_variance_grid(nmap, f.map_slope_factor, float(nmap.meta.get("map_error_m", 0.0)),
                             f.map_representation)
