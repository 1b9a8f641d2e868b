"""Readers for real bathymetry grids: round trips, orientation, projection, mosaics, holes.

Every round trip writes an analytic plane z = A + B e + C n into a file in tmp_path and
reads it back: values at random points must match to 1e-6 and north must be north
(B and C differ in size and sign, so a flipped or transposed grid fails loudly).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.io import netcdf_file

from tanbench.errors import TanbenchError
from tanbench.terrain.grid import Map
from tanbench.terrain.files import read_grid, read_tiles
from tanbench.terrain.georef import local_to_lonlat, lonlat_to_local, parse_bounds_from_name, to_local
from tanbench.terrain.mosaic import fill_holes, find_holes, mosaic

A, B, C = -50.0, 0.02, -0.035
NX, NY = 23, 17
E0, N0, RE, RN = 1000.0, 2000.0, 5.0, 4.0
E = E0 + RE * np.arange(NX)
N = N0 + RN * np.arange(NY)
BOUNDS = (E[0], E[-1], N[0], N[-1])


def plane(e, n):
    return A + B * np.asarray(e) + C * np.asarray(n)


Z = plane(E[None, :], N[:, None])  # row 0 = south

WGS84_A, WGS84_E2 = 6378137.0, 6.69437999014e-3

MONTEREY = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "monterey"


def assert_plane(m: Map, e0=E0, n0=N0, atol=1e-6):
    """The map reproduces the plane, with its nodes where they were written."""
    assert m.shape == (NY, NX)
    assert m.e0 == pytest.approx(e0) and m.n0 == pytest.approx(n0)
    assert m.res_e == pytest.approx(RE) and m.res_n == pytest.approx(RN)
    rng = np.random.default_rng(1)
    e = rng.uniform(m.e0, m.e_max, 300)
    n = rng.uniform(m.n0, m.n_max, 300)
    np.testing.assert_allclose(m.elevation(e, n), plane(e - e0 + E0, n - n0 + N0), atol=atol)
    # North is north: the northern edge is where the plane says it is.
    assert m.z[-1, 0] == pytest.approx(plane(E0, N[-1] - N0 + N0), abs=atol)


def raises_naming(path, fn, *args, match=None, **kw):
    """Call must raise a one-line TanbenchError naming the file."""
    with pytest.raises(TanbenchError) as info:
        fn(*args, **kw)
    msg = str(info.value)
    assert Path(path).name in msg, msg
    assert "\n" not in msg
    if match is not None:
        assert match in msg, msg
    return msg


# --------------------------------------------------------------------------- writers


def geokeys(model, extra=()):
    keys = [(1024, 0, 1, model), (1025, 0, 1, 1)] + list(extra)
    out = [1, 1, 0, len(keys)]
    for k in keys:
        out.extend(k)
    return out


def write_tiff(path, z, extratags=()):
    tifffile = pytest.importorskip("tifffile")
    tifffile.imwrite(path, np.asarray(z, dtype=np.float64), extratags=list(extratags))


def write_nc(path, x, y, z, names=("x", "y", "z"), z_attrs=None, dtype="f8", xy_units=None):
    xn, yn, zn = names
    with netcdf_file(path, "w") as nc:
        nc.createDimension(xn, len(x))
        nc.createDimension(yn, len(y))
        vx = nc.createVariable(xn, "f8", (xn,))
        vx[:] = x
        vy = nc.createVariable(yn, "f8", (yn,))
        vy[:] = y
        if xy_units:
            vx.units, vy.units = xy_units
        vz = nc.createVariable(zn, dtype, (yn, xn))
        vz[:] = z
        for key, value in (z_attrs or {}).items():
            setattr(vz, key, value)


def write_asc(path, z_north_first, header):
    lines = [f"{k} {v}" for k, v in header.items()]
    lines += [" ".join(f"{v:.10f}" for v in row) for row in z_north_first]
    Path(path).write_text("\n".join(lines) + "\n")


# --------------------------------------------------------------------------- GeoTIFF


def test_geotiff_projected_tags_north_up(tmp_path):
    # Standard north-up GeoTIFF: row 0 north, PixelIsArea tie point at the NW pixel corner.
    path = tmp_path / "plane_utm.tif"
    tags = [
        (33550, "d", 3, (RE, RN, 0.0), True),
        (33922, "d", 6, (0.0, 0.0, 0.0, E0 - RE / 2, N[-1] + RN / 2, 0.0), True),
        (34735, "H", 20, geokeys(1, [(3072, 0, 1, 32610), (3076, 0, 1, 9001)]), True),
    ]
    write_tiff(path, Z[::-1], tags)
    m = read_grid(path)
    assert_plane(m)
    assert m.meta["georef"] == "tags" and m.meta["rows"] == "north_to_south"
    assert m.meta["crs"] == "metric"


def test_geotiff_transformation_tag_south_up_pixel_is_point(tmp_path):
    # ModelTransformationTag with a positive y step: row 0 south (as in the Monterey tiles).
    path = tmp_path / "plane_su.tif"
    matrix = (RE, 0, 0, E0, 0, RN, 0, N0, 0, 0, 0, 0, 0, 0, 0, 1)
    keys = [1, 1, 0, 2, 1024, 0, 1, 1, 1025, 0, 1, 2]
    write_tiff(path, Z, [(34264, "d", 16, matrix, True), (34735, "H", len(keys), keys, True)])
    m = read_grid(path, rows="south_to_north")
    assert_plane(m)
    raises_naming(path, read_grid, path, rows="north_to_south", match="contradicts")


def test_geotiff_without_tags_needs_bounds_and_rows(tmp_path):
    path = tmp_path / "bare.tif"
    write_tiff(path, Z[::-1])
    raises_naming(path, read_grid, path, match="no usable georeferencing")
    raises_naming(path, read_grid, path, bounds=BOUNDS, match="rows")
    assert_plane(read_grid(path, bounds=BOUNDS, rows="north_to_south"))
    write_tiff(path, Z)
    assert_plane(read_grid(path, bounds=BOUNDS, rows="south_to_north"))


def test_geotiff_gdal_nodata_becomes_nan(tmp_path):
    path = tmp_path / "holes.tif"
    z = Z.copy()
    z[3, 4] = -9999.0
    write_tiff(path, z, [(42113, "s", 0, "-9999", True)])
    m = read_grid(path, bounds=BOUNDS, rows="south_to_north")
    assert np.isnan(m.z[3, 4]) and np.isfinite(np.delete(m.z.ravel(), 3 * NX + 4)).all()
    assert m.meta["nodata_nodes"] == 1


def test_geotiff_geographic_tags_are_projected(tmp_path):
    path = tmp_path / "geo.tif"
    lon0, lat0, dlon, dlat = -121.8, 36.8, 1e-4, 1e-4
    lon = lon0 + dlon * np.arange(NX)
    lat = lat0 + dlat * np.arange(NY)
    z = -100 + 1000 * (lon[None, :] - lon0) - 500 * (lat[:, None] - lat0)
    tags = [
        (33550, "d", 3, (dlon, dlat, 0.0), True),
        # PixelIsArea (the default): the tie point is the NW corner of the NW pixel.
        (33922, "d", 6, (0.0, 0.0, 0.0, lon0 - dlon / 2, lat[-1] + dlat / 2, 0.0), True),
        (34735, "H", 8, [1, 1, 0, 1, 1024, 0, 1, 2], True),  # geographic
    ]
    write_tiff(path, z[::-1], tags)
    m = read_grid(path)
    assert m.meta["crs"] == "local" and m.meta["source_crs"] == "epsg4326"
    assert (m.meta["lon0"], m.meta["lat0"]) == pytest.approx((lon0, lat0))
    rng = np.random.default_rng(6)
    lo = rng.uniform(lon[0], lon[-1], 100)
    la = rng.uniform(lat[0], lat[-1], 100)
    e, n = lonlat_to_local(m, lo, la)
    np.testing.assert_allclose(m.elevation(e, n), -100 + 1000 * (lo - lon0) - 500 * (la - lat0), atol=1e-9)
    raises_naming(path, read_grid, path, crs="metric", match="contradicts")


def test_garbage_tif_is_a_clear_error(tmp_path):
    path = tmp_path / "garbage.tif"
    path.write_bytes(b"this is not a tiff file at all")
    raises_naming(path, read_grid, path, match="TIFF")


# --------------------------------------------------------------------------- NetCDF


@pytest.mark.parametrize("y_decreasing", [False, True])
def test_netcdf_xyz_both_orientations(tmp_path, y_decreasing):
    path = tmp_path / f"plane_{int(y_decreasing)}.nc"
    if y_decreasing:
        write_nc(path, E, N[::-1], Z[::-1])
    else:
        write_nc(path, E, N, Z)
    m = read_grid(path)
    assert_plane(m)
    assert m.meta["rows"] == ("north_to_south" if y_decreasing else "south_to_north")
    wrong = "south_to_north" if y_decreasing else "north_to_south"
    raises_naming(path, read_grid, path, rows=wrong, match="contradicts")


def test_netcdf_packed_values_and_fill(tmp_path):
    path = tmp_path / "packed.grd"
    scale, offset = 0.001, -100.0
    packed = np.round((Z - offset) / scale).astype(np.int16)
    packed[5, 6] = -32768
    write_nc(path, E, N, packed, dtype="i2",
             z_attrs={"scale_factor": scale, "add_offset": offset, "_FillValue": np.int16(-32768)})
    m = read_grid(path)
    assert np.isnan(m.z[5, 6])
    ok = np.isfinite(m.z)
    np.testing.assert_allclose(m.z[ok], Z[ok], atol=scale / 2 + 1e-9)


def test_netcdf_values_not_finite_once_unpacked_are_holes(tmp_path):
    """scale_factor / add_offset are applied to finite packed values only; what overflows is a hole,
    and a grid that unpacks to no finite value at all is refused in one line (no numpy warning)."""
    path = tmp_path / "overflow.nc"
    packed = np.where(np.arange(NX)[None, :] < 5, 100.0, 1.0) * np.ones((NY, 1))  # 100 * 1e307 overflows
    with np.errstate(all="raise"):
        write_nc(path, E, N, packed, z_attrs={"scale_factor": np.float64(1e307)})
        m = read_grid(path)
    assert np.isnan(m.z[:, :5]).all() and (m.z[:, 5:] == 1e307).all()
    assert m.meta["nodata_nodes"] == 5 * NY
    for attrs in ({"scale_factor": np.float64(np.inf)}, {"add_offset": np.float64(np.nan)},
                  {"scale_factor": np.float64(1e307), "add_offset": np.float64(1.75e308)}):
        write_nc(path, E, N, packed, z_attrs=attrs)
        with np.errstate(all="raise"):
            msg = raises_naming(path, read_grid, path, match="the grid holds no valid elevation once unpacked")
        assert "make every value non-finite" in msg, msg


def test_netcdf_fill_value_the_type_cannot_hold_matches_nothing(tmp_path):
    """A _FillValue outside the packed integers' range (1e10 for int16) masks nothing, without a numpy
    cast warning; a 64-bit integer fill compares exactly."""
    path = tmp_path / "fill.nc"
    packed = np.round((Z - Z.min()) * 100).astype(np.int16)
    with np.errstate(invalid="ignore"):  # scipy's writer casts the fill itself
        write_nc(path, E, N, packed, dtype="i2", z_attrs={"_FillValue": np.float64(1e10)})
    with np.errstate(all="raise"):
        m = read_grid(path)
    assert not np.isnan(m.z).any()
    from tanbench.terrain.formats.netcdf import _packed_equal

    big = np.array([2**62 + 1, 2**62], dtype=np.int64)
    assert _packed_equal(big, np.int64(2**62)).tolist() == [False, True]  # as floats, both would match
    assert not _packed_equal(packed, np.float64(0.5)).any() and not _packed_equal(packed, np.nan).any()


@pytest.mark.parametrize("which", ["x", "y"])
def test_netcdf_character_coordinate_is_refused(tmp_path, which):
    path = tmp_path / "chars.nc"
    with netcdf_file(path, "w") as nc:
        nc.createDimension("x", NX)
        nc.createDimension("y", NY)
        for name, values in (("x", E), ("y", N)):
            if name == which:  # digits as characters: '1' would convert, 'a' would not; neither is a coordinate
                nc.createVariable(name, "S1", (name,))[:] = np.array([b"1"] * (len(values) - 1) + [b"a"])
            else:
                nc.createVariable(name, "f8", (name,))[:] = values
        nc.createVariable("z", "f8", ("y", "x"))[:] = Z
    raises_naming(path, read_grid, path, match=f"coordinate {which} is not numeric (it holds S1 values)")


def test_netcdf_z_stored_as_x_by_y(tmp_path):
    path = tmp_path / "transposed.nc"
    with netcdf_file(path, "w") as nc:
        nc.createDimension("x", NX)
        nc.createDimension("y", NY)
        nc.createVariable("x", "f8", ("x",))[:] = E
        nc.createVariable("y", "f8", ("y",))[:] = N
        nc.createVariable("z", "f8", ("x", "y"))[:] = Z.T
    assert_plane(read_grid(path))


def test_netcdf_lon_lat_elevation_is_geographic(tmp_path):
    path = tmp_path / "geo.nc"
    lon = -121.8 + 1e-4 * np.arange(NX)
    lat = 36.8 + 1e-4 * np.arange(NY)
    z = -80 + 2000 * (lon[None, :] - lon[0]) + 3000 * (lat[:, None] - lat[0])
    write_nc(path, lon, lat[::-1], z[::-1], names=("lon", "lat", "elevation"),
             xy_units=("degrees_east", "degrees_north"))
    m = read_grid(path)
    assert m.meta["source_crs"] == "epsg4326" and m.meta["rows"] == "north_to_south"
    rng = np.random.default_rng(2)
    lo = rng.uniform(lon[0], lon[-1], 100)
    la = rng.uniform(lat[0], lat[-1], 100)
    e, n = lonlat_to_local(m, lo, la)
    expect = -80 + 2000 * (lo - lon[0]) + 3000 * (la - lat[0])
    np.testing.assert_allclose(m.elevation(e, n), expect, atol=1e-8)
    back_lon, back_lat = local_to_lonlat(m, e, n)
    np.testing.assert_allclose(back_lon, lo, atol=1e-12)
    np.testing.assert_allclose(back_lat, la, atol=1e-12)


def test_netcdf4_needs_h5py(tmp_path, monkeypatch):
    path = tmp_path / "nc4.nc"
    path.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00" * 64)
    monkeypatch.setitem(sys.modules, "h5py", None)
    raises_naming(path, read_grid, path, match="pip install h5py")


def test_netcdf4_via_h5py(tmp_path):
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "nc4.nc"
    with h5py.File(path, "w") as f:
        f["x"] = E
        f["y"] = N[::-1]
        f["z"] = Z[::-1]
        f["z"].attrs["_FillValue"] = np.array([-9999.0])
    assert_plane(read_grid(path))


def test_netcdf4_with_dimension_scales(tmp_path):
    """A NetCDF-4 file as the netCDF library writes it: lon/lat dimension scales attached
    to a 2-D ``elevation`` variable (DIMENSION_LIST references), rows north to south."""
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "gmt4.grd"
    with h5py.File(path, "w") as f:
        f["x"] = E
        f["y"] = N[::-1]
        for name in ("x", "y"):
            f[name].make_scale(name)
        f["elevation"] = Z[::-1]
        f["elevation"].dims[0].attach_scale(f["y"])
        f["elevation"].dims[1].attach_scale(f["x"])
    assert_plane(read_grid(path, format="netcdf"))


def test_garbage_netcdf(tmp_path):
    path = tmp_path / "junk.nc"
    path.write_bytes(b"CDF\x01garbage")
    raises_naming(path, read_grid, path, match="NetCDF")
    path.write_text("hello")
    raises_naming(path, read_grid, path, match="not a NetCDF file")


def test_netcdf_without_coordinates_takes_origin_and_resolution(tmp_path):
    """No coordinate variables: the grid as stored, placed by origin/resolution (or bounds and rows)."""
    path = tmp_path / "bare.nc"
    with netcdf_file(path, "w") as nc:
        nc.createDimension("rows", NY)
        nc.createDimension("cols", NX)
        nc.createVariable("z", "f8", ("rows", "cols"))[:] = Z
    raises_naming(path, read_grid, path, match="no usable georeferencing (no coordinate variables")
    m = read_grid(path, origin=(E0, N0), resolution=(RE, RN))
    assert_plane(m)
    assert m.meta["georef"] == "arguments" and m.meta["rows"] == "south_to_north"
    assert_plane(read_grid(path, bounds=BOUNDS, rows="south_to_north"))
    with netcdf_file(path, "w") as nc:  # stored north first, as a GMT grid without coordinates might be
        nc.createDimension("rows", NY)
        nc.createDimension("cols", NX)
        nc.createVariable("z", "f8", ("rows", "cols"))[:] = Z[::-1]
    assert_plane(read_grid(path, origin=(E0, N[-1]), resolution=(RE, RN), rows="north_to_south"))


# --------------------------------------------------------------------------- ESRI ASCII


@pytest.mark.parametrize("registration", ["corner", "center"])
def test_esri_ascii_registration(tmp_path, registration):
    path = tmp_path / f"plane_{registration}.asc"
    if registration == "corner":
        origin = {"xllcorner": E0 - RE / 2, "yllcorner": N0 - RE / 2}
    else:
        origin = {"xllcenter": E0, "yllcenter": N0}
    ny, ny_res = NY, RE  # ESRI cells are square: use res RE on both axes
    n = N0 + ny_res * np.arange(ny)
    z = plane(E[None, :], n[:, None])
    z_file = z[::-1].copy()
    z_file[0, 0] = -9999  # NW node
    write_asc(path, z_file, {"ncols": NX, "nrows": ny, **origin, "cellsize": RE, "NODATA_value": -9999})
    m = read_grid(path)
    assert m.meta["rows"] == "north_to_south"
    assert (m.e0, m.n0, m.res_e, m.res_n) == pytest.approx((E0, N0, RE, RE))
    assert np.isnan(m.z[-1, 0])  # the first value in the file is the north-west node
    rng = np.random.default_rng(3)
    e = rng.uniform(E0 + RE, m.e_max, 200)
    nn = rng.uniform(N0, m.n_max - RE, 200)
    np.testing.assert_allclose(m.elevation(e, nn), plane(e, nn), atol=1e-6)


def test_esri_ascii_dx_dy_and_errors(tmp_path):
    path = tmp_path / "dxdy.asc"
    write_asc(path, Z[::-1], {"ncols": NX, "nrows": NY, "xllcenter": E0, "yllcenter": N0, "dx": RE, "dy": RN})
    assert_plane(read_grid(path))
    raises_naming(path, read_grid, path, rows="south_to_north", match="contradicts")
    bad = tmp_path / "short.asc"
    write_asc(bad, Z[::-1][:-1], {"ncols": NX, "nrows": NY, "xllcenter": E0, "yllcenter": N0, "cellsize": RE})
    raises_naming(bad, read_grid, bad, match="values")


@pytest.mark.parametrize("key, value", [("ncols", "nan"), ("ncols", "inf"), ("ncols", "-100"), ("ncols", "0"),
                                        ("ncols", "100.7"), ("ncols", "23.0000001"), ("nrows", "nan"),
                                        ("nrows", "-17")])
def test_esri_ascii_counts_must_be_positive_whole_numbers(tmp_path, key, value):
    """ncols / nrows: no truncation (100.7 is not 100), no crash on nan or inf, no negative counts."""
    path = tmp_path / "counts.asc"
    header = {"ncols": NX, "nrows": NY, "xllcenter": E0, "yllcenter": N0, "cellsize": RE, key: value}
    write_asc(path, Z[::-1], header)
    raises_naming(path, read_grid, path, match=f"{key} must be a positive whole number (got {value})")


def test_esri_ascii_both_counts_negative_is_named(tmp_path):
    """-17 x -23 multiplies to the right number of values: still the header's fault, and said so."""
    path = tmp_path / "negative.asc"
    write_asc(path, Z[::-1], {"ncols": -NX, "nrows": -NY, "xllcenter": E0, "yllcenter": N0, "cellsize": RE})
    raises_naming(path, read_grid, path, match=f"ncols must be a positive whole number (got -{NX})")
    write_asc(path, Z[::-1], {"ncols": f"{NX}.0", "nrows": NY, "xllcenter": E0, "yllcenter": N0, "cellsize": RE})
    assert read_grid(path).shape == (NY, NX)  # a whole number written with a decimal point is fine


