"""Georeferencing: where a grid's nodes are, and the local metric frame they end up in.

A format's reader gives the array as stored plus the file's own georeferencing
(:class:`~tanbench.terrain.formats.RawGrid`). :func:`georeference` completes or
replaces it with explicit ``bounds`` / ``origin`` / ``resolution`` / ``rows`` / ``crs``
arguments and flips the grid so that row 0 is south and column 0 is west. The result
is a "native" Map whose units are metres for a metric grid, degrees for a geographic
(EPSG:4326) grid and Web-Mercator metres for an EPSG:3857 grid (``meta["crs"]`` says
which). :func:`to_local` then projects geographic and Web-Mercator grids onto a local
tangent plane (equirectangular about the centre latitude, WGS84 radii of curvature)
whose origin is the south-west node; :func:`lonlat_to_local` and
:func:`local_to_lonlat` convert positions. Tiled DEMs that carry their bounds in their
file names (``...R_<lon_min>_<lon_max>_<lat_min>_<lat_max>.epsg3857.tif``) are read
with :func:`parse_bounds_from_name`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from tanbench.earth import WGS84_A, WGS84_E2, radii_of_curvature
from tanbench.errors import TanbenchError
from tanbench.terrain.formats import RawGrid, mask_value
from tanbench.terrain.grid import Map
from tanbench.terrain.mosaic import MOSAIC_TOLERANCE, tile_label

_CRS_ALIASES = {
    "metric": "metric", "local": "metric", "projected": "metric", "metres": "metric",
    "meters": "metric", "m": "metric",
    "epsg4326": "epsg4326", "wgs84": "epsg4326", "geographic": "epsg4326",
    "lonlat": "epsg4326", "crs84": "epsg4326",
    "epsg3857": "epsg3857", "webmercator": "epsg3857", "pseudomercator": "epsg3857",
    "epsg3785": "epsg3857", "epsg900913": "epsg3857",
}
CRS_NAMES = "'metric', 'epsg4326' (lon/lat degrees) or 'epsg3857' (Web Mercator)"
_ROWS = ("auto", "south_to_north", "north_to_south")


# --------------------------------------------------------------------------------------
# Arguments and file together -> native Map, row 0 south
# --------------------------------------------------------------------------------------


def georeference(raw: RawGrid, path: Path, fmt: str, *, bounds, origin, resolution, rows, crs, nodata) -> Map:
    """The native Map (row 0 south, column 0 west) of a raw grid and the georeferencing
    arguments (see :func:`tanbench.terrain.files.read_grid` for their meaning)."""
    rows = _norm_rows(rows, path)
    crs_arg = _norm_crs(crs, path)
    z = raw.z
    if nodata is not None:
        try:
            z = mask_value(z, float(nodata))
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
    with np.errstate(over="ignore", invalid="ignore"):
        corner = (x0 + (nx - 1) * dx, y0 + (ny - 1) * dy)
    if not all(np.isfinite(v) for v in (x0, y0, dx, dy, *corner)):
        # the readers refuse non-finite values of their own; this catches any other reader's
        # and a grid whose far edge overflows
        source = _GEOREF_WORDS.get(georef, georef)
        raise TanbenchError(
            f"{path}: the georeferencing ({source}) is not finite: origin ({x0:g}, {y0:g}), spacing "
            f"{dx:g} x {dy:g}, far corner ({corner[0]:g}, {corner[1]:g})"
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
    finite = np.isfinite(z)
    n_bad = int(z.size - np.count_nonzero(finite))
    if n_bad == z.size:
        raise TanbenchError(f"{path}: the grid holds no valid elevation (all nodata)")
    if n_bad and np.isinf(z).any():  # the built-in readers give NaN already; another reader's inf is a hole too
        z = np.where(finite, z, np.nan)
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
        raise TanbenchError(f"{path}: unknown crs {crs!r}; use {CRS_NAMES}")
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


# --------------------------------------------------------------------------------------
# Projection to a local metric frame
# --------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------
# Bounds in file names
# --------------------------------------------------------------------------------------


def parse_bounds_from_name(path) -> tuple[float, float, float, float]:
    """Bounds ``(lon_min, lon_max, lat_min, lat_max)`` from a ``...R_<b>_<b>_<b>_<b>.`` name.

    The naming scheme of tiled DEMs such as
    ``MontereyBay.R_-121.825_-121.815_36.790_36.800.epsg3857.tif``.
    """
    bounds = bounds_from_name(path)
    if bounds is None:
        raise TanbenchError(
            f"{path}: the file name carries no bounds; expected a name like "
            f"'<name>.R_<lon_min>_<lon_max>_<lat_min>_<lat_max>.<crs>.tif'"
        )
    return bounds


_NAME_BOUNDS = re.compile(
    r"(?:^|[._])R_(-?\d+(?:\.\d*)?)_(-?\d+(?:\.\d*)?)_(-?\d+(?:\.\d*)?)_(-?\d+(?:\.\d*)?)(?=\.|$)"
)
_NAME_CRS = re.compile(r"(?:^|\.)(epsg\d+)(?=\.|$)", re.IGNORECASE)


def bounds_from_name(path) -> tuple[float, float, float, float] | None:
    """Like :func:`parse_bounds_from_name`, but None for a name without bounds."""
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


def crs_from_name(path) -> str | None:
    """The crs of an ``.epsg<code>.`` token in a file name, else None."""
    match = _NAME_CRS.search(Path(path).name)
    if match is None:
        return None
    return _CRS_ALIASES.get(match.group(1).lower())


def check_name_against_grid(native: Map, path: Path, name_bounds) -> None:
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


def native_point_to_local(local: Map, crs: str, x: float, y: float) -> tuple[float, float]:
    """Local (e, n) of a point given in the native coordinates of the grid ``local`` was projected from."""
    lon, lat = _native_to_lonlat(crs, x, y)
    e, n = lonlat_to_local(local, lon, lat)
    return float(e), float(n)


def _frame(local: Map) -> tuple[float, float, float, float]:
    meta = local.meta
    if meta.get("crs") != "local" or "m_per_deg_lon" not in meta:
        raise TanbenchError(f"{tile_label(local, 0)}: this map was not projected from geographic coordinates")
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
