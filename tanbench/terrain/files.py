"""Terrain from bathymetry files: one grid or a mosaic of tiles, as the true seafloor.

Reading a file happens in three steps:

1. *Raw read*: the format's reader (:mod:`tanbench.terrain.formats`, chosen by the file's
   suffix or ``format``) gives the array as stored plus whatever georeferencing the file
   carries (GeoTIFF tags, NetCDF coordinate vectors, the ESRI ASCII header, npz keys).
2. *Georeferencing* (:mod:`tanbench.terrain.georef`): explicit ``bounds`` / ``origin`` /
   ``resolution`` / ``rows`` / ``crs`` arguments complete or replace the file's own; the
   grid is flipped so that row 0 is south and column 0 is west.
3. *Projection*: native geographic and Web-Mercator grids go through
   :func:`~tanbench.terrain.georef.to_local`, a local tangent plane whose origin is the
   south-west node.

:func:`read_grid` reads one file; :func:`read_tiles` reads several, mosaics them in native
coordinates (:mod:`tanbench.terrain.mosaic`) and projects once. Every bad-input problem
raises :class:`~tanbench.errors.TanbenchError` with one line naming the file and the problem.

In a sweep (``terrain: {kind: file}``) a real map is both truth and map: the file's grid
(bilinearly interpolated) is the seafloor the sonar sees, and navigation maps are derived
from it as for synthetic terrain (``derive.py``). Relative paths are resolved against the
working directory (run tanbench from the project root); a path may be a glob matching
several tiles. No-data holes are kept unless ``fill_holes`` is set: a hole under the track
is then refused with its location (``simulation.check_track_on_map``).
:func:`terrain_content_hash` identifies a file terrain by the bytes of its files.
"""

from __future__ import annotations

import glob
import hashlib
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.terrain.formats import read_raw
from tanbench.terrain.georef import (
    CRS_NAMES,
    bounds_from_name,
    check_name_against_grid,
    crs_from_name,
    georeference,
    native_point_to_local,
    to_local,
)
from tanbench.terrain.grid import Map
from tanbench.terrain.mosaic import MOSAIC_TOLERANCE, fill_holes, mosaic
from tanbench.terrain.reshape import reshape_terrain


def read_grid(
    path,
    format: str | None = None,
    *,
    bounds=None,
    origin=None,
    resolution=None,
    rows: str = "auto",
    crs: str | None = None,
    nodata: float | None = None,
    project: bool = True,
) -> Map:
    """Read one bathymetry grid file into a :class:`Map` (metres, row 0 south).

    ``format`` is a registered format (:data:`tanbench.terrain.formats.FORMATS`; default:
    the one the file's suffix selects). The file's own georeferencing is used unless
    replaced by arguments:

    - ``bounds=(x_min, x_max, y_min, y_max)``: coordinates of the first and last nodes
      (metres for ``crs='metric'``; lon/lat degrees for ``'epsg4326'`` and
      ``'epsg3857'``). Replaces the file's georeferencing; ``rows`` must then be given.
    - ``origin=(x0, y0)``: position of the stored node ``[0, 0]``; ``resolution``: a
      positive spacing, or ``(res_e, res_n)``, in the grid's own units (metres, degrees,
      or Web-Mercator metres). With ``rows='auto'`` a raw array follows the Map
      convention (row 0 south).
    - ``rows``: ``'auto'`` (from the file), ``'south_to_north'`` or ``'north_to_south'``;
      an explicit value that contradicts the file is an error.
    - ``crs``: ``'metric'``, ``'epsg4326'`` or ``'epsg3857'``; default from the file
      (GeoTIFF geokeys, NetCDF lon/lat names or degree units), else metric.
    - ``nodata``: an extra value to treat as missing (file nodata markers always are).

    NaN and nodata nodes stay NaN. Geographic and Web-Mercator grids are projected with
    :func:`~tanbench.terrain.georef.to_local` unless ``project=False`` (then the Map is in
    native units, for :func:`~tanbench.terrain.mosaic.mosaic` before projection).
    """
    path = _check_path(path)
    fmt, raw = read_raw(path, format)
    native = georeference(raw, path, fmt, bounds=bounds, origin=origin,
                          resolution=resolution, rows=rows, crs=crs, nodata=nodata)
    return to_local(native) if project else native