@pytest.mark.parametrize("key, value, match", [
    ("xllcenter", "nan", "xllcenter must be finite (got nan)"),
    ("yllcenter", "-inf", "yllcenter must be finite (got -inf)"),
    ("cellsize", "inf", "cellsize must be a positive finite number (got inf)"),
    ("cellsize", "nan", "cellsize must be a positive finite number (got nan)"),
    ("cellsize", "-5", "cellsize must be a positive finite number (got -5)"),
])
def test_esri_ascii_georeferencing_must_be_finite(tmp_path, key, value, match):
    path = tmp_path / "georef.asc"
    header = {"ncols": NX, "nrows": NY, "xllcenter": E0, "yllcenter": N0, "cellsize": RE, key: value}
    write_asc(path, Z[::-1], header)
    raises_naming(path, read_grid, path, match=match)
    corner = tmp_path / "corner.asc"
    write_asc(corner, Z[::-1], {"ncols": NX, "nrows": NY, "xllcorner": "inf", "yllcorner": N0, "dx": RE, "dy": RN})
    raises_naming(corner, read_grid, corner, match="xllcorner must be finite (got inf)")
    write_asc(corner, Z[::-1], {"ncols": NX, "nrows": NY, "xllcorner": E0, "yllcorner": N0, "dx": RE, "dy": "inf"})
    raises_naming(corner, read_grid, corner, match="dy must be a positive finite number (got inf)")


