"""Reshaping a file terrain into another test world (issue 24): resampling, depth rescaling, transforms.

``terrain.resample_m`` resamples the file's grid bilinearly onto square nodes of that
spacing (from the grid's origin node); ``terrain.depth_range_m: [low, high]`` rescales the
elevations linearly so that the lowest node is at ``low`` and the highest at ``high``;
``terrain.transform`` then lays the same relief out differently: ``transpose`` (east and
north swapped) or ``mirror-east`` (mirrored east-west), about the origin node. With these a
sweep builds the issue's real-relief world from configs (a real DEM rescaled to -180..-60 m
on 8 m truth nodes; the 24 m map is ``map_resolution_m``): ``configs/relief.yaml``.

A ``resample_m`` whose grid would have fewer than 2 x 2 nodes, more than a map may have, or
need more than half this machine's memory is refused before anything is allocated, in one
line naming ``terrain.resample_m`` (:func:`check_resampled_size`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from tanbench.arrays import physical_memory
from tanbench.errors import TanbenchError
from tanbench.terrain.grid import MAX_NODES, Map

# Peak memory of resampling, per node of the new grid: the east and north coordinate grids and
# the elevations (8 bytes each), and a copy of the map for the workers.
BYTES_PER_RESAMPLED_NODE = 32


def reshape_terrain(grid: Map, resample_m: float | None, depth_range_m, transform: str) -> Map:
    """``grid`` resampled, rescaled and transformed as the module says (each step optional)."""
    z = grid.z
    res_e, res_n = grid.res_e, grid.res_n
    if resample_m is not None:
        check_resampled_size(grid, resample_m)
        e = np.arange(0.0, grid.e_max - grid.e0 + 1e-9, resample_m)
        n = np.arange(0.0, grid.n_max - grid.n0 + 1e-9, resample_m)
        ee, nn = np.meshgrid(grid.e0 + e, grid.n0 + n)
        z = grid.elevation(ee.ravel(), nn.ravel()).reshape(ee.shape)
        res_e = res_n = float(resample_m)
    if depth_range_m is not None:
        lo, hi = float(depth_range_m[0]), float(depth_range_m[1])
        zmin, zmax = np.nanmin(z), np.nanmax(z)
        if not zmax > zmin:
            raise TanbenchError("terrain depth_range_m: the file's grid is flat, there is nothing to rescale")
        z = lo + (z - zmin) / (zmax - zmin) * (hi - lo)
    if transform == "transpose":
        z = z.T.copy()
        res_e, res_n = res_n, res_e
    elif transform == "mirror-east":
        z = z[:, ::-1].copy()
    if z is grid.z:
        return grid
    return replace(grid, z=z, res_e=res_e, res_n=res_n,
                   meta={**grid.meta, "resample_m": resample_m, "depth_range_m": depth_range_m,
                         "transform": transform})


def resampled_shape(grid: Map, resample_m: float) -> tuple[int, int]:
    """(rows, columns) of ``grid`` resampled onto square nodes ``resample_m`` apart (as
    :func:`reshape_terrain` lays them out), computed without building them."""
    def count(extent):  # len(np.arange(0.0, extent + 1e-9, resample_m))
        return max(int(math.ceil((extent + 1e-9) / resample_m)), 0)
    return count(grid.n_max - grid.n0), count(grid.e_max - grid.e0)


def check_resampled_size(grid: Map, resample_m: float) -> None:
    """Refuse a ``terrain.resample_m`` whose grid would have fewer than 2 x 2 nodes, more nodes
    than a map may have (the filters' int32 node indices), or need more than half this machine's
    memory: one line naming the setting, before anything is allocated."""
    ny, nx = resampled_shape(grid, resample_m)
    width, height = grid.e_max - grid.e0, grid.n_max - grid.n0
    what = (f"terrain.resample_m ({resample_m:g} m) resamples the {width:g} x {height:g} m grid onto "
            f"{nx} x {ny} nodes")
    if nx < 2 or ny < 2:
        raise TanbenchError(f"{what}; a map needs at least 2 x 2: use a resample_m of at most "
                            f"{_round_down(min(width, height))} m")
    nodes = nx * ny
    memory = physical_memory()
    limit, why = MAX_NODES, "a map may have"
    if memory is not None and memory / 2 / BYTES_PER_RESAMPLED_NODE < limit:
        limit = int(memory / 2 / BYTES_PER_RESAMPLED_NODE)
        why = f"fit in half of this machine's {memory / 1e9:.3g} GB"
    if nodes > limit:
        finest = math.sqrt(width * height / limit)
        while resampled_shape(grid, finest)[0] * resampled_shape(grid, finest)[1] > limit:
            finest *= 1.001
        raise TanbenchError(f"{what} ({nodes:.3g}), more than the {limit:.3g} that {why}: use a coarser "
                            f"resample_m (at least {_round_up(finest)} m)")


def _round_up(x: float) -> str:
    """``x`` rounded up to 3 significant digits."""
    scale = 10.0 ** (math.floor(math.log10(x)) - 2)
    return f"{math.ceil(x / scale) * scale:.3g}"


def _round_down(x: float) -> str:
    """``x`` rounded down to 3 significant digits."""
    scale = 10.0 ** (math.floor(math.log10(x)) - 2)
    return f"{math.floor(x / scale) * scale:.3g}"


def reshape_terrain_numpy(z, e0, n0, res_e, res_n, resample_m, depth_range_m, transform):
    """Plain reference on arrays (scipy's bilinear interpolation): the reshaped z."""
    from scipy.interpolate import RegularGridInterpolator

    z = np.asarray(z, float)
    if resample_m is not None:
        ge = e0 + np.arange(z.shape[1]) * res_e
        gn = n0 + np.arange(z.shape[0]) * res_n
        e = e0 + np.arange(0.0, ge[-1] - e0 + 1e-9, resample_m)
        n = n0 + np.arange(0.0, gn[-1] - n0 + 1e-9, resample_m)
        nn, ee = np.meshgrid(n, e, indexing="ij")
        z = RegularGridInterpolator((gn, ge), z)(np.stack([nn.ravel(), ee.ravel()], axis=1)).reshape(nn.shape)
    if depth_range_m is not None:
        z = depth_range_m[0] + (z - z.min()) / (z.max() - z.min()) * (depth_range_m[1] - depth_range_m[0])
    if transform == "transpose":
        z = z.T
    elif transform == "mirror-east":
        z = z[:, ::-1]
    return z
