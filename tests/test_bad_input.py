"""Bad input through the CLI: exactly one `error:` line naming the problem, exit code 2, no traceback.

One table of cases (sweep YAML, map files, results and output directories, a Dask
address); ``{maps}``, ``{tmp}`` and ``{sweep}`` in a case are filled in at run time.
"""

from __future__ import annotations

import copy
import json
import os
import time

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from sweep_support import cli, error_lines

BASE = {"name": "bad", "seed": 1, "runs": 2, "scenario": {"particles": 60, "duration_s": 60}}

MAP_RES = 5.0  # the test maps' node spacing, m; they span 0..1000 m east and north
FILE_SCENARIO = {
    "area": "custom", "particles": 60, "duration_s": 60,
    "terrain": {"kind": "file", "path": "{maps}/map.npy", "origin": [0, 0], "resolution": MAP_RES},
    "trajectory": {"kind": "survey", "centre_en_m": [500, 500], "heading_deg": 0, "leg_length_m": 300,
                   "leg_spacing_m": 100, "legs": 2, "depth_m": 20},
}


def sweep(*drop, **changes) -> dict:
    """The base sweep with top-level keys replaced and ``scenario.x.y=`` given as ``scenario__x__y=``."""
    data = copy.deepcopy(BASE)
    for key in drop:
        data.pop(key)
    for key, value in changes.items():
        *parents, last = key.split("__")
        node = data
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = value
    return data


def file_sweep(path="{maps}/map.npy", **changes) -> dict:
    """A sweep over a map file around a survey track (changes as in :func:`sweep`)."""
    data = sweep(scenario=copy.deepcopy(FILE_SCENARIO), **changes)
    data["scenario"]["terrain"]["path"] = path
    return data


def incompatible_results(tmp, layout):
    """A results directory whose run file says results schema 999."""
    out = tmp / "out"
    path = out / "runs" / layout / "run-00000.parquet"
    path.parent.mkdir(parents=True)
    table = pa.table({"cell_id": ["x"], "run": [0]}).replace_schema_metadata(
        {b"tanbench": json.dumps({"schema_version": 999}).encode()})
    pq.write_table(table, path)
    (out / "sweep.yaml").write_text(yaml.safe_dump(BASE))
    return {"out": str(out)}


def unwritable_output(tmp):
    """A read-only directory, or (as root, who may write there anyway) a path under a regular file."""
    ro = tmp / "readonly"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        (ro / "probe").write_text("")
    except OSError:
        return {"out": str(ro / "sub")}
    ro.chmod(0o700)
    (tmp / "a-file").write_text("")
    return {"out": str(tmp / "a-file" / "sub")}


def case(id, args, data, *fragments, setup=None, max_s=None):
    return pytest.param(args, data, fragments, setup, max_s, id=id)


