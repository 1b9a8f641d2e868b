"""Recorded missions (issue 28): `tanbench simulate --log` -> mission log -> `tanbench replay` is the
in-process run, bit for bit, for every built-in method (the multibeam ones included: the run has a
16-beam multibeam pinging at every second DVL ping); the log's variants (CSV, an frd body
frame, degrees, a multibeam block of any width) read back to the same observations; without a
reference track a replay writes the same estimates and no scores."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
import yaml

from sweep_support import cli
from tanbench.config import Scenario
from tanbench.errors import TanbenchError
from tanbench.methods import run_method
from tanbench.methods.registry import builtin_names
from tanbench.missions.logfile import read_log, write_log
from tanbench.missions.observe import observations
from tanbench.missions.replay import method_seed, replay
from tanbench.missions.simulated import simulated_log
from tanbench.missions.spec import BeamGeometry
from tanbench.schema import METRIC_COLUMNS
from tanbench.simulation import simulate_vehicle
from tanbench.terrain import navigation_map

SEED, DURATION, PARTICLES, REPLAY_SEED = 3, 60, 200, 11
METHODS = builtin_names()
OBS_ARRAYS = ("t", "gyro", "accel", "dvl_velocity", "depth", "ping_idx", "dvl_beams", "sbe_beams", "dvl_ranges",
              "sbe_ranges", "mbe_beams", "mbe_ranges")
MULTIBEAM = {"multibeam_beams": 16, "multibeam_swath_deg": 120.0, "multibeam_rate_hz": 0.5}
SWEEP = f"""name: roundtrip
seed: 1
runs: 1
methods: [tight-dvl]
scenario:
  area: A
  duration_s: {DURATION}
  particles: {PARTICLES}
  sensors: {MULTIBEAM}
"""


def same_bits(a, b) -> bool:
    """Equal to the last bit (NaN where the other is NaN)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    nan = np.isnan(a)
    return a.shape == b.shape and np.array_equal(nan, np.isnan(b)) and a[~nan].tobytes() == b[~nan].tobytes()


def assert_same_observations(obs, expected) -> None:
    for name in OBS_ARRAYS:
        assert same_bits(getattr(obs, name), getattr(expected, name)), name
    assert obs.dt == expected.dt and obs.latitude_rad == expected.latitude_rad
    for name in ("pos", "pitch", "roll", "yaw"):
        assert same_bits(getattr(obs.nav, name), getattr(expected.nav, name)), f"nav.{name}"


@pytest.fixture(scope="module")
def scenario():
    return Scenario(area="A", duration_s=DURATION, particles=PARTICLES, sensors=MULTIBEAM)


@pytest.fixture(scope="module")
def vehicle(scenario):
    """The run `tanbench simulate --sweep SWEEP --seed SEED` simulates (area A with a multibeam)."""
    return simulate_vehicle(scenario, np.random.SeedSequence(SEED))


@pytest.fixture(scope="module")
def mission(tmp_path_factory):
    """The CLI's mission log of that run, and replay settings with the test's particle count."""
    base = tmp_path_factory.mktemp("mission")
    (base / "sweep.yaml").write_text(SWEEP)
    proc = cli("simulate", "--sweep", base / "sweep.yaml", "--seed", SEED, "--log", base / "log", cwd=base)
    assert proc.returncode == 0, proc.stderr
    settings = yaml.safe_load((base / "log" / "settings.yaml").read_text())
    settings["particles"] = PARTICLES
    (base / "settings.yaml").write_text(yaml.safe_dump(settings))
    return base


def test_a_simulated_log_reads_back_to_the_observations_the_methods_were_given(mission, scenario, vehicle):
    log = read_log(mission / "log")
    nmap = navigation_map(scenario.terrain, scenario.map_resolution_m)
    assert_same_observations(observations(log, nmap), vehicle.obs)


def test_replay_of_a_simulated_log_is_the_in_process_run_for_every_builtin_method(mission, scenario, vehicle):
    """Every metric and every per-update series of every built-in method, bit for bit."""
    assert {"tight-dvl", "tight-sbe", "loose-dvl", "pmf-dvl", "mpf-dvl", "ekf-dvl", "tercom-dvl", "tight-mbe",
            "pmf-mbe"} <= set(METHODS)
    out = mission / "replayed"
    proc = cli("replay", mission / "log", "--map", mission / "log" / "map.npz", "--settings", mission / "settings.yaml",
               "--methods", ",".join(METHODS), "--seed", REPLAY_SEED, "--out", out, cwd=mission, timeout=1200)
    assert proc.returncode == 0, proc.stderr
    runs = pd.read_parquet(out / "runs.parquet").set_index("method")
    series = pd.read_parquet(out / "series.parquet")
    estimates = pd.read_parquet(out / "estimates.parquet")
    assert list(runs.index) == list(METHODS)
    for method in METHODS:
        expected = run_method(scenario, method, vehicle, method_seed(REPLAY_SEED, method))
        assert runs.loc[method, "status"] == "ok", runs.loc[method, "error"]
        for metric in METRIC_COLUMNS:
            if metric != "filter_wall_s":  # a wall-clock time
                assert same_bits(runs.loc[method, metric], expected.metrics[metric]), (method, metric)
        mine = series[series["method"] == method]
        others = set(mine.columns) - {"method"} - set(expected.series)  # other methods' own series
        assert set(expected.series) <= set(mine.columns) and mine[sorted(others)].isna().all().all(), method
        for name, values in expected.series.items():
            assert same_bits(mine[name].to_numpy(), values), (method, name)
        est = estimates[estimates["method"] == method]
        assert same_bits(est["east_m"], expected.series["est_e"]) and same_bits(est["north_m"], expected.series["est_n"])
    # the stored runs are a sweep's run rows: settings as flat columns, provenance in the metadata
    assert runs.loc["tight-dvl", "particles"] == PARTICLES and runs.loc["tight-dvl", "terrain.kind"] == "file"
    from tanbench import store

    meta = store.read_meta(out / "runs.parquet")
    assert meta["kind"] == "replay" and meta["log_source"]["seed"] == SEED and len(meta["log_sha256"]) == 64


