"""GeoTIFF grids (via tifffile): the first image and its GeoTIFF georeferencing tags."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.terrain.formats.registry import RawGrid, as_float, mask_value, register_format

_WEB_MERCATOR_CODES = {3857, 3785, 900913, 102100, 102113}


def read_geotiff(path: Path) -> RawGrid:
    """GeoTIFF via tifffile: first image, ModelPixelScale/Tiepoint or ModelTransformation,
    GeoKeyDirectory (geographic / Web Mercator / other projected = metres), GDAL nodata."""
    try:
        import tifffile
    except ImportError:
        raise TanbenchError(
            f"{path}: reading GeoTIFF needs the tifffile package: pip install tifffile "
            f"(or pip install tanbench[maps])"
        ) from None
    log = logging.getLogger("tifffile")
    level = log.level
    log.setLevel(logging.CRITICAL + 1)  # tifffile logs what it finds wrong; the one line below says it
    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages[0]
            tags = {tag.code: tag.value for tag in page.tags.values()}
            z = page.asarray()
    except Exception as exc:
        raise TanbenchError(f"{path}: not a readable TIFF file ({type(exc).__name__}: {exc})") from None
    finally:
        log.setLevel(level)
    z = np.asarray(z)
    if z.ndim == 3 and 1 in (z.shape[0], z.shape[-1]):
        z = z.reshape(z.shape[1:] if z.shape[0] == 1 else z.shape[:2])
    if z.ndim != 2:
        raise TanbenchError(f"{path}: image has shape {z.shape}; expected one band of elevations")
    z = as_float(z, path)
    if 42113 in tags:
        text = str(tags[42113]).strip().strip("\x00").strip()
        try:
            fill = float(text)
        except ValueError:
            raise TanbenchError(f"{path}: GDAL_NODATA tag {text!r} is not a number") from None
        z = mask_value(z, fill)
    raw = RawGrid(z)
    try:
        _geotiff_georef(raw, tags)
    except _GeoTagProblem as exc:
        raw.problem = str(exc)
    return raw


class _GeoTagProblem(Exception):
    """Unusable GeoTIFF georeferencing: fatal only when nothing replaces it."""


def _geotiff_georef(raw: RawGrid, tags: dict) -> None:
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


register_format("geotiff", (".tif", ".tiff"), read_geotiff, aliases=("tif", "tiff", "gtiff"))
