"""An adaptive particle count: KLD sampling (Fox 2003) at each resampling of a tight PF.

Zhou et al.'s Table 2 gives the particle sample size as "adjustable, with 3000 maximum";
tanbench reads it as a setting of the experiment (docs/model.md 6.1). This module is the
other reading, an option (``filter.kld_epsilon``): when the cloud is resampled, the number of
particles drawn is the one that bounds, with probability 1 - delta, the Kullback-Leibler
divergence between the particles' histogram and the posterior by epsilon:

    n(k) = (k - 1) / (2 epsilon) * (1 - 2 / (9 (k - 1)) + sqrt(2 / (9 (k - 1))) z)^3,

k the number of occupied bins of the (east, north, heading) histogram, z the standard normal's
1 - delta quantile (delta = 0.01), n clamped to [``filter.kld_min_particles``, ``particles``].
A bin counts as occupied when the weight of the particles in it is at least 1 / ``particles``
(it would expect one of the largest cloud's draws): Fox's sampler counts the bins of the
particles it draws, which the weight makes a count of expected draws here, without drawing
twice. Bins: ``filter.kld_bin_m`` in east and north, ``filter.kld_bin_deg`` in heading.

Kernels: :func:`occupied_bins` (an open-addressing table of the bins' summed weights) and
:func:`kld_count`, each with a plain-numpy reference (``*_numpy``) the tests check.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

KLD_Z = 2.3263478740408408  # the standard normal's 0.99 quantile: delta = 0.01
EMPTY = np.iinfo(np.int64).min  # the table's free slot
_SPAN = 1 << 19  # bin indices are packed as 20-bit fields (2^19 bins either way of the first particle's corner)
# a bin's home slot: its three indices times large odd numbers, XOR-ed (each product below 2^47, so no int64
# overflow; a product's low bits alone, as a wrapping multiply of the packed key gives them, hold only the heading)
_HASH = (73856093, 19349663, 83492791)

# the loop's adaptive count: ``epsilon`` 0 = a fixed count (the neutral value); bins of ``bin_m`` metres
# and ``bin_rad`` radians; at least ``min_particles``
Kld = namedtuple("Kld", "epsilon bin_m bin_rad min_particles")


def kld_of(f, particles: int) -> Kld:
    """The :class:`Kld` bundle of a ``FilterSpec`` ``f`` for a cloud of at most ``particles``."""
    if f.kld_epsilon is None:
        return Kld(0.0, 1.0, 1.0, particles)
    return Kld(float(f.kld_epsilon), float(f.kld_bin_m), math.radians(f.kld_bin_deg),
               min(int(f.kld_min_particles), particles))


@nb.njit(cache=True)
def bin_table(particles):
    """The (keys, weights) table :func:`occupied_bins` fills: a power of two at least twice ``particles``, at
    least 16 (its contents are set by each count)."""
    size = 16
    while size < 2 * particles:
        size *= 2
    return np.empty(size, dtype=np.int64), np.empty(size)


@nb.njit(cache=True)
def home_slot(ie, jn, iy, size):
    """The table slot (``size`` a power of two) where the search for bin (``ie``, ``jn``, ``iy``) starts."""
    return ((ie * _HASH[0]) ^ (jn * _HASH[1]) ^ (iy * _HASH[2])) & (size - 1)


@nb.njit(cache=True)
def _bin_key(x, j, e0, n0, y0, bin_m, bin_rad, size):
    """Particle ``j``'s bin: (its packed key, its home slot)."""
    ie = min(max(int(math.floor((x[0, j] - e0) / bin_m)), 1 - _SPAN), _SPAN - 1) + _SPAN
    jn = min(max(int(math.floor((x[1, j] - n0) / bin_m)), 1 - _SPAN), _SPAN - 1) + _SPAN
    iy = min(max(int(math.floor((x[5, j] - y0) / bin_rad)), 1 - _SPAN), _SPAN - 1) + _SPAN
    return (ie << 40) | (jn << 20) | iy, home_slot(ie, jn, iy, size)


@nb.njit(cache=True)
def occupied_bins(x, w, bin_m, bin_rad, min_weight, keys, weights):
    """The number of (east, north, heading) bins of the cloud ``x`` (rows 0, 1 and 5) whose particles'
    normalised weights ``w`` add up to at least ``min_weight``. Bins are counted from the first particle's
    corner; ``keys`` and ``weights`` (:func:`bin_table`) are cleared and refilled."""
    size = keys.shape[0]
    for i in range(size):
        keys[i] = EMPTY
        weights[i] = 0.0
    e0 = math.floor(x[0, 0] / bin_m) * bin_m
    n0 = math.floor(x[1, 0] / bin_m) * bin_m
    y0 = math.floor(x[5, 0] / bin_rad) * bin_rad
    count = 0
    for j in range(x.shape[1]):
        key, slot = _bin_key(x, j, e0, n0, y0, bin_m, bin_rad, size)
        while keys[slot] != EMPTY and keys[slot] != key:
            slot = (slot + 1) & (size - 1)
        new = keys[slot] == EMPTY
        before = weights[slot]
        keys[slot] = key
        weights[slot] = before + w[j]
        if weights[slot] >= min_weight and (new or before < min_weight):  # counted once, when it first qualifies
            count += 1
    return count


def occupied_bins_numpy(x, w, bin_m, bin_rad, min_weight):
    """Plain-numpy reference of :func:`occupied_bins`."""
    corner = np.floor(np.array([x[0, 0] / bin_m, x[1, 0] / bin_m, x[5, 0] / bin_rad])) * np.array([bin_m, bin_m,
                                                                                                    bin_rad])
    idx = np.floor((np.stack([x[0], x[1], x[5]]) - corner[:, None]) / np.array([bin_m, bin_m, bin_rad])[:, None])
    _, inverse = np.unique(idx.T, axis=0, return_inverse=True)
    sums = np.bincount(inverse.ravel(), weights=w)
    return int((sums >= min_weight).sum())


@nb.njit(cache=True)
def kld_count(k, epsilon, z, low, high):
    """Fox's n(k) (module docstring) for ``k`` occupied bins, rounded up and clamped to [``low``, ``high``];
    ``low`` for k < 2."""
    if k < 2:
        return low
    a = 2.0 / (9.0 * (k - 1))
    n = min((k - 1) / (2.0 * epsilon) * (1.0 - a + math.sqrt(a) * z) ** 3, float(high))  # clamped before rounding
    return int(min(max(math.ceil(n), low), high))


def kld_count_numpy(k, epsilon, z, low, high):
    """Plain-Python reference of :func:`kld_count`."""
    if k < 2:
        return low
    a = 2.0 / (9.0 * (k - 1))
    return int(np.clip(np.ceil((k - 1) / (2.0 * epsilon) * (1.0 - a + np.sqrt(a) * z) ** 3), low, high))
