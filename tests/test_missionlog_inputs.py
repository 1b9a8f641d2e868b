"""Recorded missions: a lon/lat log on a geographic map (the existing georeferencing), and bad
logs, maps and settings refused with one clear line and nothing written."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pandas as pd
import pytest
import yaml

from sweep_support import cli, error_lines
from tanbench.config import Scenario
from tanbench.earth import radii_of_curvature
from tanbench.errors import TanbenchError
from tanbench.missions.logfile import MissionLog, read_log, write_log
from tanbench.missions.replay import replay
from tanbench.missions.simulated import simulated_log, write_map
from tanbench.simulation import simulate_vehicle
from tanbench.terrain import navigation_map
from tanbench.terrain.georef import local_to_lonlat, lonlat_to_local

LON0, LAT0 = -121.9, 36.8  # where the geographic copy of the map is put


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A short simulated log of area A in the map's metres, and its navigation map."""
    d = tmp_path_factory.mktemp("inputs")
    sc = Scenario(area="A", duration_s=40, particles=300)
    log = simulated_log(sc, simulate_vehicle(sc, np.random.SeedSequence(4)), 4)
    write_log(d / "log", log)
    nmap = navigation_map(sc.terrain, sc.map_resolution_m)
    write_map(nmap, d / "map.npz")
    (d / "settings.yaml").write_text(yaml.safe_dump({"particles": 300}))
    return d, log, nmap


def geographic_map(nmap, path):
    """``nmap``'s nodes as a lon/lat grid (south-west node at LON0, LAT0) whose projected spacing is
    ``nmap``'s: the latitude step fixes the centre latitude, which fixes the metres per degree."""
    ny, nx = nmap.z.shape
    lat_c = LAT0
    for _ in range(6):
        r_n, r_e = radii_of_curvature(math.radians(lat_c))
        k_n, k_e = r_n * math.pi / 180, r_e * math.cos(math.radians(lat_c)) * math.pi / 180
        lat_c = LAT0 + 0.5 * (ny - 1) * nmap.res_n / k_n
    np.savez(path, z=nmap.z, e0=LON0, n0=LAT0, res_e=nmap.res_e / k_e, res_n=nmap.res_n / k_n)
    return path


def lonlat_log(log: MissionLog, nmap, geo) -> MissionLog:
    """``log`` with its positions as lon/lat in ``geo``'s frame (the same points on the seafloor)."""
    tables = dict(log.tables)
    for name in ("navigation", "reference"):
        df = tables[name].copy()
        lon, lat = local_to_lonlat(geo, df.pop("east_m") - nmap.e0, df.pop("north_m") - nmap.n0)
        df.insert(1, "lon_deg", lon)
        df.insert(2, "lat_deg", lat)
        tables[name] = df
    return MissionLog(meta=log.meta, tables=tables)


def test_a_lonlat_log_on_a_geographic_map_gives_the_metric_log_s_results(base, tmp_path):
    """The georeferencing carries a lon/lat log onto a lon/lat map: the same estimates as the metric
    log on the metric map (to a micrometre after the shift of origin), lon/lat in the estimates."""
    from tanbench.terrain.files import read_grid

    d, log, nmap = base
    geo_path = geographic_map(nmap, tmp_path / "geo.npz")
    (tmp_path / "geo.yaml").write_text(yaml.safe_dump({"particles": 300, "map": {"crs": "epsg4326"}}))
    from tanbench.terrain.georef import to_local

    geo = to_local(read_grid(geo_path, crs="epsg4326"))
    assert geo.meta["crs"] == "local" and abs(geo.res_e - nmap.res_e) < 1e-9 and abs(geo.res_n - nmap.res_n) < 1e-9
    write_log(tmp_path / "lonlat", lonlat_log(log, nmap, geo))
    assert "lon_deg" in pd.read_parquet(tmp_path / "lonlat" / "navigation.parquet").columns
    methods = ["tight-dvl,loose-dvl"]
    metric = replay(d / "log", str(d / "map.npz"), methods, d / "settings.yaml", out=tmp_path / "metric")
    lonlat = replay(tmp_path / "lonlat", str(geo_path), methods, tmp_path / "geo.yaml", out=tmp_path / "geo")
    a = pd.read_parquet(tmp_path / "metric" / "estimates.parquet")
    b = pd.read_parquet(tmp_path / "geo" / "estimates.parquet")
    assert {"lon_deg", "lat_deg", "nav_lon_deg"} <= set(b.columns) and "lon_deg" not in a.columns
    np.testing.assert_allclose(b["east_m"] + nmap.e0, a["east_m"], rtol=0, atol=1e-6)
    np.testing.assert_allclose(b["north_m"] + nmap.n0, a["north_m"], rtol=0, atol=1e-6)
    e, n = lonlat_to_local(geo, b["lon_deg"], b["lat_deg"])
    np.testing.assert_allclose(e, b["east_m"], rtol=0, atol=1e-6)
    for x, y in zip(metric.rows, lonlat.rows):
        assert x["status"] == y["status"] == "ok"
        assert abs(x["final_horizontal_error_m"] - y["final_horizontal_error_m"]) < 1e-6