CASES = [
    # the sweep file itself
    case("no-such-sweep-file", ["validate", "{tmp}/missing.yaml"], None, "missing.yaml: no such sweep file"),
    case("sweep-file-is-a-directory", ["validate", "{tmp}"], None, "cannot read the sweep file"),
    case("malformed-yaml", ["validate", "{sweep}"], "name: bad\nseed: [1\n", "bad.yaml: malformed YAML at line"),
    case("not-a-mapping", ["validate", "{sweep}"], "- 1\n- 2\n", "a sweep file must be a mapping"),
    case("unknown-top-level-key", ["validate", "{sweep}"], sweep(colour="red"), "bad.yaml: colour: unknown key"),
    case("unknown-nested-key", ["validate", "{sweep}"], sweep(scenario__filter__foo=1),
         "scenario.filter.foo: unknown key"),
    case("unknown-method", ["validate", "{sweep}"], sweep(methods=["tight-dvl", "magic"]), "unknown method 'magic'"),
    case("wrong-type", ["validate", "{sweep}"], sweep(scenario__particles="lots"),
         "scenario.particles: Input should be a valid integer", "'lots'"),
    case("zero-particles", ["validate", "{sweep}"], sweep(scenario__particles=0),
         "scenario.particles: Input should be greater than 0"),
    case("negative-particles", ["run", "{sweep}", "--out", "{tmp}/out"], sweep(scenario__particles=-5),
         "scenario.particles: Input should be greater than 0", "(got -5)"),
    case("zero-runs", ["validate", "{sweep}"], sweep(runs=0), "runs: Input should be greater than 0"),
    case("negative-runs", ["run", "{sweep}", "--out", "{tmp}/out"], sweep(runs=-3),
         "runs: Input should be greater than 0"),
    case("missing-seed", ["validate", "{sweep}"], sweep("seed"), "seed: Field required"),
    case("zero-map-resolution", ["validate", "{sweep}"], sweep(scenario__map_resolution_m=0),
         "scenario.map_resolution_m: Input should be greater than 0"),
    case("negative-map-resolution-in-a-table", ["validate", "{sweep}"],
         sweep(tables={"maps": {"map_resolution_m": [10, -20]}}),
         "tables.maps: map_resolution_m: Input should be greater than 0"),
    case("zero-sampling-time", ["validate", "{sweep}"], sweep(scenario__sampling_time_s=0),
         "scenario.sampling_time_s: Input should be greater than 0"),
    case("negative-sampling-time", ["validate", "{sweep}"], sweep(scenario__sampling_time_s=-1),
         "scenario.sampling_time_s: Input should be greater than 0"),
    case("sampling-time-not-whole-pings", ["validate", "{sweep}"], sweep(scenario__sampling_time_s=1.5),
         "sampling_time_s (1.5) must be a whole number of sonar pings"),
    case("empty-table-values", ["validate", "{sweep}"], sweep(tables={"maps": {"map_resolution_m": []}}),
         "maps.map_resolution_m: needs at least one value"),
    # map resolution against the terrain
    case("map-finer-than-synthetic-truth", ["validate", "{sweep}"], sweep(scenario__map_resolution_m=1),
         "scenario.map_resolution_m (1) is finer than the truth grid (2.5 m)"),
    case("map-finer-than-file-grid", ["validate", "{sweep}"], file_sweep(scenario__map_resolution_m=2),
         "bad.yaml: cell", "map resolution 2.0 m is finer than the truth grid (5 m)"),
    case("map-coarser-than-extent", ["validate", "{sweep}"], sweep(scenario__map_resolution_m=5000),
         "bad.yaml: cell", "map resolution 5000.0 m is coarser than the map extent"),
    # map files
    case("missing-map-file", ["validate", "{sweep}"], file_sweep("{maps}/nothere.npy"),
         "nothere.npy: file not found"),
    case("garbage-tif", ["validate", "{sweep}"], file_sweep("{maps}/garbage.tif"),
         "garbage.tif: not a readable TIFF file"),
    case("map-path-is-a-directory", ["validate", "{sweep}"], file_sweep("{maps}/a-directory.npy"),
         "a-directory.npy: not a regular file"),
    case("unknown-map-format", ["validate", "{sweep}"], file_sweep("{maps}/map.xyz"),
         "map.xyz: cannot tell the grid format from the extension '.xyz'"),
    case("glob-matches-nothing", ["validate", "{sweep}"], file_sweep("{maps}/tiles-*.npy"),
         "matches no file"),
    case("holes-under-the-track", ["run", "{sweep}", "--out", "{tmp}/out"],
         file_sweep("{maps}/holes.npy", scenario__duration_s=None),
         "the map has no data (a hole) under the track at t=", "(E, N) = (450, 4", "terrain.fill_holes: true"),
    case("trajectory-leaves-the-map", ["validate", "{sweep}"],
         file_sweep(scenario__duration_s=None, scenario__trajectory__centre_en_m=[500, 900]),
         "the trajectory leaves the map at t=", "N 0..1000 m"),
    case("initial-uncertainty-leaves-the-map", ["run", "{sweep}", "--out", "{tmp}/out"],
         file_sweep(scenario__filter__initial_area_m=2000),
         "the initial uncertainty", "leaves the navigation map", "filter.initial_area_m"),
    case("duration-longer-than-the-track", ["validate", "{sweep}"], file_sweep(scenario__duration_s=5000),
         "duration_s (5000 s) is longer than the trajectory"),
    # results and output directories, executors
    case("results-of-another-schema-run", ["run", "{sweep}", "--out", "{out}"], BASE,
         "cell_id=x/run-00000.parquet: written with results schema 999", "reads schema",
         setup=lambda tmp: incompatible_results(tmp, "cell_id=x")),
    case("results-of-another-schema-tables", ["tables", "{out}"], None,
         "run-00000.parquet: written with results schema 999",
         setup=lambda tmp: incompatible_results(tmp, "x")),
    case("tables-of-a-non-results-directory", ["tables", "{tmp}"], None, "no sweep.yaml"),
    case("tables-unknown-format", ["tables", "{tmp}", "--format", "xlsx"], None, "--format must be md or csv"),
    case("output-not-writable", ["run", "{sweep}", "--out", "{out}"], BASE, "is not writable",
         setup=unwritable_output),
    case("dask-scheduler-not-answering", ["run", "{sweep}", "--out", "{tmp}/out", "--scheduler", "tcp://127.0.0.1:1"],
         BASE, "cannot reach the Dask scheduler at tcp://127.0.0.1:1", max_s=30),
]