def test_esri_ascii_non_finite_data_are_holes(tmp_path):
    """nan / inf among the values are holes, as in every other format (not infinite elevations)."""
    path = tmp_path / "holes.asc"
    lines = [f"ncols {NX}", f"nrows {NY}", f"xllcenter {E0}", f"yllcenter {N0}", f"dx {RE}", f"dy {RN}"]
    rows = [[f"{v:.10f}" for v in row] for row in Z[::-1]]
    rows[0][0], rows[0][1], rows[1][0] = "inf", "-inf", "nan"  # the north-west corner
    path.write_text("\n".join(lines + [" ".join(r) for r in rows]) + "\n")
    m = read_grid(path)
    assert np.isnan(m.z[-1, :2]).all() and np.isnan(m.z[-2, 0]) and m.meta["nodata_nodes"] == 3
    assert np.isfinite(m.z).sum() == m.z.size - 3


# --------------------------------------------------------------------------- npy / npz


def test_npy_origin_resolution_both_orientations(tmp_path):
    path = tmp_path / "plane.npy"
    np.save(path, Z)
    assert_plane(read_grid(path, origin=(E0, N0), resolution=(RE, RN)))
    np.save(path, Z[::-1])
    # origin is the stored node [0, 0]: here the north-west node.
    assert_plane(read_grid(path, origin=(E0, N[-1]), resolution=(RE, RN), rows="north_to_south"))
    assert_plane(read_grid(path, bounds=BOUNDS, rows="north_to_south"))


