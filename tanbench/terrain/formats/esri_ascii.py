"""ESRI ASCII grids (``.asc``): a header, then the rows from north to south."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.terrain.formats.registry import RawGrid, as_float, mask_value, register_format

_ASC_KEYS = ("ncols", "nrows", "xllcorner", "xllcenter", "xllcentre", "yllcorner", "yllcenter",
             "yllcentre", "cellsize", "dx", "dy", "nodata_value")


def read_esri_ascii(path: Path) -> RawGrid:
    """ESRI ASCII grid: header, then rows from north to south."""
    try:
        text = path.read_text(encoding="ascii")
    except (UnicodeDecodeError, OSError) as exc:
        raise TanbenchError(f"{path}: not a readable ESRI ASCII grid ({type(exc).__name__})") from None
    lines = text.splitlines()
    header: dict[str, float] = {}
    given: dict[str, str] = {}  # each header value as the file writes it, for messages
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
            given[key] = parts[1]
            k += 1
        else:
            break
    for need in ("ncols", "nrows"):
        if need not in header:
            raise TanbenchError(f"{path}: ESRI ASCII header lacks {need}")
    for key in ("ncols", "nrows"):
        value = header[key]
        if not (np.isfinite(value) and value >= 1 and value == int(value)):
            raise TanbenchError(f"{path}: {key} must be a positive whole number (got {given[key]})")
    nx, ny = int(header["ncols"]), int(header["nrows"])
    for key in ("xllcorner", "xllcenter", "xllcentre", "yllcorner", "yllcenter", "yllcentre"):
        if key in header and not np.isfinite(header[key]):
            raise TanbenchError(f"{path}: {key} must be finite (got {given[key]})")
    if "cellsize" in header:
        steps = ("cellsize",)
    elif "dx" in header and "dy" in header:
        steps = ("dx", "dy")
    else:
        raise TanbenchError(f"{path}: ESRI ASCII header lacks cellsize (or dx and dy)")
    for key in steps:
        if not (header[key] > 0 and np.isfinite(header[key])):
            raise TanbenchError(f"{path}: {key} must be a positive finite number (got {given[key]})")
    dx, dy = header[steps[0]], header[steps[-1]]
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
    z = as_float(values.reshape(ny, nx), path)  # nan / inf in the data: holes, as in every format
    if "nodata_value" in header:
        z = mask_value(z, header["nodata_value"])
    return RawGrid(z, georef="header", x0=x_ll, y0=y_ll + (ny - 1) * dy, dx=dx, dy=-dy)


def _asc_origin(header: dict, axis: str, step: float, path: Path) -> float:
    """Centre of the lower-left cell from xll/yll corner or centre registration."""
    corner = header.get(f"{axis}llcorner")
    centre = header.get(f"{axis}llcenter", header.get(f"{axis}llcentre"))
    if (corner is None) == (centre is None):
        raise TanbenchError(
            f"{path}: ESRI ASCII header needs exactly one of {axis}llcorner and {axis}llcenter"
        )
    return corner + 0.5 * step if corner is not None else centre


register_format("esri-ascii", (".asc",), read_esri_ascii, aliases=("asc", "ascii", "esri", "aaigrid"))