# ---- map readers (issue 16): depth-positive grids, NetCDF grids without coordinates ----------


def _seafloor_1km() -> np.ndarray:
    """A 1 km x 1 km seafloor at MAP_RES nodes, row 0 south, elevations -66..-54 m."""
    e = np.arange(0.0, 1000.0 + 1e-9, MAP_RES)
    ee, nn = np.meshgrid(e, e)
    return -60.0 + 5.0 * np.sin(ee / 50.0) * np.cos(nn / 70.0)


def depth_positive_geotiff(tmp):
    """An untagged GeoTIFF of depths (positive down), placed by the sweep's origin/resolution."""
    import tifffile

    tifffile.imwrite(tmp / "depths.tif", (-_seafloor_1km()).astype(np.float32))
    return {"depths": tmp / "depths.tif"}


def netcdf_without_coordinates(tmp):
    """A NetCDF grid with only its z variable: no x/y or lon/lat coordinate vectors."""
    from scipy.io import netcdf_file

    z = _seafloor_1km()
    with netcdf_file(tmp / "bare.nc", "w") as nc:
        nc.createDimension("rows", z.shape[0])
        nc.createDimension("cols", z.shape[1])
        nc.createVariable("z", "f8", ("rows", "cols"))[:] = z
    return {"bare_nc": tmp / "bare.nc"}


def no_georeferencing_arguments(data: dict) -> dict:
    for key in ("origin", "resolution"):
        data["scenario"]["terrain"].pop(key)
    return data


READER_CASES = [
    case("depth-positive-geotiff", ["validate", "{sweep}"], file_sweep("{depths}"),
         "bad.yaml: cell", "the map looks depth-positive",
         "(median elevation +58.1 m, range +57.9..+59.4 m)", "set terrain.positive: down",
         setup=depth_positive_geotiff),
    case("netcdf-without-coordinates-or-override", ["validate", "{sweep}"],
         no_georeferencing_arguments(file_sweep("{bare_nc}")),
         "bare.nc: the file has no usable georeferencing (no coordinate variables",
         "origin=(e0, n0) with resolution=", setup=netcdf_without_coordinates),
]
CASES += READER_CASES


