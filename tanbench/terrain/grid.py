"""Regular elevation grids and their bilinear interpolation kernel.

A :class:`Map` holds elevations in metres, up positive (so the seafloor is
negative), on a regular grid in a local east/north frame: node ``z[i, j]`` sits at
``(e0 + j * res_e, n0 + i * res_n)``, row 0 is the southern edge. The same type
serves as the fine "truth" seafloor the sonar sees and as the coarser navigation
map the filters see.

Interpolation outside the grid (or next to a NaN node) returns NaN: never a silent
clamp to the edge. Callers decide what an outside query means.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from collections import namedtuple

import numba as nb
import numpy as np

# the map as the jitted kernels take it (a named tuple: numba passes it by value)
MapArgs = namedtuple("MapArgs", "z e0 n0 inv_re inv_rn")


@dataclass(frozen=True)
class Map:
    """Elevation grid: ``z`` (ny, nx) in metres up, origin node (e0, n0), spacing."""

    z: np.ndarray
    e0: float
    n0: float
    res_e: float
    res_n: float
    name: str = ""
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        z = np.ascontiguousarray(self.z, dtype=np.float64)
        if z.ndim != 2 or z.shape[0] < 2 or z.shape[1] < 2:
            raise ValueError(f"a map needs a 2-D grid of at least 2 x 2 nodes, got shape {z.shape}")
        if not (self.res_e > 0 and self.res_n > 0):
            raise ValueError(f"map resolution must be positive, got {self.res_e} x {self.res_n}")
        object.__setattr__(self, "z", z)

    @property
    def shape(self) -> tuple[int, int]:
        return self.z.shape

    @property
    def e_max(self) -> float:
        return self.e0 + (self.z.shape[1] - 1) * self.res_e

    @property
    def n_max(self) -> float:
        return self.n0 + (self.z.shape[0] - 1) * self.res_n

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(e_min, e_max, n_min, n_max) of the node extent, metres."""
        return (self.e0, self.e_max, self.n0, self.n_max)

    @property
    def resolution(self) -> float:
        """The coarser of the two spacings, metres."""
        return max(self.res_e, self.res_n)

    def contains(self, e, n, margin: float = 0.0) -> np.ndarray:
        """True where (e, n) lies inside the grid by at least ``margin`` metres."""
        e = np.asarray(e)
        n = np.asarray(n)
        return (
            (e >= self.e0 + margin)
            & (e <= self.e_max - margin)
            & (n >= self.n0 + margin)
            & (n <= self.n_max - margin)
        )

    def kernel_args(self):
        """The map as the jitted kernels take it: ``MapArgs(z, e0, n0, inv_res_e, inv_res_n)``."""
        return MapArgs(self.z, float(self.e0), float(self.n0), 1.0 / self.res_e, 1.0 / self.res_n)

    def elevation(self, e, n) -> np.ndarray:
        """Bilinear elevation at arrays of points; NaN outside the grid."""
        e = np.asarray(e, dtype=np.float64)
        n = np.asarray(n, dtype=np.float64)
        shape = np.broadcast_shapes(e.shape, n.shape)
        out = np.empty(shape)
        bilinear_many(*self.kernel_args(), np.broadcast_to(e, shape).ravel(),
                      np.broadcast_to(n, shape).ravel(), out.reshape(-1))
        return out

    def node_coords(self) -> tuple[np.ndarray, np.ndarray]:
        """East coordinates of the columns and north coordinates of the rows."""
        ny, nx = self.z.shape
        return self.e0 + np.arange(nx) * self.res_e, self.n0 + np.arange(ny) * self.res_n


# a point on the far edge may compute to (n - 1) + a rounding error; it is still on the map
EDGE_TOL = 1e-9  # grid cells


