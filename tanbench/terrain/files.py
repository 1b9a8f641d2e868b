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
from dataclasses import replace
from pathlib import Path

from tanbench.errors import TanbenchError
from tanbench.terrain.grid import Map


def _is_glob(item: str) -> bool:
    return any(ch in item for ch in "*?[")


def resolve_paths(path) -> list[Path]:
    """The files a terrain ``path`` (a file, a list of files, or a glob) names."""
    items = [path] if isinstance(path, str) else list(path)
    out: list[Path] = []
    for item in items:
        if _is_glob(item):
            matches = sorted(glob.glob(item))
            if not matches:
                raise TanbenchError(f"terrain path {item!r} matches no file (from {Path.cwd()})")
            out.extend(Path(m) for m in matches)
        else:
            out.append(Path(item))
    return out


def load_file_terrain(spec) -> Map:
    """The truth seafloor read from ``spec.path`` (see :class:`tanbench.config.TerrainSpec`).

    One named file is read as it is; several files, or a glob, as tiles of one mosaic.
    The readers refuse a grid without any valid node.
    """
    from tanbench.terrain.readers import fill_holes, read_grid, read_tiles

    paths = resolve_paths(spec.path)
    options = dict(bounds=spec.bounds, origin=spec.origin, resolution=spec.resolution, rows=spec.rows,
                   crs=spec.crs, nodata=spec.nodata)
    if len(paths) == 1 and not (isinstance(spec.path, str) and _is_glob(spec.path)):
        grid = read_grid(paths[0], spec.format, **options)
    else:
        grid, _ = read_tiles(paths, spec.format, **options)
    if spec.fill_holes:
        grid = fill_holes(grid)
    name = f"file:{paths[0].name}" + (f"+{len(paths) - 1}" if len(paths) > 1 else "")
    return replace(grid, name=name, meta={**grid.meta, "kind": "file", "path": [str(p) for p in paths]})