def _edit_table(name, edit):
    def setup(log_dir):
        path = log_dir / f"{name}.parquet"
        edit(pd.read_parquet(path)).to_parquet(path)
    return setup


def _edit_meta(edit):
    def setup(log_dir):
        path = log_dir / "mission.yaml"
        path.write_text(yaml.safe_dump(edit(yaml.safe_load(path.read_text())), sort_keys=False))
    return setup


def _remove(name):
    return lambda log_dir: (log_dir / name).unlink()


def _both(*setups):
    def setup(log_dir):
        for one in setups:
            one(log_dir)
    return setup


def _set(d, dotted, value):
    *parts, last = dotted.split(".")
    for p in parts:
        d = d.setdefault(p, {})
    d[last] = value
    return d


def _with(dotted, value):
    return lambda data: (_set(data, dotted, value), data)[1]


LOG_CASES = [
    ("no mission.yaml", _remove("mission.yaml"), {}, "not a mission log (no mission.yaml"),
    ("no imu table", _remove("imu.parquet"), {}, "no imu table (imu.parquet or imu.csv"),
    ("a column without its unit", _edit_table("navigation", lambda df: df.rename(columns={"east_m": "east"})), {},
     "navigation.parquet: no column 'east_m'"),
    ("an unknown column", _edit_table("dvl", lambda df: df.assign(quality=1.0)), {}, "unknown column 'quality'"),
    ("a quantity in two units", _edit_table("navigation", lambda df: df.assign(pitch_deg=0.0)), {},
     "pitch is given twice (pitch_rad, pitch_deg)"),
    ("text where numbers belong", _edit_table("depth", lambda df: df.assign(depth_m="deep")), {},
     "column 'depth_m' is not numeric"),
    ("times going back", _edit_table("dvl", lambda df: df.iloc[::-1]), {}, "t_s must be finite and strictly increasing"),
    ("an irregular IMU", _edit_table("imu", lambda df: df.drop(index=500)), {}, "imu samples 499 and 500 are 0.02 s apart"),
    ("an IMU rate that is not the table's", _edit_meta(_with("sensors.imu_rate_hz", 100.5)), {},
     "the imu samples come every 0.01 s on average, not every 1 / sensors.imu_rate_hz = 0.00995025 s"),
    ("a reference in another coordinate system",
     _edit_table("reference", lambda df: df.rename(columns={"east_m": "lon_deg", "north_m": "lat_deg"})), {},
     "the reference track's positions are in lon/lat but the navigation solution's are not"),
    ("another format version", _edit_meta(_with("format_version", 2)), {}, "reads mission-log version 1, not 2"),
    ("an unknown metadata key", _edit_meta(_with("sensors.sonar_rate", 1.0)), {}, "sensors.sonar_rate: unknown key"),
    ("beams that do not match the table", _edit_meta(_with("sensors.beam_azimuths_deg", [0.0, 120.0, 240.0])), {},
     "dvl has 4 beam range columns but mission.yaml describes 3 dvl beams"),
    ("the DVL geometry twice", _edit_meta(_with("beams", {"dvl": {"tilt_deg": 25.0, "azimuths_deg": [0, 90, 180, 270]}})),
     {}, "the DVL beams are given twice"),
    ("a wrong sonar rate", _edit_meta(_with("sensors.sonar_rate_hz", 2.0)), {},
     "dvl pings come every 1 s (median), but sensors.sonar_rate_hz = 2"),
    ("a reference that ends early", _edit_table("reference", lambda df: df.iloc[: len(df) // 2]), {},
     "the reference table covers t = 0..19.99 s, but it must cover 0..40 s"),
    ("a log off the map", _edit_table("navigation", lambda df: df.assign(east_m=df["east_m"] + 1e5)), {},
     "the initial uncertainty (filter.initial_area_m / 2 = 75 m around it) leaves the map"),
    ("a lon/lat log on a map in metres",
     _both(_remove("reference.parquet"),
           _edit_table("navigation", lambda df: df.rename(columns={"east_m": "lon_deg", "north_m": "lat_deg"}))), {},
     "positions are lon/lat but the map"),
    ("a negative range", _edit_table("dvl", lambda df: df.assign(range_1_m=-5.0)), {},
     "dvl.parquet: range_1_m is -5 m at row 0; a range is the slant distance along the beam, positive"),
    ("a zero range",
     _edit_table("altimeter", lambda df: df.assign(range_1_m=df["range_1_m"].where(df.index != 3, 0.0))), {},
     "altimeter.parquet: range_1_m is 0 m at row 3"),
    ("an infinite range",
     _edit_table("dvl", lambda df: df.assign(range_2_m=df["range_2_m"].where(df.index != 7, np.inf))), {},
     "dvl.parquet: range_2_m is inf m at row 7"),
    ("a negative reference range",
     _edit_table("reference_ranges", lambda df: df.assign(dvl_range_4_m=-df["dvl_range_4_m"])), {},
     "reference_ranges.parquet: dvl_range_4_m is -"),
    ("an unknown method", None, {"methods": ["tight-dvl,kalman-magic"]}, "unknown method 'kalman-magic'"),
    ("no map", None, {"map_path": None}, "no map: give --map FILE"),
    ("a missing map file", None, {"map_path": "nowhere.npz"}, "nowhere.npz"),
]


@pytest.mark.parametrize("setup, changes, message", [c[1:] for c in LOG_CASES], ids=[c[0] for c in LOG_CASES])
def test_a_bad_log_map_or_method_is_one_clear_error_and_nothing_is_written(base, tmp_path, setup, changes, message):
    d, _, _ = base
    log_dir = tmp_path / "log"
    shutil.copytree(d / "log", log_dir)
    if setup is not None:
        setup(log_dir)
    args = {"map_path": str(d / "map.npz"), "methods": ["tight-dvl"], "settings_path": d / "settings.yaml", **changes}
    with pytest.raises(TanbenchError) as err:
        replay(log_dir, out=tmp_path / "out", **args)
    assert message in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "out").exists()


def test_the_cli_refuses_with_one_line_and_exit_2(base, tmp_path):
    d, _, _ = base
    (tmp_path / "bad.yaml").write_text("particles: 300\nfilter: {resampling: sometimes}\n")
    (tmp_path / "sweep-results").mkdir()
    (tmp_path / "sweep-results" / "sweep.yaml").write_text("name: x\n")
    (tmp_path / "replay-results").mkdir()
    (tmp_path / "replay-results" / "replay.yaml").write_text("log: x\n")
    cases = [
        (["run", "configs/quick.yaml", "--runs", "1", "--out", tmp_path / "replay-results"],
         "holds a replay's results"),
        (["replay", d / "log", "--map", d / "map.npz", "--settings", tmp_path / "bad.yaml", "--out", tmp_path / "o"],
         "filter.resampling: Input should be"),
        (["replay", d / "log", "--map", d / "map.npz", "--out", tmp_path / "sweep-results"], "holds a sweep's results"),
        (["simulate", "--area", "A", "--duration", "20", "--log", tmp_path / "o", "--lonlat"],
         "--lonlat needs a map georeferenced in lon/lat or Web Mercator"),
        (["simulate", "--area", "A", "--sweep", "configs/quick.yaml", "--log", tmp_path / "o"],
         "give --area or --sweep, not both"),
        (["simulate", "--area", "A", "--duration", "20", "--log", tmp_path / "bad.yaml"],
         "exists and is not a directory"),
    ]
    for args, message in cases:
        proc = cli(*args)
        lines = error_lines(proc.stderr)
        assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), (args, proc.stderr)
        assert message in lines[0], (message, lines[0])
        assert "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists() and not (tmp_path / "sweep-results" / "runs.parquet").exists()
    assert sorted(p.name for p in (tmp_path / "replay-results").iterdir()) == ["replay.yaml"]


