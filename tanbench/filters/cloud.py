"""The initial clouds: a uniform square (Section 4.3) or, read from Table 2's initial
covariance ``diag(150 m, 150 m, ...)^2``, a Gaussian (``filter.initial_cloud: gaussian``).

Particles are the columns of ``x`` (rows 0 and 1: east, north); the draws are block fills
(``rng.fill_uniforms``, ``rng.fill_normals``), east row then north row. Each kernel has a
plain-numpy reference (``*_numpy``) fed the numbers its fill draws.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.rng import fill_normals, fill_uniforms


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _scale_shift(row, scale, shift):
    for j in range(row.shape[0]):
        row[j] = shift + scale * row[j]


@nb.njit(cache=True)
def uniform_horizontal(x, rng, centre_e, centre_n, half_side):
    """Rows 0, 1 (east, north) of ``x`` uniform in the square of side 2 * half_side around the centre."""
    fill_uniforms(rng, x[0:2], -half_side, half_side)
    _scale_shift(x[0], 1.0, centre_e)
    _scale_shift(x[1], 1.0, centre_n)


def uniform_horizontal_numpy(x, uniforms, centre_e, centre_n, half_side):
    """Plain-numpy reference of :func:`uniform_horizontal` (returns a new array): ``uniforms`` (2, M)
    are the [0, 1) uniforms of the kernel's fill (``rng.uniforms_from_words_numpy`` of its words, or
    ``rng.fill_numpy``), which it scales to [-half_side, half_side)."""
    x = np.array(x, dtype=float)
    low, high = -half_side, half_side
    x[0] = centre_e + (low + (high - low) * uniforms[0])
    x[1] = centre_n + (low + (high - low) * uniforms[1])
    return x


@nb.njit(cache=True)
def gaussian_horizontal(x, rng, centre_e, centre_n, std):
    """Replace rows 0, 1 (east, north) of ``x`` by N(centre, std^2) draws, the east row first."""
    fill_normals(rng, x[0:2])
    _scale_shift(x[0], std, centre_e)
    _scale_shift(x[1], std, centre_n)


def gaussian_horizontal_numpy(x, normals, centre_e, centre_n, std):
    """Plain-numpy reference: ``normals`` (2, M) are the standard normals the kernel would draw."""
    x = x.copy()
    x[0] = centre_e + std * normals[0]
    x[1] = centre_n + std * normals[1]
    return x