def read_tiles(
    paths,
    format: str | None = None,
    *,
    bounds=None,
    origin=None,
    resolution=None,
    rows: str = "auto",
    crs: str | None = None,
    nodata: float | None = None,
    tol: float = MOSAIC_TOLERANCE,
) -> tuple[Map, list[dict]]:
    """Read several tiles with the same options, mosaic them natively, project once.

    Mosaicking happens in the tiles' own coordinates (metres, lon/lat degrees or
    Web-Mercator metres) so that geographic tiles are projected as one grid, in one
    local frame. ``bounds`` and ``origin`` may be given per tile (a list, one entry per
    path). A tile with no georeferencing of its own and no explicit bounds takes its
    bounds from its file name (:func:`~tanbench.terrain.georef.parse_bounds_from_name`), and its crs from an
    ``.epsg<code>.`` token in the name when ``crs`` is not given. When a tile carries
    its own georeferencing *and* a name with bounds, the two must agree: each named
    bound must fall on a node of the tile's grid. Returns ``(map, seams)`` as
    :func:`~tanbench.terrain.mosaic.mosaic` does, with seam locations in the local frame.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    paths = [_check_path(p) for p in paths]
    if not paths:
        raise TanbenchError("read_tiles: no tile files given")
    per_bounds = _per_tile(bounds, len(paths), "bounds")
    per_origin = _per_tile(origin, len(paths), "origin")
    tiles = []
    for path, tile_bounds, tile_origin in zip(paths, per_bounds, per_origin):
        fmt, raw = read_raw(path, format)
        name_bounds = bounds_from_name(path)
        tile_crs = crs
        from_name = False
        if tile_bounds is None and tile_origin is None and not raw.complete and name_bounds:
            tile_bounds = name_bounds
            from_name = True
            if tile_crs is None:
                tile_crs = crs_from_name(path)
                if tile_crs is None:
                    raise TanbenchError(
                        f"{path}: bounds come from the file name but its crs is unknown: "
                        f"pass crs= ({CRS_NAMES})"
                    )
        native = georeference(raw, path, fmt, bounds=tile_bounds, origin=tile_origin,
                              resolution=resolution, rows=rows, crs=tile_crs, nodata=nodata)
        if from_name:
            native.meta["georef"] = "file name"
        elif name_bounds is not None and tile_bounds is None:
            check_name_against_grid(native, path, name_bounds)
        tiles.append(native)
    joined, seams = mosaic(tiles, tol=tol)
    local = to_local(joined)
    if local is not joined:
        for seam in seams:
            seam["worst_at"] = native_point_to_local(local, joined.meta["crs"], *seam["worst_at"])
    local.meta["seams"] = seams
    return local, seams


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
    The readers refuse a grid without any valid node. A grid of depths (``positive:
    down``) is negated into elevations.
    """
    paths = resolve_paths(spec.path)
    options = dict(bounds=spec.bounds, origin=spec.origin, resolution=spec.resolution, rows=spec.rows,
                   crs=spec.crs, nodata=spec.nodata)
    if len(paths) == 1 and not (isinstance(spec.path, str) and _is_glob(spec.path)):
        grid = read_grid(paths[0], spec.format, **options)
    else:
        grid, _ = read_tiles(paths, spec.format, **options)
    if spec.positive == "down":
        grid = replace(grid, z=-grid.z)
    if spec.fill_holes:
        grid = fill_holes(grid)
    grid = reshape_terrain(grid, spec.resample_m, spec.depth_range_m, spec.transform)
    name = f"file:{paths[0].name}" + (f"+{len(paths) - 1}" if len(paths) > 1 else "")
    return replace(grid, name=name, meta={**grid.meta, "kind": "file", "path": [str(p) for p in paths]})


def terrain_content_hash(spec) -> str | None:
    """sha256 (hex) of the content of a file terrain's files, in the order they are read.

    The sha256 of the sequence of each file's own sha256, over every file ``spec.path``
    resolves to (a glob's matches in sorted order). It covers the bytes, not the names: moving or renaming the files keeps it, editing any
    of them changes it. Each file's digest is cached per (path, size, mtime), so a sweep
    hashes a file once. None for a synthetic terrain (its spec is its whole identity).
    """
    if spec.kind != "file":
        return None
    total = hashlib.sha256()
    for path in resolve_paths(spec.path):
        total.update(_file_digest(_check_path(path)))
    return total.hexdigest()


_FILE_DIGESTS: dict[tuple[str, int, int], bytes] = {}


def _file_digest(path: Path) -> bytes:
    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns)
    digest = _FILE_DIGESTS.get(key)
    if digest is None:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        digest = _FILE_DIGESTS[key] = h.digest()
    return digest


def _check_path(path) -> Path:
    try:
        p = Path(os.fspath(path))
    except TypeError:
        raise TanbenchError(f"not a file path: {path!r}") from None
    if not p.exists():
        raise TanbenchError(f"{p}: file not found")
    if not p.is_file():
        raise TanbenchError(f"{p}: not a regular file")
    if not os.access(p, os.R_OK):
        raise TanbenchError(f"{p}: file is not readable (permission denied)")
    return p


def _per_tile(value, count: int, what: str) -> list:
    """Expand a per-tile option: None, or a list with one entry per tile."""
    if value is None:
        return [None] * count
    nested = np.ndim(value) == 2 or (isinstance(value, (list, tuple)) and value
                                     and all(v is None or np.ndim(v) == 1 for v in value))
    if not nested:
        raise TanbenchError(f"read_tiles: {what} must be given per tile (a list with one entry per file)")
    if len(value) != count:
        raise TanbenchError(f"read_tiles: {what} has {len(value)} entries for {count} files")
    return list(value)