def test_npz_keys_and_single_array(tmp_path):
    path = tmp_path / "map.npz"
    np.savez(path, z=Z, e0=E0, n0=N0, res_e=RE, res_n=RN)
    m = read_grid(path)
    assert_plane(m)
    assert m.meta["georef"] == "keys"
    only = tmp_path / "only.npz"
    np.savez(only, heights=Z)
    assert_plane(read_grid(only, origin=(E0, N0), resolution=(RE, RN)))
    partial = tmp_path / "partial.npz"
    np.savez(partial, z=Z, res_e=RE, res_n=RN)
    assert_plane(read_grid(partial, origin=(E0, N0)))


@pytest.mark.parametrize("key, value", [("e0", np.nan), ("e0", np.inf), ("n0", -np.inf), ("res_e", np.inf),
                                        ("res_n", np.nan)])
def test_npz_georeferencing_keys_must_be_finite(tmp_path, key, value):
    """A non-finite origin or spacing is the file's fault, said by the reader (not a map at E nan .. nan m)."""
    path = tmp_path / "nonfinite.npz"
    np.savez(path, **{"z": Z, "e0": E0, "n0": N0, "res_e": RE, "res_n": RN, key: value})
    raises_naming(path, read_grid, path, match=f".npz key {key} must be finite, got {value}")