def test_replay_help_is_plain_and_points_to_the_format():
    proc = cli("replay", "--help")
    assert proc.returncode == 0 and "docs/missions.md" in proc.stdout and "<bool>" not in proc.stdout


def test_a_lonlat_log_s_settings_say_to_replay_it_on_its_georeferenced_map():
    """``simulate --log --lonlat``: map.npz is in metres with no geographic reference, so settings.yaml's first line
    names the map the run was simulated on for the replay; a map-frame log's names map.npz."""
    from tanbench.config import Scenario
    from tanbench.missions.simulated import settings_text

    sc = Scenario(terrain={"kind": "file", "path": "../shared/data/monterey/MontereyBay.R_*.tif"}, area="custom",
                  trajectory={"kind": "survey", "centre_en_m": [900.0, 1100.0]})
    first = settings_text(sc, lonlat=True).splitlines()[0]
    assert "lon/lat" in first and "--map '../shared/data/monterey/MontereyBay.R_*.tif'" in first
    assert "not the simulated run's" in first
    assert "--map LOG/map.npz" in settings_text(sc).splitlines()[0]
    assert yaml.safe_load(settings_text(sc, lonlat=True)) == yaml.safe_load(settings_text(sc))


def test_simulate_refuses_a_log_path_that_is_a_file_before_simulating(tmp_path, monkeypatch):
    """``simulate --log FILE``: refused before the run is simulated (the simulation is made to fail here, so the
    refusal must come first)."""
    from typer.testing import CliRunner

    import tanbench.simulation
    from tanbench.cli import app

    def never(*_args, **_kwargs):
        raise AssertionError("simulated before the log directory was checked")

    monkeypatch.setattr(tanbench.simulation, "simulate_vehicle", never)
    (tmp_path / "a-file").write_text("keep me")
    result = CliRunner().invoke(app, ["simulate", "--area", "A", "--duration", "20", "--log", str(tmp_path / "a-file")])
    assert result.exit_code != 0 and "exists and is not a directory" in str(result.output) + str(result.exception)
    assert (tmp_path / "a-file").read_text() == "keep me"


