"""Readers for real bathymetry grids: GeoTIFF, GMT/COARDS NetCDF, ESRI ASCII, npy/npz.

Every reader returns a :class:`~tanbench.terrain.grid.Map`: elevations in metres, up
positive, on a regular grid in a local east/north metric frame with row 0 at the south.
Reading happens in three steps:

1. *Raw read*: the array as stored plus whatever georeferencing the file carries
   (GeoTIFF tags, NetCDF coordinate vectors, the ESRI ASCII header, npz keys).
2. *Georeferencing*: explicit ``bounds`` / ``origin`` / ``resolution`` / ``rows`` /
   ``crs`` arguments complete or replace the file's own; the grid is flipped so that
   row 0 is south and column 0 is west. The result is a "native" Map whose units are
   metres for a metric grid, degrees for a geographic (EPSG:4326) grid and Web-Mercator
   metres for an EPSG:3857 grid (``meta["crs"]`` says which).
3. *Projection*: native geographic and Web-Mercator grids go through :func:`to_local`,
   a local tangent plane (equirectangular about the centre latitude, WGS84 radii of
   curvature) whose origin is the south-west node.

Tiles are joined with :func:`mosaic` (one grid, overlaps averaged, a seam report per
join); :func:`read_tiles` reads, mosaics in native coordinates and projects once.
:func:`find_holes` and :func:`fill_holes` deal with NaN nodes, which the readers keep.

Every bad-input problem raises :class:`~tanbench.errors.TanbenchError` with one line
naming the file and the problem.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tanbench.earth import WGS84_A, WGS84_E2, radii_of_curvature
from tanbench.errors import TanbenchError
from tanbench.terrain.grid import Map


FORMATS: dict[str, tuple[str, ...]] = {
    "geotiff": (".tif", ".tiff"),
    "netcdf": (".nc", ".grd", ".nc4", ".cdf"),
    "esri-ascii": (".asc",),
    "npy": (".npy",),
    "npz": (".npz",),
}
"""Known formats and the file extensions that select them."""

_FORMAT_ALIASES = {
    "tif": "geotiff", "tiff": "geotiff", "gtiff": "geotiff",
    "nc": "netcdf", "gmt": "netcdf", "grd": "netcdf", "netcdf4": "netcdf",
    "asc": "esri-ascii", "ascii": "esri-ascii", "esri": "esri-ascii", "aaigrid": "esri-ascii",
}

_CRS_ALIASES = {
    "metric": "metric", "local": "metric", "projected": "metric", "metres": "metric",
    "meters": "metric", "m": "metric",
    "epsg4326": "epsg4326", "wgs84": "epsg4326", "geographic": "epsg4326",
    "lonlat": "epsg4326", "crs84": "epsg4326",
    "epsg3857": "epsg3857", "webmercator": "epsg3857", "pseudomercator": "epsg3857",
    "epsg3785": "epsg3857", "epsg900913": "epsg3857",
}
_CRS_NAMES = "'metric', 'epsg4326' (lon/lat degrees) or 'epsg3857' (Web Mercator)"
_WEB_MERCATOR_CODES = {3857, 3785, 900913, 102100, 102113}
_ROWS = ("auto", "south_to_north", "north_to_south")

# Positions that differ from the mosaic grid by less than this fraction of a cell are "on" it.
MOSAIC_TOLERANCE = 0.05


# --------------------------------------------------------------------------------------
# Public entry points
# --------------------------------------------------------------------------------------


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

    ``format`` is one of :data:`FORMATS` (default: from the file extension). The file's
    own georeferencing is used unless replaced by arguments:

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
    :func:`to_local` unless ``project=False`` (then the Map is in native units, for
    :func:`mosaic` before projection).
    """
    path = _check_path(path)
    fmt = _resolve_format(path, format)
    raw = _READERS[fmt](path)
    native = _georeference(raw, path, fmt, bounds=bounds, origin=origin,
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
    bounds from its file name (:func:`parse_bounds_from_name`), and its crs from an
    ``.epsg<code>.`` token in the name when ``crs`` is not given. When a tile carries
    its own georeferencing *and* a name with bounds, the two must agree: each named
    bound must fall on a node of the tile's grid. Returns ``(map, seams)`` as
    :func:`mosaic` does, with seam locations in the local frame.
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
        fmt = _resolve_format(path, format)
        raw = _READERS[fmt](path)
        name_bounds = _try_bounds_from_name(path)
        tile_crs = crs
        from_name = False
        if tile_bounds is None and tile_origin is None and not raw.complete and name_bounds:
            tile_bounds = name_bounds
            from_name = True
            if tile_crs is None:
                tile_crs = _crs_from_name(path)
                if tile_crs is None:
                    raise TanbenchError(
                        f"{path}: bounds come from the file name but its crs is unknown: "
                        f"pass crs= ({_CRS_NAMES})"
                    )
        native = _georeference(raw, path, fmt, bounds=tile_bounds, origin=tile_origin,
                               resolution=resolution, rows=rows, crs=tile_crs, nodata=nodata)
        if from_name:
            native.meta["georef"] = "file name"
        elif name_bounds is not None and tile_bounds is None:
            _check_name_against_grid(native, path, name_bounds)
        tiles.append(native)
    joined, seams = mosaic(tiles, tol=tol)
    local = to_local(joined)
    if local is not joined:
        for seam in seams:
            seam["worst_at"] = _native_point_to_local(local, joined.meta["crs"], *seam["worst_at"])
    local.meta["seams"] = seams
    return local, seams


def parse_bounds_from_name(path) -> tuple[float, float, float, float]:
    """Bounds ``(lon_min, lon_max, lat_min, lat_max)`` from a ``...R_<b>_<b>_<b>_<b>.`` name.

    The naming scheme of tiled DEMs such as
    ``MontereyBay.R_-121.825_-121.815_36.790_36.800.epsg3857.tif``.
    """
    bounds = _try_bounds_from_name(path)
    if bounds is None:
        raise TanbenchError(
            f"{path}: the file name carries no bounds; expected a name like "
            f"'<name>.R_<lon_min>_<lon_max>_<lat_min>_<lat_max>.<crs>.tif'"
        )
    return bounds


def to_local(native: Map) -> Map:
    """Project a geographic or Web-Mercator native Map into a local metric frame.

    The frame is a local tangent plane, equirectangular about the centre latitude
    ``lat_c`` of the grid, with the WGS84 meridian and transverse radii of curvature
    ``R_N = a(1-e^2)/(1-e^2 sin^2 lat_c)^1.5`` and ``R_E = a/(1-e^2 sin^2 lat_c)^0.5``:
    ``e = R_E cos(lat_c) (lon - lon0)``, ``n = R_N (lat - lat0)`` (radians), with the
    south-west node ``(lon0, lat0)`` at ``(0, 0)``. A lon/lat grid stays exactly regular.
    A Web-Mercator grid has rows evenly spaced in Mercator y, not in latitude: it is
    resampled (linearly between rows, the columns being exact) onto as many evenly
    spaced rows between the same first and last latitudes.

    Against an exact ECEF -> ENU tangent plane at the grid centre the frame is off by
    about ``1.12 h^2 tan(lat_c) / R`` at the corners of a square of half-size ``h``
    (meridians converge): 0.03 m for 1 km x 1 km and 0.30 m for 3 km x 3 km at 37 deg N,
    0.68 m for 3 km x 3 km at 60 deg N, 3.3 m for 10 km x 10 km at 37 deg N. The figure
    for each grid is computed at its corners and edge midpoints and kept in
    ``meta["projection_error_m"]``. Metric maps are returned unchanged.
    """
    crs = native.meta.get("crs", "metric")
    if crs in ("metric", "local"):
        return native
    if crs not in ("epsg4326", "epsg3857"):
        raise TanbenchError(f"{native.meta.get('source', native.name)}: unknown crs {crs!r}")
    x, y = native.node_coords()
    lon, lat = _native_to_lonlat(crs, x, y)
    lon0, lat0 = float(lon[0]), float(lat[0])
    lat_c = 0.5 * (lat0 + float(lat[-1]))
    k_e, k_n = _metres_per_degree(lat_c)
    e = k_e * (lon - lon0)
    n_nodes = k_n * (lat - lat0)
    ny = native.z.shape[0]
    res_e = float(e[-1] / (len(e) - 1))
    res_n = float(n_nodes[-1] / (ny - 1))
    if crs == "epsg4326":
        z = native.z
    else:
        z = _resample_rows(native.z, n_nodes, res_n * np.arange(ny))
    meta = dict(native.meta)
    meta.update(
        crs="local",
        source_crs=crs,
        lon0=lon0,
        lat0=lat0,
        lat_c=lat_c,
        m_per_deg_lon=k_e,
        m_per_deg_lat=k_n,
        projection=(
            "local tangent plane, equirectangular about lat_c with WGS84 radii of "
            "curvature; origin (0, 0) at the south-west node (lon0, lat0)"
        ),
    )
    local = Map(z, 0.0, 0.0, res_e, res_n, name=native.name, meta=meta)
    local.meta["projection_error_m"] = _projection_error(local, lon, lat)
    return local


def lonlat_to_local(local: Map, lon, lat) -> tuple[np.ndarray, np.ndarray]:
    """Local (e, n) metres of WGS84 (lon, lat) degrees in a projected Map's frame."""
    k_e, k_n, lon0, lat0 = _frame(local)
    return (k_e * (np.asarray(lon, dtype=float) - lon0),
            k_n * (np.asarray(lat, dtype=float) - lat0))


def local_to_lonlat(local: Map, e, n) -> tuple[np.ndarray, np.ndarray]:
    """WGS84 (lon, lat) degrees of local (e, n) metres in a projected Map's frame."""
    k_e, k_n, lon0, lat0 = _frame(local)
    return (lon0 + np.asarray(e, dtype=float) / k_e, lat0 + np.asarray(n, dtype=float) / k_n)


def mosaic(maps, *, tol: float = MOSAIC_TOLERANCE) -> tuple[Map, list[dict]]:
    """Join tiles lying on one grid into one Map, averaging overlaps; report the seams.

    The tiles must share a crs and a spacing, with offsets that are whole multiples of
    it: every node of every tile must lie within ``tol`` cells of the common grid (whose
    spacing is the tiles' median spacing, anchored on the first tile), else
    :class:`TanbenchError`. Nodes covered by no tile are NaN; overlapping nodes take the
    mean of the tiles' finite values.

    One seam entry is returned per pair of tiles that overlap or share an edge:
    ``tiles`` (the two names), ``kind`` (``'overlap'``; ``'east-west'`` for tiles side
    by side, the seam running north-south; ``'north-south'`` for one tile above the
    other), ``pairs`` (node pairs compared, NaN pairs left out), ``mean_abs_step`` and
    ``max_abs_step`` and ``worst_at`` (the (e, n) of the largest step). For an overlap
    the step is the difference between the two tiles' values at the same node. For an
    edge the raw jump between the two node rows (columns) adjacent to the join is
    ``mean_abs_jump``; the step is that jump minus the slope seen on either side (the
    mean of the last difference inside each tile), so that a smooth surface, a plane
    included, gives a step of 0 and an offset between tiles shows in full.
    """
    maps = list(maps)
    if not maps:
        raise TanbenchError("mosaic: no tiles given")
    labels = [_label(m, k) for k, m in enumerate(maps)]
    crs_set = {m.meta.get("crs", "metric") for m in maps}
    if "local" in crs_set and len(maps) > 1:
        k = next(k for k, m in enumerate(maps) if m.meta.get("crs") == "local")
        raise TanbenchError(
            f"{labels[k]}: this tile was projected from geographic coordinates on its own; "
            f"mosaic geographic tiles before projecting them: use read_tiles(...) or "
            f"read_grid(..., project=False) then mosaic() then to_local()"
        )
    if len(crs_set) > 1:
        raise TanbenchError(
            "mosaic: tiles are in different coordinate systems ("
            + ", ".join(f"{lab}: {m.meta.get('crs', 'metric')}" for lab, m in zip(labels, maps))
            + ")"
        )
    if len(maps) == 1:
        return maps[0], []
    res_e = float(np.median([m.res_e for m in maps]))
    res_n = float(np.median([m.res_n for m in maps]))
    anchor_e, anchor_n = maps[0].e0, maps[0].n0
    cols, rows_, misplaced = [], [], []
    for m in maps:
        c, mis_e = _snap(m.e0, m.res_e, m.z.shape[1], anchor_e, res_e)
        r, mis_n = _snap(m.n0, m.res_n, m.z.shape[0], anchor_n, res_n)
        misplaced.append(max(mis_e, mis_n))
        cols.append(c)
        rows_.append(r)
    if max(misplaced) > tol:
        offenders = sorted((k for k, mis in enumerate(misplaced) if mis > tol), key=lambda k: -misplaced[k])
        raise TanbenchError(
            "; ".join(
                f"{labels[k]}: tile does not sit on the mosaic grid (spacing {maps[k].res_e:.6g} x "
                f"{maps[k].res_n:.6g} against {res_e:.6g} x {res_n:.6g}, nodes up to "
                f"{misplaced[k]:.3g} cells off)"
                for k in offenders
            )
            + f"; the grid is anchored on {labels[0]}, tolerance {tol:g} cells"
        )
    worst = max(misplaced)
    c_min, r_min = min(cols), min(rows_)
    cols = [c - c_min for c in cols]
    rows_ = [r - r_min for r in rows_]
    nx = max(c + m.z.shape[1] for c, m in zip(cols, maps))
    ny = max(r + m.z.shape[0] for r, m in zip(rows_, maps))
    total = np.zeros((ny, nx))
    count = np.zeros((ny, nx))
    for m, c, r in zip(maps, cols, rows_):
        ok = np.isfinite(m.z)
        h, w = m.z.shape
        total[r:r + h, c:c + w] += np.where(ok, m.z, 0.0)
        count[r:r + h, c:c + w] += ok
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    e0 = anchor_e + c_min * res_e
    n0 = anchor_n + r_min * res_n
    meta = {k: v for k, v in maps[0].meta.items() if k in ("crs", "format")}
    meta.update(
        sources=[m.meta.get("source", lab) for m, lab in zip(maps, labels)],
        tile_offsets=[(r, c) for r, c in zip(rows_, cols)],
        max_misplacement_cells=worst,
        uncovered_nodes=int((count == 0).sum()),
    )
    joined = Map(z, e0, n0, res_e, res_n, name=f"mosaic of {len(maps)} tiles", meta=meta)
    seams = _seams(maps, labels, rows_, cols, e0, n0, res_e, res_n)
    return joined, seams


def find_holes(grid: Map, e, n, margin: float = 0.0) -> list[tuple[float, float]]:
    """NaN nodes that bilinear look-ups at points (e, n) would touch: [(e, n), ...].

    A look-up reads the four nodes of the cell holding the point (as the kernel in
    :mod:`tanbench.terrain.grid` does); ``margin`` metres widen that to every cell
    within a box of half-width ``margin`` around the point (for a sonar footprint).
    Points whose box misses the grid altogether are not holes (check those with
    :meth:`Map.contains`). Holes are returned once each, south to north, west to east,
    so that a caller can reject a track with their locations or fill them on request.
    """
    if not (np.isfinite(margin) and margin >= 0):
        raise TanbenchError(f"find_holes: margin must be a non-negative number of metres, got {margin}")
    bad = np.isnan(grid.z)
    if not bad.any():
        return []
    e, n = np.broadcast_arrays(np.asarray(e, dtype=float), np.asarray(n, dtype=float))
    e, n = e.ravel(), n.ravel()
    ny, nx = grid.z.shape
    fx_lo = (e - margin - grid.e0) / grid.res_e
    fx_hi = (e + margin - grid.e0) / grid.res_e
    fy_lo = (n - margin - grid.n0) / grid.res_n
    fy_hi = (n + margin - grid.n0) / grid.res_n
    keep = (np.isfinite(e) & np.isfinite(n) & (fx_hi >= 0) & (fx_lo <= nx - 1)
            & (fy_hi >= 0) & (fy_lo <= ny - 1))
    if not keep.any():
        return []
    j_lo = np.clip(np.floor(fx_lo[keep]), 0, nx - 2).astype(np.int64)
    j_hi = np.clip(np.floor(fx_hi[keep]), 0, nx - 2).astype(np.int64) + 1
    i_lo = np.clip(np.floor(fy_lo[keep]), 0, ny - 2).astype(np.int64)
    i_hi = np.clip(np.floor(fy_hi[keep]), 0, ny - 2).astype(np.int64) + 1
    # Cover each point's node box with a 2-D difference array, then integrate it.
    cover = np.zeros((ny + 1, nx + 1), dtype=np.int64)
    np.add.at(cover, (i_lo, j_lo), 1)
    np.add.at(cover, (i_lo, j_hi + 1), -1)
    np.add.at(cover, (i_hi + 1, j_lo), -1)
    np.add.at(cover, (i_hi + 1, j_hi + 1), 1)
    touched = cover.cumsum(axis=0).cumsum(axis=1)[:ny, :nx] > 0
    ii, jj = np.nonzero(touched & bad)
    return [(float(grid.e0 + j * grid.res_e), float(grid.n0 + i * grid.res_n))
            for i, j in zip(ii, jj)]


def fill_holes(grid: Map, method: str = "laplace") -> Map:
    """A copy of ``grid`` with its NaN nodes filled, for callers that ask for it.

    ``method='laplace'`` (default) solves Laplace's equation over the holes with the
    known nodes around them as boundary values (anisotropic spacing respected, no flux
    through the map edges): a smooth membrane, no terraces, exact for a plane.
    ``method='nearest'`` copies the nearest known node (in metres). The number of filled
    nodes and the method go to ``meta["filled_nodes"]`` and ``meta["fill_method"]``.
    """
    if method not in ("laplace", "nearest"):
        raise TanbenchError(f"fill_holes: unknown method {method!r}; use 'laplace' or 'nearest'")
    bad = np.isnan(grid.z)
    n_bad = int(bad.sum())
    if n_bad == 0:
        return grid
    if n_bad == bad.size:
        raise TanbenchError(f"{_label(grid, 0)}: cannot fill holes, the map has no valid node")
    if method == "nearest":
        from scipy.ndimage import distance_transform_edt

        _, (ii, jj) = distance_transform_edt(bad, sampling=(grid.res_n, grid.res_e),
                                             return_indices=True)
        z = grid.z[ii, jj]
    else:
        z = _laplace_fill(grid.z, bad, grid.res_e, grid.res_n)
    meta = dict(grid.meta)
    meta.update(filled_nodes=n_bad, fill_method=method)
    return Map(z, grid.e0, grid.n0, grid.res_e, grid.res_n, name=grid.name, meta=meta)


def _laplace_fill(z: np.ndarray, bad: np.ndarray, res_e: float, res_n: float) -> np.ndarray:
    """Harmonic fill: each hole node is the weighted mean of its 4 neighbours (weights
    1/res^2 per axis), known nodes fixed; edge nodes simply have fewer neighbours."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    ny, nx = z.shape
    index = -np.ones(z.shape, dtype=np.int64)
    ii, jj = np.nonzero(bad)
    index[ii, jj] = np.arange(ii.size)
    rows, cols, vals = [], [], []
    diag = np.zeros(ii.size)
    rhs = np.zeros(ii.size)
    for di, dj, w in ((1, 0, res_n ** -2), (-1, 0, res_n ** -2), (0, 1, res_e ** -2), (0, -1, res_e ** -2)):
        ni, nj = ii + di, jj + dj
        inside = (ni >= 0) & (ni < ny) & (nj >= 0) & (nj < nx)
        k = np.flatnonzero(inside)
        diag[k] += w
        neighbour = index[ni[k], nj[k]]
        unknown = neighbour >= 0
        rows.append(k[unknown])
        cols.append(neighbour[unknown])
        vals.append(np.full(int(unknown.sum()), -w))
        rhs[k[~unknown]] += w * z[ni[k[~unknown]], nj[k[~unknown]]]
    rows.append(np.arange(ii.size))
    cols.append(np.arange(ii.size))
    vals.append(diag)
    matrix = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                        shape=(ii.size, ii.size)).tocsr()
    out = z.copy()
    out[ii, jj] = spsolve(matrix, rhs)
    return out


# --------------------------------------------------------------------------------------
# Raw readers: the array as stored and the file's own georeferencing
# --------------------------------------------------------------------------------------


@dataclass
class _Raw:
    """An array as stored, with the file's georeferencing where it has some.

    Stored node ``[i, j]`` sits at ``(x0 + j * dx, y0 + i * dy)``; a negative ``dy``
    means row 0 is the northern edge. ``crs`` is None when the file does not say.
    """

    z: np.ndarray
    georef: str = "none"
    x0: float | None = None
    y0: float | None = None
    dx: float | None = None
    dy: float | None = None
    crs: str | None = None
    problem: str = ""

    @property
    def complete(self) -> bool:
        return None not in (self.x0, self.y0, self.dx, self.dy)


def _read_geotiff(path: Path) -> _Raw:
    """GeoTIFF via tifffile: first image, ModelPixelScale/Tiepoint or ModelTransformation,
    GeoKeyDirectory (geographic / Web Mercator / other projected = metres), GDAL nodata."""
    try:
        import tifffile
    except ImportError:
        raise TanbenchError(
            f"{path}: reading GeoTIFF needs the tifffile package: pip install tifffile "
            f"(or pip install tanbench[maps])"
        ) from None
    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages[0]
            tags = {tag.code: tag.value for tag in page.tags.values()}
            z = page.asarray()
    except Exception as exc:
        raise TanbenchError(f"{path}: not a readable TIFF file ({type(exc).__name__}: {exc})") from None
    z = np.asarray(z)
    if z.ndim == 3 and 1 in (z.shape[0], z.shape[-1]):
        z = z.reshape(z.shape[1:] if z.shape[0] == 1 else z.shape[:2])
    if z.ndim != 2:
        raise TanbenchError(f"{path}: image has shape {z.shape}; expected one band of elevations")
    z = _as_float(z, path)
    if 42113 in tags:
        text = str(tags[42113]).strip().strip("\x00").strip()
        try:
            fill = float(text)
        except ValueError:
            raise TanbenchError(f"{path}: GDAL_NODATA tag {text!r} is not a number") from None
        z = _mask_value(z, fill)
    raw = _Raw(z)
    try:
        _geotiff_georef(raw, tags)
    except _GeoTagProblem as exc:
        raw.problem = str(exc)
    return raw


class _GeoTagProblem(Exception):
    """Unusable GeoTIFF georeferencing: fatal only when nothing replaces it."""


def _geotiff_georef(raw: _Raw, tags: dict) -> None:
    keys = _geokeys(tags)
    model = keys.get(1024)
    if model == 2:
        raw.crs = "epsg4326"
    elif model == 1:
        code = keys.get(3072)
        if code in _WEB_MERCATOR_CODES:
            raw.crs = "epsg3857"
        else:
            unit = keys.get(3076)
            if unit not in (None, 9001):
                raise _GeoTagProblem(
                    f"projected linear unit code {unit} is not metres (EPSG 9001); "
                    f"reproject the grid to metres"
                )
            raw.crs = "metric"
    elif model == 3:
        raise _GeoTagProblem("geocentric GeoTIFF model is not supported")
    # GTRasterTypeGeoKey: 1 = PixelIsArea (tie point at a pixel corner), 2 = PixelIsPoint.
    half = 0.0 if keys.get(1025, 1) == 2 else 0.5
    if 34264 in tags:
        m = [float(v) for v in tags[34264]]
        if len(m) != 16:
            raise _GeoTagProblem("ModelTransformationTag does not hold 16 values")
        if m[1] != 0.0 or m[4] != 0.0:
            raise _GeoTagProblem(
                "ModelTransformationTag is rotated or sheared; only north-up grids are supported"
            )
        raw.dx, raw.dy = m[0], m[5]
        raw.x0, raw.y0 = m[3] + half * m[0], m[7] + half * m[5]
    elif 33550 in tags and 33922 in tags:
        scale = [float(v) for v in tags[33550]]
        tie = [float(v) for v in tags[33922]]
        if len(tie) > 6:
            raise _GeoTagProblem("several ModelTiepoints (a warped grid) are not supported")
        if len(scale) < 2 or len(tie) < 6 or scale[0] == 0 or scale[1] == 0:
            raise _GeoTagProblem("ModelPixelScale/ModelTiepoint tags are malformed")
        i_tie, j_tie, _, x_tie, y_tie, _ = tie
        raw.dx, raw.dy = scale[0], -scale[1]
        raw.x0 = x_tie + (half - i_tie) * scale[0]
        raw.y0 = y_tie - (half - j_tie) * scale[1]
    elif 33550 in tags or 33922 in tags:
        raise _GeoTagProblem("has only one of ModelPixelScale and ModelTiepoint")
    else:
        return
    if not all(np.isfinite(v) for v in (raw.x0, raw.y0, raw.dx, raw.dy)):
        raise _GeoTagProblem("georeferencing tags hold non-finite values")
    raw.georef = "tags"


def _geokeys(tags: dict) -> dict:
    """GeoKeyDirectoryTag (34735) as {key id: value}, values resolved from 34736/34737."""
    directory = tags.get(34735)
    if directory is None:
        return {}
    try:
        d = [int(v) for v in directory]
        doubles = tags.get(34736)
        ascii_params = tags.get(34737)
        keys = {}
        for k in range(d[3]):
            key, loc, count, value = d[4 + 4 * k: 8 + 4 * k]
            if loc == 0:
                keys[key] = value
            elif loc == 34736 and doubles is not None:
                vals = tuple(float(v) for v in doubles[value:value + count])
                keys[key] = vals[0] if count == 1 else vals
            elif loc == 34737 and ascii_params is not None:
                keys[key] = str(ascii_params)[value:value + count].rstrip("|")
        return keys
    except (ValueError, TypeError, IndexError):
        raise _GeoTagProblem("GeoKeyDirectoryTag is malformed") from None


_NC_X = ("x", "lon", "longitude")
_NC_Y = ("y", "lat", "latitude")
_NC_Z = ("z", "elevation", "elev", "band1")


def _read_netcdf(path: Path) -> _Raw:
    """GMT/COARDS NetCDF: classic via scipy, NetCDF-4/HDF5 via h5py when installed."""
    with open(path, "rb") as fh:
        magic = fh.read(8)
    if magic.startswith(b"\x89HDF"):
        variables = _netcdf4_variables(path)
    elif magic.startswith(b"CDF"):
        from scipy.io import netcdf_file

        try:
            with netcdf_file(path, "r", mmap=False) as nc:
                variables = {
                    name: (np.array(var.data), dict(getattr(var, "_attributes", {})),
                           tuple(var.dimensions))
                    for name, var in nc.variables.items()
                }
        except Exception as exc:
            raise TanbenchError(f"{path}: not a readable NetCDF file ({type(exc).__name__}: {exc})") from None
    else:
        raise TanbenchError(f"{path}: not a NetCDF file (no CDF or HDF5 signature)")
    return _netcdf_raw(path, variables)


def _netcdf4_variables(path: Path) -> dict:
    try:
        import h5py
    except ImportError:
        raise TanbenchError(
            f"{path}: is a NetCDF-4 (HDF5) file; reading it needs h5py: pip install h5py "
            f"(or convert it to classic NetCDF: nccopy -k classic)"
        ) from None
    skip = {"DIMENSION_LIST", "REFERENCE_LIST", "CLASS", "NAME", "_Netcdf4Dimid",
            "_Netcdf4Coordinates", "_nc3_strict"}
    variables = {}
    try:
        with h5py.File(path, "r") as f:
            for name, obj in f.items():
                if not isinstance(obj, h5py.Dataset):
                    continue
                attrs = {}
                for key, value in obj.attrs.items():
                    if key in skip:
                        continue
                    if isinstance(value, bytes):
                        value = value.decode("utf-8", "replace")
                    attrs[key] = value
                dims = ()
                if "DIMENSION_LIST" in obj.attrs:
                    try:
                        dims = tuple(f[refs[0]].name.lstrip("/") for refs in obj.attrs["DIMENSION_LIST"])
                    except Exception:
                        dims = ()
                elif obj.ndim == 1:
                    dims = (name,)
                variables[name] = (np.array(obj[()]), attrs, dims)
    except Exception as exc:
        raise TanbenchError(f"{path}: not a readable NetCDF-4 file ({type(exc).__name__}: {exc})") from None
    return variables


def _netcdf_raw(path: Path, variables: dict) -> _Raw:
    lower = {name.lower(): name for name in variables}

    def pick(candidates):
        for cand in candidates:
            if cand in lower:
                return lower[cand]
        return None

    xname, yname = pick(_NC_X), pick(_NC_Y)
    if xname is None or yname is None:
        raise TanbenchError(
            f"{path}: no coordinate variables x/y, lon/lat or longitude/latitude "
            f"(variables: {', '.join(variables) or 'none'})"
        )
    zname = pick(_NC_Z)
    if zname is None:
        two_d = [name for name, (data, _, _) in variables.items() if data.ndim == 2]
        if len(two_d) != 1:
            raise TanbenchError(
                f"{path}: no elevation variable z or elevation (variables: {', '.join(variables)})"
            )
        zname = two_d[0]
    x, x_attrs, _ = variables[xname]
    y, y_attrs, _ = variables[yname]
    zdata, z_attrs, z_dims = variables[zname]
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 1 or y.ndim != 1 or zdata.ndim != 2:
        raise TanbenchError(
            f"{path}: expected 1-D {xname}, {yname} and a 2-D {zname}, got shapes "
            f"{x.shape}, {y.shape}, {zdata.shape}"
        )
    if z_dims == (xname, yname) or (not z_dims and zdata.shape == (x.size, y.size) != (y.size, x.size)):
        zdata = zdata.T
    if zdata.shape != (y.size, x.size):
        raise TanbenchError(
            f"{path}: {zname} has shape {zdata.shape} but {yname} x {xname} is {y.size} x {x.size}"
        )
    z = _unpack(zdata, z_attrs, path, zname)
    crs_x = _coord_kind(xname, x_attrs, path)
    crs_y = _coord_kind(yname, y_attrs, path)
    if "epsg4326" in (crs_x, crs_y) and crs_x != crs_y:
        raise TanbenchError(f"{path}: {xname} and {yname} are not both in degrees or both in metres")
    raw = _Raw(z, georef="coordinates", crs=crs_x)
    raw.x0, raw.dx = _even_spacing(x, xname, path)
    raw.y0, raw.dy = _even_spacing(y, yname, path)
    return raw


def _coord_kind(name: str, attrs: dict, path: Path) -> str | None:
    units = attrs.get("units", b"")
    if isinstance(units, (bytes, np.bytes_)):
        units = units.decode("ascii", "replace")
    units = str(units).strip().lower()
    if units.startswith("degree") or name.lower() in ("lon", "lat", "longitude", "latitude"):
        return "epsg4326"
    if units in ("", "m", "metre", "metres", "meter", "meters"):
        return "metric" if units else None
    raise TanbenchError(f"{path}: coordinate {name} is in units {units!r}; expected metres or degrees")


def _unpack(data: np.ndarray, attrs: dict, path: Path, name: str) -> np.ndarray:
    """CF unpacking: _FillValue / missing_value (packed units) -> NaN, then scale and offset."""
    mask = np.zeros(data.shape, dtype=bool)
    for key in ("_FillValue", "missing_value"):
        if key in attrs:
            for value in np.atleast_1d(np.asarray(attrs[key])).ravel():
                try:
                    value = float(value)
                except (TypeError, ValueError):
                    raise TanbenchError(f"{path}: {name}:{key} is not a number") from None
                if not np.isnan(value):
                    mask |= data == np.asarray(value).astype(data.dtype)
    z = _as_float(data, path)
    scale = _scalar_attr(attrs, "scale_factor", 1.0, path, name)
    offset = _scalar_attr(attrs, "add_offset", 0.0, path, name)
    z = z * scale + offset
    z[mask] = np.nan
    return z


def _scalar_attr(attrs, key, default, path, name) -> float:
    if key not in attrs:
        return default
    try:
        return float(np.asarray(attrs[key]).ravel()[0])
    except (TypeError, ValueError, IndexError):
        raise TanbenchError(f"{path}: {name}:{key} is not a number") from None


def _even_spacing(v: np.ndarray, name: str, path: Path) -> tuple[float, float]:
    """First value and step of an evenly spaced coordinate vector, else TanbenchError."""
    if v.size < 2 or not np.all(np.isfinite(v)):
        raise TanbenchError(f"{path}: coordinate {name} needs at least 2 finite values")
    step = (v[-1] - v[0]) / (v.size - 1)
    if step == 0:
        raise TanbenchError(f"{path}: coordinate {name} does not change")
    # Coordinates stored as float32 carry rounding of a few ulps of their magnitude.
    slack = 1e-3 * abs(step) + 8 * np.finfo(np.float32).eps * np.max(np.abs(v))
    if np.max(np.abs(v - (v[0] + step * np.arange(v.size)))) > slack:
        raise TanbenchError(
            f"{path}: coordinate {name} is not evenly spaced; tanbench reads regular grids only"
        )
    return float(v[0]), float(step)


_ASC_KEYS = ("ncols", "nrows", "xllcorner", "xllcenter", "xllcentre", "yllcorner", "yllcenter",
             "yllcentre", "cellsize", "dx", "dy", "nodata_value")


def _read_esri_ascii(path: Path) -> _Raw:
    """ESRI ASCII grid: header, then rows from north to south."""
    try:
        text = path.read_text(encoding="ascii")
    except (UnicodeDecodeError, OSError) as exc:
        raise TanbenchError(f"{path}: not a readable ESRI ASCII grid ({type(exc).__name__})") from None
    lines = text.splitlines()
    header: dict[str, float] = {}
    k = 0
    while k < len(lines):
        parts = lines[k].split()
        if not parts:
            k += 1
            continue
        key = parts[0].lower()
        if key[0].isalpha() and key not in ("nan", "inf", "infinity"):
            if key not in _ASC_KEYS or len(parts) != 2:
                raise TanbenchError(f"{path}: unexpected ESRI ASCII header line {lines[k].strip()!r}")
            try:
                header[key] = float(parts[1])
            except ValueError:
                raise TanbenchError(f"{path}: header {parts[0]} value {parts[1]!r} is not a number") from None
            k += 1
        else:
            break
    for need in ("ncols", "nrows"):
        if need not in header:
            raise TanbenchError(f"{path}: ESRI ASCII header lacks {need}")
    nx, ny = int(header["ncols"]), int(header["nrows"])
    if "cellsize" in header:
        dx = dy = header["cellsize"]
    elif "dx" in header and "dy" in header:
        dx, dy = header["dx"], header["dy"]
    else:
        raise TanbenchError(f"{path}: ESRI ASCII header lacks cellsize (or dx and dy)")
    if not (dx > 0 and dy > 0):
        raise TanbenchError(f"{path}: ESRI ASCII cell size must be positive, got {dx} x {dy}")
    x_ll = _asc_origin(header, "x", dx, path)
    y_ll = _asc_origin(header, "y", dy, path)
    try:
        values = np.array(" ".join(lines[k:]).split(), dtype=float)
    except ValueError:
        raise TanbenchError(f"{path}: ESRI ASCII data hold a value that is not a number") from None
    if values.size != nx * ny:
        raise TanbenchError(
            f"{path}: header says {ny} rows x {nx} columns but the file holds {values.size} values"
        )
    z = values.reshape(ny, nx)
    if "nodata_value" in header:
        z = _mask_value(z, header["nodata_value"])
    return _Raw(z, georef="header", x0=x_ll, y0=y_ll + (ny - 1) * dy, dx=dx, dy=-dy)


def _asc_origin(header: dict, axis: str, step: float, path: Path) -> float:
    """Centre of the lower-left cell from xll/yll corner or centre registration."""
    corner = header.get(f"{axis}llcorner")
    centre = header.get(f"{axis}llcenter", header.get(f"{axis}llcentre"))
    if (corner is None) == (centre is None):
        raise TanbenchError(
            f"{path}: ESRI ASCII header needs exactly one of {axis}llcorner and {axis}llcenter"
        )
    return corner + 0.5 * step if corner is not None else centre


def _read_npy(path: Path) -> _Raw:
    """A bare 2-D array: georeferencing comes from the arguments."""
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise TanbenchError(f"{path}: not a readable .npy file ({type(exc).__name__}: {exc})") from None
    return _Raw(_as_2d(z, path))


def _read_npz(path: Path) -> _Raw:
    """Key ``z`` (or the only array) and optional scalar keys e0, n0, res_e, res_n."""
    meta_keys = ("e0", "n0", "res_e", "res_n")
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in npz.files}
    except Exception as exc:
        raise TanbenchError(f"{path}: not a readable .npz file ({type(exc).__name__}: {exc})") from None
    if "z" in arrays:
        zkey = "z"
    else:
        others = [key for key in arrays if key not in meta_keys]
        if len(others) != 1:
            raise TanbenchError(
                f"{path}: .npz needs a key 'z' or exactly one array (keys: {', '.join(arrays) or 'none'})"
            )
        zkey = others[0]
    raw = _Raw(_as_2d(arrays[zkey], path))
    found = {}
    for key in meta_keys:
        if key in arrays:
            try:
                found[key] = float(np.asarray(arrays[key]).reshape(()))
            except (TypeError, ValueError):
                raise TanbenchError(f"{path}: .npz key {key} must be a single number") from None
    for key in ("res_e", "res_n"):
        if key in found and not found[key] > 0:
            raise TanbenchError(f"{path}: .npz key {key} must be positive, got {found[key]}")
    raw.x0, raw.y0 = found.get("e0"), found.get("n0")
    raw.dx, raw.dy = found.get("res_e"), found.get("res_n")
    if found:
        raw.georef = "keys"
    return raw


_READERS = {
    "geotiff": _read_geotiff,
    "netcdf": _read_netcdf,
    "esri-ascii": _read_esri_ascii,
    "npy": _read_npy,
    "npz": _read_npz,
}


# --------------------------------------------------------------------------------------
# Georeferencing: arguments and file together -> native Map, row 0 south
# --------------------------------------------------------------------------------------


def _georeference(raw: _Raw, path: Path, fmt: str, *, bounds, origin, resolution, rows, crs, nodata) -> Map:
    rows = _norm_rows(rows, path)
    crs_arg = _norm_crs(crs, path)
    z = raw.z
    if nodata is not None:
        try:
            z = _mask_value(z, float(nodata))
        except (TypeError, ValueError):
            raise TanbenchError(f"{path}: nodata must be a number, got {nodata!r}") from None
    ny, nx = z.shape
    if bounds is not None:
        if origin is not None or resolution is not None:
            raise TanbenchError(f"{path}: give either bounds= or origin= with resolution=, not both")
        if rows == "auto":
            raise TanbenchError(
                f"{path}: with bounds= the row order cannot be read from the file: pass "
                f"rows='south_to_north' or rows='north_to_south'"
            )
        out_crs = crs_arg or raw.crs or "metric"
        x_min, x_max, y_min, y_max = _check_bounds(bounds, path)
        if out_crs == "epsg3857":
            x_min, x_max = _mercator_x(x_min), _mercator_x(x_max)
            y_min, y_max = _mercator_y(y_min), _mercator_y(y_max)
        dx = (x_max - x_min) / (nx - 1)
        dy = (y_max - y_min) / (ny - 1)
        x0, y0 = x_min, (y_min if rows == "south_to_north" else y_max)
        dy = dy if rows == "south_to_north" else -dy
        georef = "bounds"
    else:
        x0, y0, dx, dy = raw.x0, raw.y0, raw.dx, raw.dy
        georef = raw.georef
        if dy is not None and rows != "auto" and (dy > 0) != (rows == "south_to_north"):
            raise TanbenchError(
                f"{path}: rows={rows!r} contradicts the file, whose "
                f"{_GEOREF_WORDS.get(raw.georef, raw.georef)} put row 0 at the "
                f"{'south' if dy > 0 else 'north'}; pass bounds= to override the file"
            )
        if raw.crs is not None and crs_arg is not None and raw.crs != crs_arg:
            raise TanbenchError(
                f"{path}: crs={crs!r} contradicts the file's {_GEOREF_WORDS.get(raw.georef, raw.georef)} "
                f"({raw.crs}); pass bounds= to override the file"
            )
        out_crs = crs_arg or raw.crs or "metric"
        if origin is not None:
            x0, y0 = _pair(origin, "origin", path)
            georef = "arguments"
        if resolution is not None:
            rx, ry = _resolution(resolution, path)
            sign_y = (1.0 if dy is None or dy > 0 else -1.0) if rows == "auto" else (
                1.0 if rows == "south_to_north" else -1.0)
            sign_x = 1.0 if dx is None or dx > 0 else -1.0
            dx, dy = sign_x * rx, sign_y * ry
            georef = "arguments"
        if None in (x0, y0, dx, dy):
            why = f" ({raw.problem})" if raw.problem else ""
            raise TanbenchError(
                f"{path}: the file has no usable georeferencing{why}: give bounds=(x_min, x_max, "
                f"y_min, y_max) with rows='south_to_north' or 'north_to_south', or origin=(e0, n0) "
                f"with resolution="
            )
    stored_rows = "north_to_south" if dy < 0 else "south_to_north"
    if dy < 0:
        z = z[::-1]
        y0, dy = y0 + (ny - 1) * dy, -dy
    if dx < 0:
        z = z[:, ::-1]
        x0, dx = x0 + (nx - 1) * dx, -dx
    if out_crs != "metric":
        _check_geographic_extent(out_crs, x0, dx, nx, y0, dy, ny, path)
    n_bad = int(np.isnan(z).sum())
    if n_bad == z.size:
        raise TanbenchError(f"{path}: the grid holds no valid elevation (all nodata)")
    meta = dict(crs=out_crs, source=str(path), format=fmt, georef=georef, rows=stored_rows,
                nodata_nodes=n_bad)
    try:
        return Map(z, float(x0), float(y0), float(dx), float(dy), name=path.stem, meta=meta)
    except ValueError as exc:
        raise TanbenchError(f"{path}: {exc}") from None


_GEOREF_WORDS = {"tags": "GeoTIFF tags", "coordinates": "coordinate vectors",
                 "header": "ESRI ASCII layout", "keys": ".npz keys"}


def _check_bounds(bounds, path: Path) -> tuple[float, float, float, float]:
    try:
        b = tuple(float(v) for v in bounds)
    except (TypeError, ValueError):
        b = ()
    if len(b) != 4 or not all(np.isfinite(b)):
        raise TanbenchError(
            f"{path}: bounds must be 4 finite numbers (x_min, x_max, y_min, y_max), got {bounds!r}"
        )
    if not (b[0] < b[1] and b[2] < b[3]):
        raise TanbenchError(f"{path}: bounds {b} must be (x_min, x_max, y_min, y_max) with min < max")
    return b


def _check_geographic_extent(crs, x0, dx, nx, y0, dy, ny, path) -> None:
    lon, lat = _native_to_lonlat(crs, np.array([x0, x0 + (nx - 1) * dx]), np.array([y0, y0 + (ny - 1) * dy]))
    limit = 85.06 if crs == "epsg3857" else 90.0
    if not (np.all(np.abs(lat) <= limit) and lon[1] - lon[0] <= 360.0):
        raise TanbenchError(
            f"{path}: {crs} grids must lie within latitudes +-{limit} and span at most 360 deg of "
            f"longitude; got lon {lon[0]:.6g}..{lon[1]:.6g}, lat {lat[0]:.6g}..{lat[1]:.6g}"
        )


# --------------------------------------------------------------------------------------
# Geodesy helpers
# --------------------------------------------------------------------------------------


def _radii(lat_deg: float) -> tuple[float, float]:
    """WGS84 meridian (R_N) and transverse (R_E) radii of curvature at ``lat_deg``, metres."""
    return radii_of_curvature(math.radians(lat_deg))


def _metres_per_degree(lat_c: float) -> tuple[float, float]:
    """(east metres per degree of longitude, north metres per degree of latitude) at lat_c."""
    r_n, r_e = _radii(lat_c)
    return r_e * math.cos(math.radians(lat_c)) * math.pi / 180.0, r_n * math.pi / 180.0


def _mercator_x(lon_deg):
    return WGS84_A * np.radians(lon_deg)


def _mercator_y(lat_deg):
    return WGS84_A * np.log(np.tan(np.pi / 4 + np.radians(lat_deg) / 2))


def _native_to_lonlat(crs: str, x, y) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if crs == "epsg3857":
        return np.degrees(x / WGS84_A), np.degrees(2 * np.arctan(np.exp(y / WGS84_A)) - np.pi / 2)
    return x, y


def _native_point_to_local(local: Map, crs: str, x: float, y: float) -> tuple[float, float]:
    lon, lat = _native_to_lonlat(crs, x, y)
    e, n = lonlat_to_local(local, lon, lat)
    return float(e), float(n)


def _frame(local: Map) -> tuple[float, float, float, float]:
    meta = local.meta
    if meta.get("crs") != "local" or "m_per_deg_lon" not in meta:
        raise TanbenchError(f"{_label(local, 0)}: this map was not projected from geographic coordinates")
    return meta["m_per_deg_lon"], meta["m_per_deg_lat"], meta["lon0"], meta["lat0"]


def _enu(lon, lat, lon_c: float, lat_c: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact east/north of points on the WGS84 ellipsoid in the tangent plane at (lon_c, lat_c)."""

    def ecef(lo, la):
        lo, la = np.radians(lo), np.radians(la)
        n = WGS84_A / np.sqrt(1 - WGS84_E2 * np.sin(la) ** 2)
        return (n * np.cos(la) * np.cos(lo), n * np.cos(la) * np.sin(lo),
                n * (1 - WGS84_E2) * np.sin(la))

    x, y, z = ecef(np.asarray(lon, float), np.asarray(lat, float))
    xc, yc, zc = ecef(lon_c, lat_c)
    dx, dy, dz = x - xc, y - yc, z - zc
    lo, la = math.radians(lon_c), math.radians(lat_c)
    e = -math.sin(lo) * dx + math.cos(lo) * dy
    n = -math.sin(la) * math.cos(lo) * dx - math.sin(la) * math.sin(lo) * dy + math.cos(la) * dz
    return e, n


def _projection_error(local: Map, lon: np.ndarray, lat: np.ndarray) -> float:
    """Largest horizontal distance, metres, between the frame and an exact tangent plane
    at the grid centre, over the corners and edge midpoints of the grid."""
    lon_c, lat_c = 0.5 * (lon[0] + lon[-1]), 0.5 * (lat[0] + lat[-1])
    los = np.array([lon[0], lon_c, lon[-1]])
    las = np.array([lat[0], lat_c, lat[-1]])
    glo, gla = np.meshgrid(los, las)
    e_ref, n_ref = _enu(glo, gla, lon_c, lat_c)
    e, n = lonlat_to_local(local, glo, gla)
    e_c, n_c = lonlat_to_local(local, lon_c, lat_c)
    return float(np.max(np.hypot(e - e_c - e_ref, n - n_c - n_ref)))


def _resample_rows(z: np.ndarray, n_src: np.ndarray, n_dst: np.ndarray) -> np.ndarray:
    """Linear interpolation of rows at north positions ``n_src`` onto rows at ``n_dst``.

    A target row falling on a source row copies it, so NaN does not leak from a
    neighbour whose weight is zero; otherwise a NaN neighbour gives NaN.
    """
    k = np.clip(np.searchsorted(n_src, n_dst, side="right") - 1, 0, len(n_src) - 2)
    t = ((n_dst - n_src[k]) / (n_src[k + 1] - n_src[k]))[:, None]
    lo, hi = z[k], z[k + 1]
    with np.errstate(invalid="ignore"):
        mixed = lo * (1.0 - t) + hi * t
    return np.where(t <= 0.0, lo, np.where(t >= 1.0, hi, mixed))


# --------------------------------------------------------------------------------------
# Mosaic helpers
# --------------------------------------------------------------------------------------


def _snap(start: float, res: float, count: int, anchor: float, grid_res: float) -> tuple[int, float]:
    """Grid index of a tile's first node and its nodes' worst distance from the grid, in cells."""
    index = int(round((start - anchor) / grid_res))
    first = start - (anchor + index * grid_res)
    last = first + (count - 1) * (res - grid_res)
    return index, max(abs(first), abs(last)) / grid_res


def _seams(maps, labels, rows_, cols, e0, n0, res_e, res_n) -> list[dict]:
    """One entry per pair of tiles that overlap or share an edge (see :func:`mosaic`)."""
    seams = []
    boxes = [(r, r + m.z.shape[0], c, c + m.z.shape[1]) for m, r, c in zip(maps, rows_, cols)]
    for a in range(len(maps)):
        for b in range(a + 1, len(maps)):
            ra0, ra1, ca0, ca1 = boxes[a]
            rb0, rb1, cb0, cb1 = boxes[b]
            r0, r1 = max(ra0, rb0), min(ra1, rb1)
            c0, c1 = max(ca0, cb0), min(ca1, cb1)
            jump = None
            if r1 > r0 and c1 > c0:
                kind = "overlap"
                va = maps[a].z[r0 - ra0:r1 - ra0, c0 - ca0:c1 - ca0]
                vb = maps[b].z[r0 - rb0:r1 - rb0, c0 - cb0:c1 - cb0]
                step = vb - va
                rr, cc = np.meshgrid(np.arange(r0, r1), np.arange(c0, c1), indexing="ij")
                where_e, where_n = e0 + cc * res_e, n0 + rr * res_n
            elif r1 > r0 and (ca1 == cb0 or cb1 == ca0):
                kind = "east-west"
                west, east = (a, b) if ca1 == cb0 else (b, a)
                jump, step = _edge_step(maps[west].z[r0 - boxes[west][0]:r1 - boxes[west][0]].T,
                                        maps[east].z[r0 - boxes[east][0]:r1 - boxes[east][0]].T)
                where_e = np.full(r1 - r0, e0 + (boxes[east][2] - 0.5) * res_e)
                where_n = n0 + np.arange(r0, r1) * res_n
            elif c1 > c0 and (ra1 == rb0 or rb1 == ra0):
                kind = "north-south"
                south, north = (a, b) if ra1 == rb0 else (b, a)
                jump, step = _edge_step(maps[south].z[:, c0 - boxes[south][2]:c1 - boxes[south][2]],
                                        maps[north].z[:, c0 - boxes[north][2]:c1 - boxes[north][2]])
                where_e = e0 + np.arange(c0, c1) * res_e
                where_n = np.full(c1 - c0, n0 + (boxes[north][0] - 0.5) * res_n)
            else:
                continue
            step = np.abs(step).ravel()
            ok = np.isfinite(step)
            entry = {"tiles": (labels[a], labels[b]), "kind": kind, "pairs": int(ok.sum()),
                     "mean_abs_step": float("nan"), "max_abs_step": float("nan"),
                     "worst_at": (float("nan"), float("nan"))}
            if ok.any():
                worst = int(np.flatnonzero(ok)[np.argmax(step[ok])])
                entry.update(mean_abs_step=float(step[ok].mean()), max_abs_step=float(step[worst]),
                             worst_at=(float(np.ravel(where_e)[worst]), float(np.ravel(where_n)[worst])))
            if jump is not None:
                finite = np.abs(jump[np.isfinite(jump)])
                entry["mean_abs_jump"] = float(finite.mean()) if finite.size else float("nan")
            seams.append(entry)
    return seams


def _edge_step(low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jump across a join between grids stacked along axis 0 (``low`` first), and that
    jump minus the mean of the last slope inside each grid (0 for a smooth surface)."""
    jump = high[0] - low[-1]
    return jump, jump - 0.5 * ((low[-1] - low[-2]) + (high[1] - high[0]))


def _label(m: Map, k: int) -> str:
    return str(m.meta.get("source") or m.name or f"tile {k}")


# --------------------------------------------------------------------------------------
# Small helpers
# --------------------------------------------------------------------------------------


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


def _known_formats() -> str:
    return "; ".join(f"{name} ({', '.join(exts)})" for name, exts in FORMATS.items())


def _resolve_format(path: Path, fmt: str | None) -> str:
    if fmt is not None:
        key = str(fmt).strip().lower().replace("_", "-")
        key = _FORMAT_ALIASES.get(key, key)
        if key not in FORMATS:
            raise TanbenchError(f"{path}: unknown grid format {fmt!r}; known formats: {_known_formats()}")
        return key
    suffix = path.suffix.lower()
    for name, exts in FORMATS.items():
        if suffix in exts:
            return name
    raise TanbenchError(
        f"{path}: cannot tell the grid format from the extension {suffix or '(none)'!r}; "
        f"known formats: {_known_formats()}; or pass format="
    )


def _norm_rows(rows, path: Path) -> str:
    key = str(rows).strip().lower().replace("-", "_")
    if key not in _ROWS:
        raise TanbenchError(f"{path}: rows must be one of {', '.join(_ROWS)}, got {rows!r}")
    return key


def _norm_crs(crs, path: Path) -> str | None:
    if crs is None:
        return None
    key = re.sub(r"[\s:_\-]", "", str(crs).lower())
    if key not in _CRS_ALIASES:
        raise TanbenchError(f"{path}: unknown crs {crs!r}; use {_CRS_NAMES}")
    return _CRS_ALIASES[key]


def _pair(value, what: str, path: Path) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise TanbenchError(f"{path}: {what} must be two numbers, got {value!r}") from None
    if not (np.isfinite(a) and np.isfinite(b)):
        raise TanbenchError(f"{path}: {what} must be finite, got {value!r}")
    return a, b


def _resolution(value, path: Path) -> tuple[float, float]:
    if np.ndim(value) == 0:
        try:
            rx = ry = float(value)
        except (TypeError, ValueError):
            raise TanbenchError(
                f"{path}: resolution must be a number or (res_e, res_n), got {value!r}"
            ) from None
    else:
        rx, ry = _pair(value, "resolution", path)
    if not (rx > 0 and ry > 0 and np.isfinite(rx) and np.isfinite(ry)):
        raise TanbenchError(f"{path}: resolution must be positive, got {value!r}")
    return rx, ry


def _as_float(z: np.ndarray, path: Path) -> np.ndarray:
    if z.dtype.kind not in "iuf":
        raise TanbenchError(f"{path}: grid values have type {z.dtype}; expected numbers")
    out = z.astype(np.float64)
    out[~np.isfinite(out)] = np.nan
    return out


def _as_2d(z, path: Path) -> np.ndarray:
    z = np.asarray(z)
    if z.ndim != 2:
        raise TanbenchError(f"{path}: array has shape {z.shape}; expected a 2-D grid")
    return _as_float(z, path)


def _mask_value(z: np.ndarray, value: float) -> np.ndarray:
    """NaN where z equals a nodata value (compared in float32 too, as grids often store it)."""
    if np.isnan(value):
        return z
    hit = (z == value) | (z == float(np.float32(value)))
    if hit.any():
        z = z.copy()
        z[hit] = np.nan
    return z


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


_NAME_BOUNDS = re.compile(
    r"(?:^|[._])R_(-?\d+(?:\.\d*)?)_(-?\d+(?:\.\d*)?)_(-?\d+(?:\.\d*)?)_(-?\d+(?:\.\d*)?)(?=\.|$)"
)
_NAME_CRS = re.compile(r"(?:^|\.)(epsg\d+)(?=\.|$)", re.IGNORECASE)


def _try_bounds_from_name(path) -> tuple[float, float, float, float] | None:
    match = _NAME_BOUNDS.search(Path(path).name)
    if match is None:
        return None
    lon_min, lon_max, lat_min, lat_max = (float(v) for v in match.groups())
    if not (lon_min < lon_max and lat_min < lat_max and -90 <= lat_min and lat_max <= 90):
        raise TanbenchError(
            f"{path}: bounds in the file name ({lon_min}, {lon_max}, {lat_min}, {lat_max}) are not "
            f"lon_min < lon_max, lat_min < lat_max within +-90 deg"
        )
    return lon_min, lon_max, lat_min, lat_max


def _crs_from_name(path) -> str | None:
    match = _NAME_CRS.search(Path(path).name)
    if match is None:
        return None
    return _CRS_ALIASES.get(match.group(1).lower())


def _check_name_against_grid(native: Map, path: Path, name_bounds) -> None:
    """The bounds in a file name must fall on nodes of the grid the file's tags describe."""
    crs = native.meta["crs"]
    if crs == "metric":
        raise TanbenchError(
            f"{path}: the file name gives lon/lat bounds but the file's georeferencing is metric; "
            f"pass bounds= to choose"
        )
    lon_min, lon_max, lat_min, lat_max = name_bounds
    if crs == "epsg3857":
        xs, ys = _mercator_x(np.array([lon_min, lon_max])), _mercator_y(np.array([lat_min, lat_max]))
    else:
        xs, ys = np.array([lon_min, lon_max]), np.array([lat_min, lat_max])
    fj = (xs - native.e0) / native.res_e
    fi = (ys - native.n0) / native.res_n
    ny, nx = native.z.shape
    off = max(np.max(np.abs(fj - np.round(fj))), np.max(np.abs(fi - np.round(fi))))
    inside = np.all((fj > -0.5) & (fj < nx - 0.5)) and np.all((fi > -0.5) & (fi < ny - 0.5))
    if off > MOSAIC_TOLERANCE or not inside:
        raise TanbenchError(
            f"{path}: the bounds in the file name do not match the file's "
            f"{_GEOREF_WORDS.get(native.meta['georef'], 'georeferencing')} (name bounds at node "
            f"columns {fj[0]:.2f}..{fj[1]:.2f}, rows {fi[0]:.2f}..{fi[1]:.2f} of a {ny} x {nx} grid); "
            f"pass bounds= per tile to choose"
        )
    native.meta["name_bounds_nodes"] = (int(round(fj[0])), int(round(fj[1])),
                                        int(round(fi[0])), int(round(fi[1])))
