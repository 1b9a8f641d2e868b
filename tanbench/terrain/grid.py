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

from tanbench.arrays import read_only
from tanbench.fastmath import FASTMATH

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
        bilinear_many(*self.kernel_args(), read_only(np.broadcast_to(e, shape).ravel()),
                      read_only(np.broadcast_to(n, shape).ravel()), out.reshape(-1))
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

    ``i`` is -1 outside the node extent.
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


# ---- the filters' map look-ups ------------------------------------------------------------------
# The particle filters look the map up at millions of points per run. They read it as a
# :class:`NodeGrid`: the nodes of one or two grids on the same nodes (the map's heights, then
# the map-aware likelihood's variance grid) interleaved node by node, so that a look-up reads
# both from the same cache lines. The look-up is split so that most of it vectorises:
# :func:`locate_cells` (SIMD) finds each point's cell, and :func:`interpolate_cells` reads the
# cell's four corner nodes (two runs of two neighbouring nodes) and interpolates them, as
# :func:`bilinear` does: the one scalar loop.
NodeGrid = namedtuple("NodeGrid", "nodes grids e0 n0 inv_re inv_rn nx ny")
MAX_NODES = 2**31 - 1  # node indices are int32 (they vectorise; int64 conversions do not with AVX2)


def node_grid(grid: "Map", z2: np.ndarray | None = None) -> NodeGrid:
    """The map as the filters read it: its heights (and a second grid ``z2`` of its shape, if
    given) interleaved node by node, flat."""
    return node_grid_of(*grid.kernel_args(), z2=z2)


def node_grid_of(z, e0, n0, inv_re, inv_rn, z2=None) -> NodeGrid:
    """:func:`node_grid` of a map given as its kernel arguments (``Map.kernel_args()``)."""
    ny, nx = z.shape
    if ny * nx > MAX_NODES:
        raise ValueError(f"the navigation map has {ny * nx} nodes; the filters take at most {MAX_NODES}")
    nodes = z if z2 is None else np.stack([z, np.asarray(z2, dtype=np.float64)], axis=-1)
    return NodeGrid(np.ascontiguousarray(nodes, dtype=np.float64).reshape(-1), 1 if z2 is None else 2,
                    float(e0), float(n0), float(inv_re), float(inv_rn), nx, ny)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def locate_cell(e, n, e0, n0, inv_re, inv_rn, nx, ny):
    """(node, tx, ty) of the point (e, n): ``node`` is the index (row i * nx + column j) of its
    cell's lower-left node, -1 outside the node extent (or for a NaN point); (tx, ty) its
    position in the cell. Branch free (for SIMD loops)."""
    fx = (e - e0) * inv_re
    fy = (n - n0) * inv_rn
    inside = (fx >= 0.0) & (fy >= 0.0) & (fx <= nx - 1 + EDGE_TOL) & (fy <= ny - 1 + EDGE_TOL)
    jj = np.int32(min(fx, nx - 2.0) if inside else 0.0)
    ii = np.int32(min(fy, ny - 2.0) if inside else 0.0)
    return (ii * np.int32(nx) + jj if inside else np.int32(-1)), fx - jj, fy - ii


@nb.njit(cache=True, error_model="numpy")
def locate_cells(e, n, e0, n0, inv_re, inv_rn, nx, ny, cell, tx, ty):
    """:func:`locate_cell` of every point (arrays ``e``, ``n``) into ``cell`` (int32), ``tx``, ``ty``."""
    for j in range(e.shape[0]):
        cell[j], tx[j], ty[j] = locate_cell(e[j], n[j], e0, n0, inv_re, inv_rn, nx, ny)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def interpolate_cells(cell, tx, ty, nodes, grids, nx, values):
    """Bilinear value of each of the ``grids`` grids of ``nodes`` (``NodeGrid`` order) at every
    point, from its cell ``cell[j]`` and position (``tx[j]``, ``ty[j]``) in it: row ``g`` of
    ``values`` (grids, M) for grid ``g``; the same arithmetic as :func:`bilinear`. Where
    ``cell[j]`` is -1 cell 0 is read (its value is never used). The one scalar loop of the
    look-up: its loads follow the points; it stores two values per point, where a copy of the
    cell's corners for a SIMD loop to interpolate stored eight (docs/speed.md 0b)."""
    if grids == 2:
        row = 2 * nx
        h, v = values[0], values[1]
        for j in range(cell.shape[0]):  # the corners as 1-D views: no 2-D index arithmetic per value
            k = 2 * max(cell[j], 0)
            low = nodes[k:k + 4]
            high = nodes[k + row:k + row + 4]
            a, b = tx[j], ty[j]
            h[j] = _bilinear_weights(low[0], low[2], high[0], high[2], a, b)
            v[j] = _bilinear_weights(low[1], low[3], high[1], high[3], a, b)
    else:
        h = values[0]
        for j in range(cell.shape[0]):
            k = max(cell[j], 0)
            h[j] = _bilinear_weights(nodes[k], nodes[k + 1], nodes[k + nx], nodes[k + nx + 1], tx[j], ty[j])


def node_grid_at(grid: NodeGrid, e, n, which: int = 0) -> np.ndarray:
    """Grid ``which`` of ``grid`` at the points (e, n) (1-D arrays) by the three look-up kernels:
    what the filters read (NaN outside)."""
    e = np.ascontiguousarray(e, dtype=np.float64)
    n = np.ascontiguousarray(n, dtype=np.float64)
    cell, tx, ty = np.empty(e.size, dtype=np.int32), np.empty(e.size), np.empty(e.size)
    locate_cells(e, n, grid.e0, grid.n0, grid.inv_re, grid.inv_rn, grid.nx, grid.ny, cell, tx, ty)
    values = np.empty((grid.grids, e.size))
    interpolate_cells(cell, tx, ty, grid.nodes, grid.grids, grid.nx, values)
    return np.where(cell >= 0, values[which], np.nan)