@nb.njit(cache=True, inline="always")
def bilinear_cell(ny, nx, e0, n0, inv_re, inv_rn, e, n):
    """The grid cell under (e, n) of a (ny, nx) grid and the position in it: (i, j, tx, ty).

    ``i`` is -1 outside the node extent. Shared by :func:`bilinear` and
    :func:`bilinear_pair` (two grids on the same nodes, one cell look-up).
    """
    fx = (e - e0) * inv_re
    fy = (n - n0) * inv_rn
    if not (fx >= 0.0 and fy >= 0.0 and fx <= nx - 1 + EDGE_TOL and fy <= ny - 1 + EDGE_TOL):
        return -1, 0, 0.0, 0.0
    j = int(fx)
    i = int(fy)
    if j > nx - 2:
        j = nx - 2
    if i > ny - 2:
        i = ny - 2
    return i, j, fx - j, fy - i


@nb.njit(cache=True, inline="always")
def _bilinear_weights(z00, z01, z10, z11, tx, ty):
    return (z00 * (1.0 - tx) + z01 * tx) * (1.0 - ty) + (z10 * (1.0 - tx) + z11 * tx) * ty


@nb.njit(cache=True, inline="always")
def bilinear(z, e0, n0, inv_re, inv_rn, e, n):
    """Bilinear interpolation of grid ``z`` at (e, n); NaN outside the node extent."""
    i, j, tx, ty = bilinear_cell(z.shape[0], z.shape[1], e0, n0, inv_re, inv_rn, e, n)
    if i < 0:
        return np.nan
    return _bilinear_weights(z[i, j], z[i, j + 1], z[i + 1, j], z[i + 1, j + 1], tx, ty)


@nb.njit(cache=True)
def stack_grids(z, z2):
    """Two grids of the same shape interleaved node by node: (ny, nx, 2), ``[..., 0]`` = ``z``.

    :func:`bilinear_pair` reads both values of a node from one cache line (the map-aware
    likelihoods' map and variance grid)."""
    ny, nx = z.shape
    out = np.empty((ny, nx, 2))
    for i in range(ny):
        for j in range(nx):
            out[i, j, 0] = z[i, j]
            out[i, j, 1] = z2[i, j]
    return out


@nb.njit(cache=True, inline="always")
def bilinear_pair(zz, e0, n0, inv_re, inv_rn, e, n):
    """(:func:`bilinear` of ``zz[..., 0]``, of ``zz[..., 1]``) at (e, n) from one cell look-up,
    ``zz`` from :func:`stack_grids`; (NaN, NaN) outside."""
    i, j, tx, ty = bilinear_cell(zz.shape[0], zz.shape[1], e0, n0, inv_re, inv_rn, e, n)
    if i < 0:
        return np.nan, np.nan
    return (_bilinear_weights(zz[i, j, 0], zz[i, j + 1, 0], zz[i + 1, j, 0], zz[i + 1, j + 1, 0], tx, ty),
            _bilinear_weights(zz[i, j, 1], zz[i, j + 1, 1], zz[i + 1, j, 1], zz[i + 1, j + 1, 1], tx, ty))


@nb.njit(cache=True)
def bilinear_many(z, e0, n0, inv_re, inv_rn, e, n, out):
    """Vectorised :func:`bilinear` over 1-D arrays of points, into ``out``."""
    for k in range(e.shape[0]):
        out[k] = bilinear(z, e0, n0, inv_re, inv_rn, e[k], n[k])


def bilinear_numpy(z, e0, n0, inv_re, inv_rn, e, n):
    """Plain-numpy reference of :func:`bilinear` for arrays of points."""
    e = np.asarray(e, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    ny, nx = z.shape
    fx = (e - e0) * inv_re
    fy = (n - n0) * inv_rn
    inside = (fx >= 0) & (fy >= 0) & (fx <= nx - 1 + EDGE_TOL) & (fy <= ny - 1 + EDGE_TOL)
    j = np.clip(np.floor(np.where(inside, fx, 0.0)).astype(np.int64), 0, nx - 2)
    i = np.clip(np.floor(np.where(inside, fy, 0.0)).astype(np.int64), 0, ny - 2)
    tx = fx - j
    ty = fy - i
    val = (z[i, j] * (1 - tx) + z[i, j + 1] * tx) * (1 - ty) + (
        z[i + 1, j] * (1 - tx) + z[i + 1, j + 1] * tx
    ) * ty
    return np.where(inside, val, np.nan)