def test_georeferencing_that_overflows_is_refused(tmp_path):
    """Finite origin and spacing whose far corner overflows (from any reader or the arguments): one line."""
    path = tmp_path / "far.npy"
    np.save(path, Z)
    msg = raises_naming(path, read_grid, path, origin=(1.7e308, 0.0), resolution=(1e307, RN),
                        match="the georeferencing (arguments) is not finite")
    assert "far corner (inf, " in msg, msg


def test_a_reader_giving_inf_heights_gets_holes(tmp_path):
    """A (plug-in) reader that hands over inf elevations: holes, as the built-in readers make them."""
    from tanbench.terrain.formats import RawGrid, register_format
    from tanbench.terrain.formats.registry import FORMATS

    def read_inf(path):
        z = Z.copy()
        z[2, 3], z[4, 5] = np.inf, -np.inf
        return RawGrid(z, georef="keys", x0=E0, y0=N0, dx=RE, dy=RN, crs="metric")

    register_format("inf-test", (".inftest",), read_inf)
    try:
        (tmp_path / "g.inftest").write_text("")
        m = read_grid(tmp_path / "g.inftest")
    finally:
        FORMATS.pop("inf-test")
    assert np.isnan(m.z[2, 3]) and np.isnan(m.z[4, 5]) and m.meta["nodata_nodes"] == 2
    assert not np.isinf(m.z).any()


def test_npy_without_georeferencing_is_an_error(tmp_path):
    path = tmp_path / "bare.npy"
    np.save(path, Z)
    raises_naming(path, read_grid, path, match="bounds=")
    raises_naming(path, read_grid, path, origin=(E0, N0), match="resolution=")
    raises_naming(path, read_grid, path, bounds=BOUNDS, match="rows=")
    raises_naming(path, read_grid, path, bounds=BOUNDS, origin=(0, 0), rows="south_to_north")


def test_npy_npz_with_text_or_object_data_are_refused_plainly(tmp_path):
    """A text file renamed .npy/.npz, or object arrays: one plain line, not numpy's advice to load it unsafely."""
    text_npy, text_npz, obj_npy, obj_npz = (tmp_path / n for n in ("text.npy", "text.npz", "obj.npy", "obj.npz"))
    text_npy.write_text("hello")
    text_npz.write_text("hello")
    np.save(obj_npy, np.array([{"z": 1}, 2], dtype=object))
    np.savez(obj_npz, z=np.array([{"z": 1}, 2], dtype=object))
    for path in (text_npy, text_npz, obj_npy, obj_npz):
        msg = raises_naming(path, read_grid, path, origin=(E0, N0), resolution=(RE, RN),
                            match="not a numeric NumPy array file (object/pickled data is refused)")
        assert "allow_pickle" not in msg, msg


# --------------------------------------------------------------------------- generic errors


def test_missing_file_and_unknown_format(tmp_path):
    missing = tmp_path / "nowhere.tif"
    raises_naming(missing, read_grid, missing, match="not found")
    odd = tmp_path / "grid.xyz"
    odd.write_text("1 2 3\n")
    msg = raises_naming(odd, read_grid, odd, match="known formats")
    assert "geotiff" in msg and "netcdf" in msg and "esri-ascii" in msg
    raises_naming(odd, read_grid, odd, format="surfer", match="known formats")


# --------------------------------------------------------------------------- projection