@pytest.mark.parametrize("setup, changes", [
    (depth_positive_geotiff, {"scenario__terrain__positive": "down"}),
    (netcdf_without_coordinates, {}),
], ids=["depth-positive-negated", "netcdf-origin-resolution"])
def test_reader_inputs_accepted_as_documented(tmp_path, setup, changes):
    """The same maps with the documented option validate, and read as the seafloor they hold."""
    from tanbench.runner.sweep import load_sweep
    from tanbench.terrain import truth_map

    path = next(iter(setup(tmp_path).values()))
    data = file_sweep(str(path), **changes)
    (tmp_path / "ok.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    proc = cli("validate", tmp_path / "ok.yaml")
    assert proc.returncode == 0 and "ok (1 cell(s)" in proc.stdout, proc.stderr
    grid = truth_map(load_sweep(tmp_path / "ok.yaml").cells[0].scenario.terrain)
    np.testing.assert_allclose(grid.z, _seafloor_1km(), atol=1e-5)  # float32 in the GeoTIFF
    assert (grid.e0, grid.n0, grid.res_e, grid.res_n) == (0.0, 0.0, MAP_RES, MAP_RES)


# ---- end of the map-reader block ---------------------------------------------------------------


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    """A 1 km x 1 km .npy map (5 m nodes), the same with a hole under the survey, and broken files."""
    d = tmp_path_factory.mktemp("maps")
    e = np.arange(0.0, 1000.0 + 1e-9, MAP_RES)
    ee, nn = np.meshgrid(e, e)
    z = -60.0 + 5.0 * np.sin(ee / 50.0) * np.cos(nn / 70.0) + 3.0 * np.cos(ee / 23.0 + nn / 41.0)
    np.save(d / "map.npy", z)
    holes = z.copy()
    holes[(nn >= 480) & (nn <= 520) & (ee >= 430) & (ee <= 470)] = np.nan  # on the first leg (E = 450 m)
    np.save(d / "holes.npy", holes)
    (d / "garbage.tif").write_bytes(b"\x00 this is not a TIFF \xff" * 40)
    (d / "map.xyz").write_text("0 0 -60\n5 0 -61\n")
    (d / "a-directory.npy").mkdir()
    return d


def fill(text: str, values: dict) -> str:
    for key, value in values.items():
        text = text.replace("{" + key + "}", str(value))
    return text


def prepare(tmp_path, maps, args, data, setup):
    """Write the case's sweep file and run its setup; the CLI arguments with placeholders filled."""
    values = {"maps": maps, "tmp": tmp_path, "sweep": tmp_path / "bad.yaml"}
    if setup is not None:
        values.update(setup(tmp_path))
    if data is not None:
        text = data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False)
        (tmp_path / "bad.yaml").write_text(fill(text, values))
    return [fill(a, values) for a in args]


@pytest.mark.parametrize("args, data, fragments, setup, max_s", CASES)
def test_bad_input_gives_one_error_line(tmp_path, maps, args, data, fragments, setup, max_s):
    """The CLI prints one `error:` line naming the problem, exits 2, shows no traceback."""
    argv = prepare(tmp_path, maps, args, data, setup)
    started = time.monotonic()
    proc = cli(*argv, timeout=120)
    elapsed = time.monotonic() - started
    lines = error_lines(proc.stderr)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for fragment in fragments:
        assert fill(fragment, {"tmp": tmp_path}) in lines[0]
    assert "Traceback" not in proc.stderr + proc.stdout
    if max_s is not None:
        assert elapsed < max_s


def test_holes_are_accepted_when_filled(tmp_path, maps):
    """The map with a hole under the track validates and runs with terrain.fill_holes: true."""
    data = file_sweep("{maps}/holes.npy", runs=1, scenario__duration_s=None, scenario__terrain__fill_holes=True)
    argv = prepare(tmp_path, maps, ["validate", "{sweep}"], data, None)
    proc = cli(*argv)
    assert proc.returncode == 0 and "ok (1 cell(s)" in proc.stdout, proc.stderr
    proc = cli("run", argv[1], "--out", tmp_path / "out", "--workers", 1, "-q")
    assert proc.returncode == 0, proc.stderr
    runs = pd.read_parquet(tmp_path / "out" / "runs")
    assert (runs["status"] == "ok").all() and runs["terrain.fill_holes"].all()


def test_debug_shows_the_traceback(tmp_path, maps):
    """With --debug the same bad input raises with its traceback (exit 1 from Python)."""
    argv = prepare(tmp_path, maps, ["validate", "{sweep}"], sweep(runs=0), None)
    proc = cli("--debug", *argv)
    assert proc.returncode != 0
    assert "Traceback (most recent call last)" in proc.stderr
    assert "TanbenchError: " in proc.stderr and "runs: Input should be greater than 0" in proc.stderr


def test_usage_errors_are_one_line_too(tmp_path, maps):
    """A bad command-line option (`--workers 0`) is one `error:` line with exit 2, like bad input."""
    argv = prepare(tmp_path, maps, ["run", "{sweep}"], BASE, None)
    proc = cli(*argv, "--workers", 0)
    lines = error_lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "--workers" in lines[0]
    assert not os.path.exists(tmp_path / "results")