def test_without_a_reference_track_the_estimates_are_the_same_and_nothing_is_scored(mission):
    """The methods never see the reference: taking it away changes no estimate; runs carry no metrics."""
    log = mission / "no-reference"
    shutil.copytree(mission / "log", log)
    for path in log.glob("reference*.parquet"):
        path.unlink()
    args = dict(map_path=str(mission / "log" / "map.npz"), methods=["tight-dvl,loose-dvl"],
                settings_path=mission / "settings.yaml", seed=REPLAY_SEED)
    scored = replay(mission / "log", out=mission / "scored", **args)
    unscored = replay(log, out=mission / "unscored", **args)
    assert scored.has_reference and not unscored.has_reference
    pd.testing.assert_frame_equal(pd.read_parquet(mission / "scored" / "estimates.parquet"),
                                  pd.read_parquet(mission / "unscored" / "estimates.parquet"), check_exact=True)
    runs = pd.read_parquet(mission / "unscored" / "runs.parquet")
    assert "final_horizontal_error_m" not in runs.columns and (runs["status"] == "ok").all()
    assert not (mission / "unscored" / "series.parquet").exists()


def test_csv_tables_an_frd_body_frame_and_degrees_read_back_to_the_same_observations(tmp_path, scenario, vehicle):
    nmap = navigation_map(scenario.terrain, scenario.map_resolution_m)
    log = simulated_log(scenario, vehicle, SEED)
    write_log(tmp_path / "csv", log, "csv")
    assert not list((tmp_path / "csv").glob("*.parquet"))
    assert_same_observations(observations(read_log(tmp_path / "csv"), nmap), vehicle.obs)
    frd = log.__class__(meta=log.meta.model_copy(update={"body_frame": "frd"}), tables=log.tables)
    write_log(tmp_path / "frd", frd)
    imu = pd.read_parquet(tmp_path / "frd" / "imu.parquet")  # stored forward, starboard, down
    assert same_bits(imu["gyro_x_rad_s"], vehicle.obs.gyro[:, 1]) and same_bits(imu["accel_z_m_s2"],
                                                                                -vehicle.obs.accel[:, 2])
    assert_same_observations(observations(read_log(tmp_path / "frd"), nmap), vehicle.obs)
    nav = pd.read_parquet(tmp_path / "frd" / "navigation.parquet")
    nav = nav.assign(heading_deg=np.degrees(nav.pop("heading_rad")), depth_m=-nav.pop("up_m"))
    nav.to_parquet(tmp_path / "frd" / "navigation.parquet")
    obs = observations(read_log(tmp_path / "frd"), nmap)
    np.testing.assert_allclose(obs.nav.yaw, vehicle.obs.nav.yaw, rtol=0, atol=1e-12)
    assert same_bits(obs.nav.pos, vehicle.obs.nav.pos)


def test_a_multibeam_block_of_any_width_round_trips(tmp_path, scenario, vehicle):
    """The beam block is generic in the beam count: 32 beams across track written and read back."""
    log = simulated_log(scenario, vehicle, SEED)
    fan = tuple(np.linspace(-60.0, 60.0, 32))
    pings = log.tables["dvl"]["t_s"].to_numpy()
    ranges = np.random.default_rng(0).uniform(20, 80, (pings.size, 32))
    ranges[5, 3] = np.nan  # no bottom
    log.tables["multibeam"] = pd.DataFrame({"t_s": pings, **{f"range_{i + 1}_m": ranges[:, i] for i in range(32)}})
    beams = dict(log.meta.beams, multibeam=BeamGeometry(across_track_deg=fan))
    log = log.__class__(meta=log.meta.model_copy(update={"beams": beams}), tables=log.tables)
    write_log(tmp_path / "mb", log)
    back = read_log(tmp_path / "mb")
    assert back.beam_count("multibeam") == 32
    assert same_bits(back.tables["multibeam"][[f"range_{i + 1}_m" for i in range(32)]].to_numpy(), ranges)
    vectors = back.meta.beam_vectors("multibeam")
    np.testing.assert_allclose(np.degrees(np.arctan2(vectors[:, 0], -vectors[:, 2])), fan, atol=1e-12)
    text = (tmp_path / "mb" / "mission.yaml").read_text()
    (tmp_path / "mb" / "mission.yaml").write_text(text.replace("\n    - 60.0\n", "\n", 1))  # 31 angles for 32 columns
    with pytest.raises(TanbenchError, match="multibeam has 32 beam range columns but mission.yaml describes 31"):
        read_log(tmp_path / "mb")
