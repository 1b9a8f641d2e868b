"""Thinning a multibeam swath: which beams a filter weighs by (methods/multibeam.py).

The cost of the likelihood grows with the beams used, and neighbouring beams of a dense
fan share their map cells (so their map errors are correlated and their information
largely repeated). Two selections, both from what the vehicle has (the navigation
solution, the navigation map and the measured ranges), never the truth:

* ``every-kth``: beams 0, k, 2k, ... with k = ceil(N / wanted);
* ``information``: per update, the ``wanted`` beams whose range says most about the
  horizontal position: the range sensitivity |dr/d(E, N)|^2 = (h_e^2 + h_n^2) / D^2 of
  the PCRB (``bounds/pcrb.py``; D = b_u - h_e b_e - h_n b_n), with the gradient of the
  navigation map at the footprint the navigation solution puts each measured range at.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.terrain.grid import bilinear, bilinear_numpy


@nb.njit(cache=True)
def beam_information(offsets, nav_en, z, e0, n0, inv_re, inv_rn, out):
    """Fill ``out`` (K, m) with each beam's (h_e^2 + h_n^2) / D^2 at its footprint nav_en[k] +
    offsets[k, i] (``offsets`` (K, m, 3): nav-frame beam vectors times ranges, ``filters.beams``):
    -1 where the beam has no range, 0 where the map has no gradient there (off the map)."""
    he = 0.5 / inv_re
    hn = 0.5 / inv_rn
    for k in range(offsets.shape[0]):
        for i in range(offsets.shape[1]):
            ox = offsets[k, i, 0]
            oy = offsets[k, i, 1]
            oz = offsets[k, i, 2]
            if oz != oz:
                out[k, i] = -1.0
                continue
            r = math.sqrt(ox * ox + oy * oy + oz * oz)
            pe = nav_en[k, 0] + ox
            pn = nav_en[k, 1] + oy
            ge = (bilinear(z, e0, n0, inv_re, inv_rn, pe + he, pn) - bilinear(z, e0, n0, inv_re, inv_rn, pe - he, pn)) \
                / (2.0 * he)
            gn = (bilinear(z, e0, n0, inv_re, inv_rn, pe, pn + hn) - bilinear(z, e0, n0, inv_re, inv_rn, pe, pn - hn)) \
                / (2.0 * hn)
            d = (oz - ge * ox - gn * oy) / r if r > 0.0 else 0.0
            v = (ge * ge + gn * gn) / (d * d) if d != 0.0 else np.nan
            out[k, i] = v if v == v and v < np.inf else 0.0


def beam_information_numpy(offsets, nav_en, z, e0, n0, inv_re, inv_rn) -> np.ndarray:
    """Plain-numpy reference of :func:`beam_information`."""
    he, hn = 0.5 / inv_re, 0.5 / inv_rn
    o = np.asarray(offsets, dtype=float)
    pe = nav_en[:, 0:1] + o[..., 0]
    pn = nav_en[:, 1:2] + o[..., 1]
    ge = (bilinear_numpy(z, e0, n0, inv_re, inv_rn, pe + he, pn) - bilinear_numpy(z, e0, n0, inv_re, inv_rn, pe - he, pn)) / (2 * he)
    gn = (bilinear_numpy(z, e0, n0, inv_re, inv_rn, pe, pn + hn) - bilinear_numpy(z, e0, n0, inv_re, inv_rn, pe, pn - hn)) / (2 * hn)
    r = np.sqrt((o**2).sum(axis=-1))
    with np.errstate(divide="ignore", invalid="ignore"):
        d = (o[..., 2] - ge * o[..., 0] - gn * o[..., 1]) / r
        v = (ge**2 + gn**2) / d**2
    v = np.where(np.isfinite(v), v, 0.0)
    return np.where(np.isnan(o[..., 2]), -1.0, v)


def every_kth(beams: int, wanted: int) -> np.ndarray:
    """The beams 0, k, 2k, ... (k = ceil(beams / wanted)); all of them when ``wanted`` is 0 or >= beams."""
    if wanted <= 0 or wanted >= beams:
        return np.arange(beams)
    return np.arange(0, beams, -(-beams // wanted))


def most_informative(info: np.ndarray, ranges: np.ndarray, wanted: int) -> np.ndarray:
    """``ranges`` (K, m) with every beam but each update's ``wanted`` most informative (``info`` (K, m),
    ties to the lower beam index) set to NaN (no range: the likelihood skips it)."""
    if wanted <= 0 or wanted >= ranges.shape[1]:
        return np.array(ranges)
    order = np.argsort(-info, axis=1, kind="stable")[:, :wanted]
    keep = np.zeros(ranges.shape, dtype=bool)
    np.put_along_axis(keep, order, True, axis=1)
    return np.where(keep, ranges, np.nan)