def holed(nmap, path, nodes):
    """``nmap`` as an .npz with NaN at ``nodes`` (a tuple of index arrays or slices)."""
    z = nmap.z.copy()
    z[nodes] = np.nan
    np.savez(path, z=z, e0=nmap.e0, n0=nmap.n0, res_e=nmap.res_e, res_n=nmap.res_n)
    return path


def node_near(nmap, e, n):
    """The (row, column) of the node nearest (e, n)."""
    return int(round((n - nmap.n0) / nmap.res_n)), int(round((e - nmap.e0) / nmap.res_e))


def test_a_hole_under_the_navigation_solution_or_within_the_initial_uncertainty_is_refused(base, tmp_path):
    """The sweep's check of its true track (no data under it: refused, terrain.fill_holes fills), for a recorded
    mission: the navigation solution with filter.initial_area_m / 2 (75 m) around it, at every sample. Refused: a
    hole under the track, a map with three finite nodes, one missing node 50 m beside the start; replayed: a hole
    300 m away, and the holed map with map.fill_holes: true."""
    d, log, nmap = base
    nav = log.tables["navigation"]
    e, n = nav["east_m"].to_numpy(), nav["north_m"].to_numpy()
    i0, j0 = node_near(nmap, e[0] + 50.0, n[0])
    few = np.ones(nmap.z.shape, dtype=bool)
    few[0, 0] = few[0, 1] = few[1, 0] = False
    refused = {
        "under": (holed(nmap, tmp_path / "under.npz", (slice(20, 60), slice(90, 150))), "(E, N) = (1152, 374) m "
                  "(the nearest node without data: (E, N) = (1154, 374) m, 2 m away)"),
        "three-nodes": (holed(nmap, tmp_path / "few.npz", few), "the map has no data (a hole)"),
        "beside": (holed(nmap, tmp_path / "beside.npz", ([i0], [j0])), "at t=0 s, (E, N) = (1152, 374) m (the nearest "
                   "node without data: (E, N) = (1204, 374) m, 52 m away)"),
    }
    for name, (path, where) in refused.items():
        with pytest.raises(TanbenchError) as err:
            replay(d / "log", str(path), ["tight-dvl"], d / "settings.yaml", out=tmp_path / f"out-{name}")
        text = str(err.value)
        assert text.startswith(f"{d / 'log'}: the map has no data (a hole) under the navigation solution or within "
                               f"filter.initial_area_m / 2 = 75 m of it at t="), (name, text)
        assert where in text and text.endswith("; set map.fill_holes: true in the --settings file to fill holes")
        assert "\n" not in text and not (tmp_path / f"out-{name}").exists()
    i1, j1 = node_near(nmap, e.max() + 300.0, n.min())
    far = replay(d / "log", str(holed(nmap, tmp_path / "far.npz", ([i1], [j1]))), ["tight-dvl"], d / "settings.yaml",
                 out=tmp_path / "out-far")
    (tmp_path / "fill.yaml").write_text(yaml.safe_dump({"particles": 300, "map": {"fill_holes": True}}))
    filled = replay(d / "log", str(refused["under"][0]), ["tight-dvl"], tmp_path / "fill.yaml",
                    out=tmp_path / "out-filled")
    assert far.rows[0]["status"] == filled.rows[0]["status"] == "ok"