def enu_reference(lon, lat, lon_c, lat_c):
    """Independent ECEF -> ENU on the WGS84 ellipsoid (h = 0)."""

    def ecef(lo, la):
        lo, la = np.radians(lo), np.radians(la)
        nu = WGS84_A / np.sqrt(1 - WGS84_E2 * np.sin(la) ** 2)
        return np.stack([nu * np.cos(la) * np.cos(lo), nu * np.cos(la) * np.sin(lo),
                         nu * (1 - WGS84_E2) * np.sin(la)])

    d = ecef(lon, lat) - ecef(lon_c, lat_c)[:, None, None]
    lo, la = math.radians(lon_c), math.radians(lat_c)
    east = np.array([-math.sin(lo), math.cos(lo), 0.0])
    north = np.array([-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)])
    return np.tensordot(east, d, 1), np.tensordot(north, d, 1)


@pytest.mark.parametrize("lat_c, limit", [(36.8, 0.32), (60.0, 0.72)])
def test_projection_error_over_3_km(lat_c, limit):
    w = 1 - WGS84_E2 * math.sin(math.radians(lat_c)) ** 2
    deg_n = 3000 / (math.pi / 180 * WGS84_A * (1 - WGS84_E2) / w ** 1.5)
    deg_e = 3000 / (math.pi / 180 * WGS84_A / math.sqrt(w) * math.cos(math.radians(lat_c)))
    lon_c = -121.8
    native = Map(np.zeros((31, 31)), lon_c - deg_e / 2, lat_c - deg_n / 2, deg_e / 30, deg_n / 30,
                 meta={"crs": "epsg4326"})
    local = to_local(native)
    assert (local.e_max, local.n_max) == pytest.approx((3000, 3000), rel=1e-9)
    lon = np.linspace(native.e0, native.e_max, 41)
    lat = np.linspace(native.n0, native.n_max, 41)
    glon, glat = np.meshgrid(lon, lat)
    e_ref, n_ref = enu_reference(glon, glat, lon_c, lat_c)
    e, n = lonlat_to_local(local, glon, glat)
    e_c, n_c = lonlat_to_local(local, lon_c, lat_c)
    err = np.hypot(e - e_c - e_ref, n - n_c - n_ref)
    assert err.max() < limit
    assert local.meta["projection_error_m"] == pytest.approx(err.max(), rel=1e-3)
    # Distances between nodes: relative error below 1e-4 (a ruler of 3 km is off by < 0.3 m).
    d_frame = np.hypot(e[-1, -1] - e[0, 0], n[-1, -1] - n[0, 0])
    d_ref = np.hypot(e_ref[-1, -1] - e_ref[0, 0], n_ref[-1, -1] - n_ref[0, 0])
    assert abs(d_frame - d_ref) / d_ref < 1e-4


def mercator_y(lat):
    return WGS84_A * np.log(np.tan(np.pi / 4 + np.radians(lat) / 2))


def inverse_mercator(y):
    return np.degrees(2 * np.arctan(np.exp(y / WGS84_A)) - np.pi / 2)


def test_web_mercator_grid_with_bounds(tmp_path):
    lon_min, lon_max, lat_min, lat_max = -121.825, -121.815, 36.79, 36.80
    lon = np.linspace(lon_min, lon_max, NX)
    lat = inverse_mercator(np.linspace(mercator_y(lat_min), mercator_y(lat_max), NY))
    # Linear in lon and lat, hence linear in the local frame: row resampling must be exact.
    z = -40 + 3000 * (lon[None, :] - lon_min) - 7000 * (lat[:, None] - lat_min)
    path = tmp_path / "merc.npy"
    np.save(path, z[::-1])
    m = read_grid(path, crs="epsg3857", bounds=(lon_min, lon_max, lat_min, lat_max), rows="north_to_south")
    assert m.shape == (NY, NX)
    assert m.meta["lon0"] == pytest.approx(lon_min) and m.meta["lat0"] == pytest.approx(lat_min)
    assert m.n_max == pytest.approx(m.meta["m_per_deg_lat"] * (lat_max - lat_min))
    rng = np.random.default_rng(4)
    lo = rng.uniform(lon_min, lon_max, 200)
    la = rng.uniform(lat_min, lat_max, 200)
    e, n = lonlat_to_local(m, lo, la)
    expect = -40 + 3000 * (lo - lon_min) - 7000 * (la - lat_min)
    np.testing.assert_allclose(m.elevation(e, n), expect, atol=1e-6)
    # Nodes of the source rows, read back at their own latitudes.
    e, n = lonlat_to_local(m, lon[3], lat)
    np.testing.assert_allclose(m.elevation(e, n), z[:, 3], atol=1e-6)


# --------------------------------------------------------------------------- mosaics


def tiles_of(z, cuts_r, cuts_c, overlap=0, crs=None):
    """Cut a grid into tiles at row/column indices, each extended by ``overlap`` nodes."""
    tiles = []
    for r0, r1 in zip(cuts_r[:-1], cuts_r[1:]):
        for c0, c1 in zip(cuts_c[:-1], cuts_c[1:]):
            rr1, cc1 = min(r1 + overlap, z.shape[0]), min(c1 + overlap, z.shape[1])
            meta = {"crs": crs} if crs else {}
            tiles.append(Map(z[r0:rr1, c0:cc1], E0 + c0 * RE, N0 + r0 * RN, RE, RN,
                             name=f"t{r0}_{c0}", meta=meta))
    return tiles


