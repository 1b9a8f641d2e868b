"""Terrain from bathymetry files: one grid or a mosaic of tiles, as the true seafloor.

A real map is both truth and map: the file's grid (bilinearly interpolated) is the
seafloor the sonar sees, and navigation maps are derived from it as for synthetic
terrain (``derive.py``). Relative paths are resolved against the working directory
(run tanbench from the project root); a path may be a glob matching several tiles.
No-data holes are kept unless ``fill_holes`` is set: a hole under the track is then
refused with its location (``simulation.check_track_on_map``).
"""

from __future__ import annotations

import glob
from pathlib import Path

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.terrain.grid import Map


def resolve_paths(path) -> list[Path]:
    """The files a terrain ``path`` (a file, a list of files, or a glob) names."""
    items = [path] if isinstance(path, str) else list(path)
    out: list[Path] = []
    for item in items:
        if any(ch in item for ch in "*?["):
            matches = sorted(glob.glob(item))
            if not matches:
                raise TanbenchError(f"terrain path {item!r} matches no file (from {Path.cwd()})")
            out.extend(Path(m) for m in matches)
        else:
            out.append(Path(item))
    return out


def load_file_terrain(spec) -> Map:
    """The truth seafloor read from ``spec.path`` (see :class:`tanbench.config.TerrainSpec`)."""
    from tanbench.terrain.readers import fill_holes, read_grid, read_tiles

    paths = resolve_paths(spec.path)
    options = dict(bounds=spec.bounds, origin=spec.origin, resolution=spec.resolution, rows=spec.rows,
                   crs=spec.crs, nodata=spec.nodata)
    if len(paths) == 1 and not (isinstance(spec.path, str) and any(c in spec.path for c in "*?[")):
        grid = read_grid(paths[0], spec.format, **options)
    else:
        grid, _ = read_tiles(paths, spec.format, **options)
    if np.isnan(grid.z).all():
        raise TanbenchError(f"terrain {spec.path}: the map holds no data (every node is no-data)")
    if spec.fill_holes and np.isnan(grid.z).any():
        grid = fill_holes(grid)
    meta = {**grid.meta, "kind": "file", "path": [str(p) for p in paths]}
    return Map(z=grid.z, e0=grid.e0, n0=grid.n0, res_e=grid.res_e, res_n=grid.res_n,
               name=f"file:{paths[0].name}" + (f"+{len(paths) - 1}" if len(paths) > 1 else ""), meta=meta)