def test_the_hole_check_reads_the_navigation_solution_not_the_reference(base, tmp_path):
    """A hole under the reference track (moved 400 m east, far from the navigation solution) is not refused: the
    reference is the scoring's, never what the vehicle believed (docs/missions.md, section 5, "Holes in the map")."""
    d, log, nmap = base
    log_dir = tmp_path / "log"
    shutil.copytree(d / "log", log_dir)
    _edit_table("reference", lambda df: df.assign(east_m=df["east_m"] + 400.0))(log_dir)
    ref = pd.read_parquet(log_dir / "reference.parquet")
    rows, cols = zip(*(node_near(nmap, e, n) for e, n in zip(ref["east_m"], ref["north_m"])))
    path = holed(nmap, tmp_path / "ref-hole.npz", (np.array(rows), np.array(cols)))
    report = replay(log_dir, str(path), ["tight-dvl"], d / "settings.yaml", out=tmp_path / "out")
    assert report.rows[0]["status"] == "ok"


def test_the_hole_check_is_the_sweep_s_without_a_margin():
    """One piece of code: without a margin the check is the bilinear look-up's NaN itself, on node lines too
    (over_holes' boxes once divided by the spacing where the look-up multiplies by its inverse, so on a node line
    the two could pick neighbouring cells; found by the review); with a margin over_holes says which points
    find_holes would find a hole around."""
    from tanbench.simulation import check_no_holes
    from tanbench.terrain.grid import Map
    from tanbench.terrain.mosaic import find_holes, over_holes

    rng = np.random.default_rng(2)
    z = rng.normal(-50.0, 3.0, (30, 40))
    z[5, 7] = z[12:14, 20:23] = np.nan
    m = Map(z, 100.0, 200.0, 5.0, 4.0, name="holed")
    e, n = rng.uniform(90.0, 310.0, 600), rng.uniform(190.0, 330.0, 600)
    inside = m.contains(e, n)
    np.testing.assert_array_equal(over_holes(m, e, n)[inside], np.isnan(m.elevation(e, n))[inside])
    for margin in (0.0, 3.0, 12.5):
        assert list(over_holes(m, e, n, margin)) == [bool(find_holes(m, a, b, margin)) for a, b in zip(e, n)]
    # points on node lines (e0 and the spacings chosen so that fx, fy round): the check refuses exactly where the
    # look-up reads NaN
    odd = Map(z, -13.0, -7.0, 3.3, 2.7, name="odd")
    jj, ii = np.meshgrid(np.arange(40), np.arange(30))
    e_line, n_line = (-13.0 + 3.3 * jj).ravel(), (-7.0 + 2.7 * ii).ravel()
    lookup = np.isnan(odd.elevation(e_line, n_line)) & odd.contains(e_line, n_line)
    assert lookup.any() and not lookup.all()
    for k in range(e_line.size):
        refused = False
        try:
            check_no_holes(odd, np.zeros(1), e_line[k:k + 1], n_line[k:k + 1], "terrain.fill_holes: true")
        except TanbenchError:
            refused = True
        assert refused == lookup[k], (e_line[k], n_line[k])