@pytest.mark.parametrize("overlap", [0, 3])
def test_mosaic_of_a_plane_is_the_plane(overlap):
    tiles = tiles_of(Z, [0, 8, NY], [0, 11, NX], overlap)
    joined, seams = mosaic(tiles[::-1])
    assert joined.shape == Z.shape
    assert (joined.e0, joined.n0) == pytest.approx((E0, N0))
    np.testing.assert_allclose(joined.z, Z, atol=1e-9)
    kinds = sorted(s["kind"] for s in seams)
    if overlap:
        assert kinds.count("overlap") == 6  # four edges plus the two diagonal corners
    else:
        assert kinds == ["east-west", "east-west", "north-south", "north-south"]
        for s in seams:
            expect_jump = abs(B) * RE if s["kind"] == "east-west" else abs(C) * RN
            assert s["mean_abs_jump"] == pytest.approx(expect_jump)
    for s in seams:
        assert s["pairs"] > 0 and s["max_abs_step"] < 1e-9


@pytest.mark.parametrize("overlap", [0, 2])
def test_mosaic_reports_an_injected_step(overlap):
    tiles = tiles_of(Z, [0, 8, NY], [0, 11, NX], overlap)
    north_east = tiles[3]
    tiles[3] = Map(north_east.z + 2.5, north_east.e0, north_east.n0, RE, RN, name="stepped")
    joined, seams = mosaic(tiles)
    for s in seams:
        if "stepped" in s["tiles"]:
            assert s["mean_abs_step"] == pytest.approx(2.5) and s["max_abs_step"] == pytest.approx(2.5)
            e, n = s["worst_at"]
            assert e >= E0 + 11 * RE - RE and n >= N0 + 8 * RN - RN
        else:
            assert s["max_abs_step"] < 1e-9
    assert joined.z[15, 20] == pytest.approx(Z[15, 20] + 2.5)
    if overlap:  # overlapping nodes take the mean of the tiles covering them
        assert joined.z[8, 11] == pytest.approx(Z[8, 11] + 2.5 / 4)  # all four tiles
        assert joined.z[14, 12] == pytest.approx(Z[14, 12] + 2.5 / 2)  # two tiles


def test_mosaic_leaves_gaps_nan():
    tiles = tiles_of(Z, [0, 8, NY], [0, 11, NX])
    joined, _ = mosaic([tiles[0], tiles[3]])
    assert joined.shape == Z.shape and np.isnan(joined.z[0, -1]) and np.isnan(joined.z[-1, 0])
    assert joined.meta["uncovered_nodes"] == 8 * (NX - 11) + (NY - 8) * 11


def test_tiles_not_on_one_grid(tmp_path):
    a = tmp_path / "a.npz"
    b = tmp_path / "b.npz"
    np.savez(a, z=Z, e0=E0, n0=N0, res_e=RE, res_n=RN)
    np.savez(b, z=Z, e0=E0 + NX * RE + 0.5 * RE, n0=N0, res_e=RE, res_n=RN)
    raises_naming(b, read_tiles, [a, b], match="mosaic grid")
    np.savez(b, z=Z, e0=E0 + NX * RE, n0=N0, res_e=1.1 * RE, res_n=RN)
    raises_naming(b, read_tiles, [a, b], match="mosaic grid")
    local = Map(Z, 0, 0, RE, RN, name="projected", meta={"crs": "local", "source": "projected.tif"})
    with pytest.raises(TanbenchError, match="projected.tif"):
        mosaic([local, local])


def test_geographic_tiles_mosaic_then_project_once(tmp_path):
    lon = -121.8 + 1e-4 * np.arange(NX)
    lat = 36.8 + 1e-4 * np.arange(NY)
    z = -80 + 2000 * (lon[None, :] - lon[0]) + 3000 * (lat[:, None] - lat[0])
    whole = tmp_path / "whole.nc"
    write_nc(whole, lon, lat, z, names=("lon", "lat", "z"))
    paths = []
    for r0, r1 in ((0, 9), (8, NY)):
        for c0, c1 in ((0, 12), (11, NX)):
            p = tmp_path / f"tile_{r0}_{c0}.nc"
            write_nc(p, lon[c0:c1], lat[r0:r1], z[r0:r1, c0:c1], names=("lon", "lat", "z"))
            paths.append(p)
    joined, seams = read_tiles(paths)
    ref = read_grid(whole)
    assert joined.shape == ref.shape
    for key in ("lon0", "lat0", "lat_c", "m_per_deg_lon", "m_per_deg_lat"):
        assert joined.meta[key] == pytest.approx(ref.meta[key], rel=1e-12)
    np.testing.assert_allclose(joined.z, ref.z, atol=1e-9)
    assert all(s["kind"] == "overlap" and s["max_abs_step"] < 1e-9 for s in seams)
    for s in seams:  # seam locations are in the local frame
        e, n = s["worst_at"]
        assert 0 <= e <= joined.e_max and 0 <= n <= joined.n_max


# --------------------------------------------------------------------------- holes


def holed_map():
    z = Z.copy()
    z[5, 7] = np.nan
    z[10:12, 15:18] = np.nan
    return Map(z, E0, N0, RE, RN, name="holed")


def test_find_holes_matches_the_kernel():
    m = holed_map()
    rng = np.random.default_rng(5)
    e = rng.uniform(E0, m.e_max, 400)
    n = rng.uniform(N0, m.n_max, 400)
    nan_lookup = np.isnan(m.elevation(e, n))
    for ek, nk, bad in zip(e, n, nan_lookup):
        assert bool(find_holes(m, ek, nk)) == bad
    assert find_holes(m, E0 + 7 * RE + 1.0, N0 + 5 * RN + 1.0) == [(E0 + 7 * RE, N0 + 5 * RN)]
    assert find_holes(m, E0 + 1.0, N0 + 1.0) == []
    assert find_holes(m, E0 + 7 * RE - 1.5 * RE, N0 + 5 * RN, margin=RE) == [(E0 + 7 * RE, N0 + 5 * RN)]
    assert find_holes(m, E0 - 100.0, N0 - 100.0, margin=10.0) == []
    holes = find_holes(m, E, np.full(NX, N0 + 10.5 * RN))
    assert holes == [(E0 + j * RE, N0 + i * RN) for i in (10, 11) for j in (15, 16, 17)]


