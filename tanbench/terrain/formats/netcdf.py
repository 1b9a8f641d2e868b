"""GMT/COARDS NetCDF grids: classic NetCDF via SciPy, NetCDF-4 (HDF5) via h5py."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.terrain.formats.registry import RawGrid, as_float, register_format

_NC_X = ("x", "lon", "longitude")
_NC_Y = ("y", "lat", "latitude")
_NC_Z = ("z", "elevation", "elev", "band1")


def read_netcdf(path: Path) -> RawGrid:
    """GMT/COARDS NetCDF: classic via scipy, NetCDF-4/HDF5 via h5py when installed."""
    with open(path, "rb") as fh:
        magic = fh.read(8)
    if magic.startswith(b"\x89HDF"):
        variables = _netcdf4_variables(path)
    elif magic.startswith(b"CDF"):
        from scipy.io import netcdf_file

        try:  # (a _FillValue the variable's type cannot hold is cast with a numpy warning: quiet, it matches nothing)
            with np.errstate(invalid="ignore", over="ignore"), netcdf_file(path, "r", mmap=False) as nc:
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


def _netcdf_raw(path: Path, variables: dict) -> RawGrid:
    lower = {name.lower(): name for name in variables}

    def pick(candidates):
        for cand in candidates:
            if cand in lower:
                return lower[cand]
        return None

    xname, yname = pick(_NC_X), pick(_NC_Y)
    zname = pick(_NC_Z)
    if zname is None:
        two_d = [name for name, (data, _, _) in variables.items() if data.ndim == 2]
        if len(two_d) != 1:
            raise TanbenchError(
                f"{path}: no elevation variable z or elevation (variables: {', '.join(variables) or 'none'})"
            )
        zname = two_d[0]
    zdata, z_attrs, z_dims = variables[zname]
    if xname is None or yname is None:
        # no coordinate vectors: the grid as stored (row 0 first), placed by the georeferencing
        # arguments (origin and resolution, or bounds and rows) as a bare array is
        if zdata.ndim != 2:
            raise TanbenchError(f"{path}: {zname} has shape {zdata.shape}; expected a 2-D grid")
        return RawGrid(_unpack(zdata, z_attrs, path, zname), problem=(
            f"no coordinate variables x/y, lon/lat or longitude/latitude; variables: {', '.join(variables)}"))
    x, x_attrs, _ = variables[xname]
    y, y_attrs, _ = variables[yname]
    x = _numeric_coordinate(x, xname, path)
    y = _numeric_coordinate(y, yname, path)
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
    raw = RawGrid(z, georef="coordinates", crs=crs_x)
    raw.x0, raw.dx = _even_spacing(x, xname, path)
    raw.y0, raw.dy = _even_spacing(y, yname, path)
    return raw


def _numeric_coordinate(v: np.ndarray, name: str, path: Path) -> np.ndarray:
    """A coordinate variable's values as float64; a character (or other non-numeric) variable is an error."""
    v = np.asarray(v)
    if v.dtype.kind not in "iuf":
        raise TanbenchError(f"{path}: coordinate {name} is not numeric (it holds {v.dtype.str.lstrip('<>|=')} values)")
    return v.astype(np.float64)


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
    """CF unpacking: _FillValue / missing_value (packed units) -> NaN, then scale and offset;
    a value that is not finite once unpacked (an overflow, a non-finite scale_factor) is a hole too."""
    z = as_float(data, path)
    mask = np.zeros(data.shape, dtype=bool)
    for key in ("_FillValue", "missing_value"):
        if key in attrs:
            for value in np.atleast_1d(np.asarray(attrs[key])).ravel():
                try:
                    float(value)
                except (TypeError, ValueError):
                    raise TanbenchError(f"{path}: {name}:{key} is not a number") from None
                mask |= _packed_equal(data, value)
    valid = np.isfinite(z) & ~mask
    scale = _scalar_attr(attrs, "scale_factor", 1.0, path, name)
    offset = _scalar_attr(attrs, "add_offset", 0.0, path, name)
    with np.errstate(over="ignore", invalid="ignore"):
        z = z * scale + offset
    z[mask | ~np.isfinite(z)] = np.nan
    if valid.any() and np.isnan(z).all():
        raise TanbenchError(
            f"{path}: the grid holds no valid elevation once unpacked: {name}:scale_factor {scale:g} and "
            f"add_offset {offset:g} make every value non-finite"
        )
    return z


def _packed_equal(data: np.ndarray, value) -> np.ndarray:
    """Where the packed ``data`` equal a fill value; a value the data's type cannot hold (e.g.
    1e10 for 16-bit integers, NaN) matches nothing."""
    nothing = np.zeros(data.shape, dtype=bool)
    if data.dtype.kind == "f":
        if np.isnan(float(value)):
            return nothing
        with np.errstate(over="ignore"):
            return data == np.asarray(value).astype(data.dtype)
    if np.asarray(value).dtype.kind in "iu":  # integers compare exactly (a 64-bit fill is not a float)
        value = int(value)
    else:
        value = float(value)
        if not (np.isfinite(value) and value == int(value)):
            return nothing
        value = int(value)
    info = np.iinfo(data.dtype)
    return data == value if info.min <= value <= info.max else nothing


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


register_format("netcdf", (".nc", ".grd", ".nc4", ".cdf"), read_netcdf, aliases=("nc", "gmt", "grd", "netcdf4"))