def test_replay_refuses_a_sampling_time_longer_than_the_log(base, tmp_path):
    """The sweep's check of sampling_time_s against its run's length, on the span of the log's DVL pings (40 s)."""
    d, _, _ = base
    (tmp_path / "long.yaml").write_text(yaml.safe_dump({"particles": 300, "sampling_time_s": 1000}))
    with pytest.raises(TanbenchError) as err:
        replay(d / "log", str(d / "map.npz"), ["tight-dvl"], tmp_path / "long.yaml", out=tmp_path / "out")
    assert str(err.value) == (f"{tmp_path / 'long.yaml'}: sampling_time_s (1000 s) is longer than the span of the "
                              f"log's DVL pings (40 s): the filter would not update after the start")
    assert not (tmp_path / "out").exists()
    (tmp_path / "whole.yaml").write_text(yaml.safe_dump({"particles": 300, "sampling_time_s": 40}))
    report = replay(d / "log", str(d / "map.npz"), ["tight-dvl"], tmp_path / "whole.yaml", out=tmp_path / "whole")
    assert report.rows[0]["status"] == "ok"


def test_a_csv_row_with_fewer_or_more_fields_than_the_header_is_refused(base, tmp_path):
    """A CSV table cut short (its last row's last field gone, its last number cut) or with a field too many is
    refused naming the file, the row and the line: pandas would read NaN for the missing field or shift the row."""
    d, log, _ = base
    write_log(tmp_path / "csv", log, "csv")
    read_log(tmp_path / "csv")  # intact, it reads
    cases = {
        "cut": lambda text: text[:-30],
        "extra": lambda text: text.replace("\n", ",1.5\n", 6).replace(",1.5\n", "\n", 5),
        "every-row-extra": lambda text: "\n".join(line + ",0" if k else line
                                                  for k, line in enumerate(text.splitlines())) + "\n",
    }
    messages = {"cut": "row 40 (line 42) has 7 fields but the header has 8: a truncated or damaged table?",
                "extra": "row 4 (line 6) has 9 fields but the header has 8: a truncated or damaged table?",
                "every-row-extra": "row 0 (line 2) has 9 fields but the header has 8: a truncated or damaged table?"}
    for name, edit in cases.items():
        log_dir = tmp_path / name
        shutil.copytree(tmp_path / "csv", log_dir)
        (log_dir / "dvl.csv").write_text(edit((log_dir / "dvl.csv").read_text()))
        with pytest.raises(TanbenchError) as err:
            replay(log_dir, str(d / "map.npz"), ["tight-dvl"], d / "settings.yaml", out=tmp_path / f"out-{name}")
        assert str(err.value) == f"{log_dir / 'dvl.csv'}: {messages[name]}", name
        assert not (tmp_path / f"out-{name}").exists()


def test_write_log_refuses_ranges_that_reading_would_refuse(base, tmp_path):
    """What write_log writes, read_log reads: a non-positive range is refused before any file is written."""
    _, log, _ = base
    tables = dict(log.tables)
    tables["dvl"] = tables["dvl"].assign(range_2_m=tables["dvl"]["range_2_m"].where(tables["dvl"].index != 5, -0.3))
    with pytest.raises(TanbenchError) as err:
        write_log(tmp_path / "log", MissionLog(meta=log.meta, tables=tables))
    assert str(err.value) == (f"cannot write the mission log {tmp_path / 'log'}: its dvl table: range_2_m is -0.3 m "
                              f"at row 5; a range is the slant distance along the beam, positive (NaN, an empty CSV "
                              f"field, for no bottom)")
    assert not (tmp_path / "log").exists()


def fingerprint(directory):
    """Every file of a directory with its bytes and modification time."""
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(directory.iterdir())}