@pytest.mark.parametrize("method", ["laplace", "nearest"])
def test_fill_holes(method):
    m = holed_map()
    filled = fill_holes(m, method=method)
    assert np.isfinite(filled.z).all() and filled.meta["filled_nodes"] == 7
    ok = np.isfinite(m.z)
    np.testing.assert_array_equal(filled.z[ok], m.z[ok])
    if method == "laplace":
        np.testing.assert_allclose(filled.z, Z, atol=1e-9)  # harmonic: exact for a plane
    else:
        assert filled.z[5, 7] in {Z[4, 7], Z[6, 7], Z[5, 6], Z[5, 8]}
    whole = Map(Z, E0, N0, RE, RN)
    assert fill_holes(whole) is whole
    with pytest.raises(TanbenchError):
        fill_holes(Map(np.full((3, 3), np.nan), 0, 0, 1, 1))


# --------------------------------------------------------------------------- file names


def test_parse_bounds_from_name(tmp_path):
    name = "MontereyBay.R_-121.825_-121.815_36.790_36.800.epsg3857.tif"
    assert parse_bounds_from_name(name) == (-121.825, -121.815, 36.79, 36.8)
    raises_naming("plain.tif", parse_bounds_from_name, "plain.tif", match="R_<lon_min>")


def test_read_tiles_bounds_from_names(tmp_path):
    # Two untagged tiles sharing their common edge column, bounds only in the names.
    lon = np.linspace(-121.825, -121.805, 2 * NX - 1)
    lat = inverse_mercator(np.linspace(mercator_y(36.79), mercator_y(36.80), NY))
    z = -40 + 3000 * (lon[None, :] - lon[0]) - 7000 * (lat[:, None] - lat[0])
    west = tmp_path / "T.R_-121.825_-121.815_36.790_36.800.epsg3857.tif"
    east = tmp_path / "T.R_-121.815_-121.805_36.790_36.800.epsg3857.tif"
    write_tiff(west, z[:, :NX])
    write_tiff(east, z[:, NX - 1:])
    raises_naming(west, read_tiles, [west, east], match="rows")
    joined, seams = read_tiles([west, east], rows="south_to_north")
    assert joined.shape == (NY, 2 * NX - 1)
    assert seams[0]["kind"] == "overlap" and seams[0]["pairs"] == NY and seams[0]["max_abs_step"] < 1e-9
    e, n = lonlat_to_local(joined, lon[5], lat)
    np.testing.assert_allclose(joined.elevation(e, n), z[:, 5], atol=1e-6)


# --------------------------------------------------------------------------- Monterey


def monterey_paths():
    paths = sorted(MONTEREY.glob("MontereyBay.R_*.epsg3857.tif"))
    if len(paths) != 4:
        pytest.skip(f"Monterey tiles not found in {MONTEREY.resolve()} (shared data folder absent)")
    pytest.importorskip("tifffile")
    return paths


def test_monterey_mosaic():
    paths = monterey_paths()
    m, seams = read_tiles(paths, crs="epsg3857", rows="south_to_north")
    # Each 119 x 119 tile spans its named 0.01 deg with 108 steps (1/3 arc-second) plus
    # 5 nodes beyond each named edge, so neighbours share 11 rows or columns: 227 x 227.
    assert m.shape == (227, 227)
    assert m.e_max == pytest.approx(1867.5, abs=1.0) and m.n_max == pytest.approx(2322.2, abs=1.0)
    assert (m.res_e, m.res_n) == pytest.approx((8.26, 10.28), abs=0.01)
    assert np.isfinite(m.z).all()
    assert np.min(m.z) == pytest.approx(-223.5, abs=0.5) and np.max(m.z) == pytest.approx(-13.3, abs=0.5)
    assert m.meta["projection_error_m"] < 0.2
    assert len(seams) == 6 and all(s["kind"] == "overlap" for s in seams)
    # The shared rows and columns hold identical samples: the seams vanish.
    assert all(s["pairs"] in (11 * 119, 11 * 11) and s["max_abs_step"] == 0.0 for s in seams)
    # The GeoTIFF tags put each tile's named bounds on its nodes 5 and 113.
    for path in paths:
        tile = read_grid(path, project=False)
        assert tile.meta["crs"] == "epsg3857" and tile.meta["georef"] == "tags"
        lon_min, lon_max, lat_min, lat_max = parse_bounds_from_name(path)
        cols = (WGS84_A * np.radians([lon_min, lon_max]) - tile.e0) / tile.res_e
        rows = (mercator_y(np.array([lat_min, lat_max])) - tile.n0) / tile.res_n
        np.testing.assert_allclose(np.concatenate([cols, rows]), [5, 113, 5, 113], atol=1e-3)


def test_monterey_names_alone_misplace_the_tiles():
    paths = monterey_paths()
    bounds = [parse_bounds_from_name(p) for p in paths]
    m, seams = read_tiles(paths, bounds=bounds, crs="epsg3857", rows="south_to_north")
    # Taking each tile's 119 nodes to span exactly its named bounds squeezes the tiles by
    # 108/118 and stacks the 11 shared rows on one: the joins step by metres to tens of metres.
    assert m.shape == (237, 237)
    worst = max(s["mean_abs_step"] for s in seams if s["pairs"] > 100)
    assert worst > 10.0