def test_simulate_log_never_overwrites_a_log_without_force_nor_a_recorded_one(base, tmp_path, monkeypatch):
    """An existing simulated log: refused without --force (before simulating), overwritten with it; a recorded log
    (mission.yaml's source is not a simulation): refused with or without --force; nothing changed by a refusal."""
    from typer.testing import CliRunner

    import tanbench.simulation
    from tanbench.cli import app

    d, _, _ = base
    simulated, recorded = tmp_path / "simulated", tmp_path / "recorded"
    shutil.copytree(d / "log", simulated)
    shutil.copytree(d / "log", recorded)
    _edit_meta(_with("source", {"vehicle": "Sirius", "dive": 12}))(recorded)
    before = {p: fingerprint(p) for p in (simulated, recorded)}
    real = tanbench.simulation.simulate_vehicle

    def never(*_args, **_kwargs):
        raise AssertionError("simulated before the log directory was checked")

    monkeypatch.setattr(tanbench.simulation, "simulate_vehicle", never)
    cases = [
        (simulated, [], f"{simulated}: holds a mission log already; give --force to overwrite it, or use a new "
                        f"directory"),
        (recorded, [], f"{recorded}: holds a recorded mission log (mission.yaml does not say source.kind: simulation), "
                       f"which tanbench never overwrites; use a new directory"),
        (recorded, ["--force"], "which tanbench never overwrites"),
    ]
    for directory, extra, message in cases:
        result = CliRunner().invoke(app, ["simulate", "--area", "A", "--duration", "20", "--log", str(directory),
                                          *extra])
        assert result.exit_code != 0 and isinstance(result.exception, TanbenchError), result.output
        assert message in str(result.exception) and "\n" not in str(result.exception)
    assert {p: fingerprint(p) for p in (simulated, recorded)} == before
    monkeypatch.setattr(tanbench.simulation, "simulate_vehicle", real)
    result = CliRunner().invoke(app, ["simulate", "--area", "A", "--duration", "20", "--seed", "9", "--log",
                                      str(simulated), "--force"])
    assert result.exit_code == 0, result.output
    assert read_log(simulated).meta.source["seed"] == 9 and (simulated / "map.npz").is_file()
    assert fingerprint(recorded) == before[recorded]


def test_the_new_refusals_are_one_line_exit_2_and_write_nothing(base, tmp_path):
    """The CLI: a hole under the track, a sampling time longer than the log, a truncated CSV table, a negative range,
    and simulate --log over an existing log: one error line, exit 2, no results directory, the log untouched."""
    d, log, nmap = base
    holes = holed(nmap, tmp_path / "loghole.npz", (slice(20, 60), slice(90, 150)))
    (tmp_path / "long.yaml").write_text(yaml.safe_dump({"particles": 300, "sampling_time_s": 1000}))
    write_log(tmp_path / "csv", log, "csv")
    shutil.copytree(tmp_path / "csv", tmp_path / "cut")
    (tmp_path / "cut" / "dvl.csv").write_text((tmp_path / "cut" / "dvl.csv").read_text()[:-30])
    shutil.copytree(tmp_path / "csv", tmp_path / "negative")
    dvl = pd.read_csv(tmp_path / "negative" / "dvl.csv")
    dvl.assign(range_1_m=-5.0).to_csv(tmp_path / "negative" / "dvl.csv", index=False)
    before = fingerprint(d / "log")
    out = ["--out", tmp_path / "o"]
    cases = [
        (["replay", d / "log", "--map", holes, "--methods", "tight-dvl", "--settings", d / "settings.yaml", *out],
         "the map has no data (a hole) under the navigation solution"),
        (["replay", d / "log", "--map", d / "map.npz", "--methods", "tight-dvl", "--settings", tmp_path / "long.yaml",
          *out], "sampling_time_s (1000 s) is longer than the span of the log's DVL pings (40 s)"),
        (["replay", tmp_path / "cut", "--map", d / "map.npz", "--methods", "tight-dvl", *out],
         "dvl.csv: row 40 (line 42) has 7 fields but the header has 8"),
        (["replay", tmp_path / "negative", "--map", d / "map.npz", "--methods", "tight-dvl", *out],
         "dvl.csv: range_1_m is -5 m at row 0"),
        (["replay", tmp_path / "negative", "--map", d / "map.npz", "--methods", "tight-dvl"],  # default --out
         "dvl.csv: range_1_m is -5 m at row 0"),
        (["simulate", "--area", "A", "--duration", "20", "--log", d / "log"],
         "holds a mission log already; give --force"),
    ]
    for args, message in cases:
        proc = cli(*args, cwd=tmp_path)
        lines = error_lines(proc.stderr)
        assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), (args, proc.stderr)
        assert message in lines[0], (message, lines[0])
    assert not (tmp_path / "o").exists() and not (tmp_path / "results").exists()
    assert fingerprint(d / "log") == before
