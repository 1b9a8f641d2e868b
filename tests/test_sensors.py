"""Sensors: ray casting, sonar beams and range noise, IMU / DVL / pressure error models.

Error figures are the resolved Table 1 configuration (``Scenario().sensors``), checked
against the paper's facts first, so the statistics tests never retype the paper's numbers.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from tanbench.config import Scenario, SensorSpec
from tanbench.sensors.dvl import measure_velocity
from tanbench.sensors.imu import first_order_recursion, first_order_recursion_numpy, gauss_markov, measure_imu
from tanbench.sensors.pressure import measure_depth
from tanbench.sensors.raycast import cast_ray, cast_rays, cast_rays_numpy
from tanbench.sensors.sonar import (
    altimeter_beam_vectors,
    dvl_beam_vectors,
    measure_ranges,
    true_ranges,
)
from tanbench.terrain.grid import Map

RES = 2.5
MAX_RANGE = 200.0
STEP = 0.5 * RES  # the march step the sonar uses on a 2.5 m truth


def plane_map(a, b, c, size=600.0) -> Map:
    """The plane z = a + b e + c n on a 2.5 m grid over [0, size]^2."""
    x = np.arange(0.0, size + RES / 2, RES)
    return Map(z=a + b * x[None, :] + c * x[:, None], e0=0.0, n0=0.0, res_e=RES, res_n=RES)


def random_down_dirs(rng, k, max_tilt_deg=60.0) -> np.ndarray:
    """k unit vectors at most ``max_tilt_deg`` from straight down, random azimuth."""
    tilt = np.radians(rng.uniform(0.0, max_tilt_deg, k))
    az = rng.uniform(0.0, 2 * np.pi, k)
    return np.stack([np.sin(tilt) * np.sin(az), np.sin(tilt) * np.cos(az), -np.cos(tilt)], axis=1)


def cast(m: Map, origins, dirs, max_range=MAX_RANGE, step=STEP) -> np.ndarray:
    out = np.empty(len(origins))
    cast_rays(*m.kernel_args(), np.ascontiguousarray(origins, dtype=float),
              np.ascontiguousarray(dirs, dtype=float), max_range, step, out)
    return out


@pytest.fixture(scope="module")
def table1() -> SensorSpec:
    """Resolved Table 1 sensors, after checking they are the paper's figures."""
    return Scenario().sensors


def test_table1_config_matches_paper(table1, facts):
    """The default (Table 1) sensor figures are the paper's, read from the facts file."""
    g, a = facts["sensors"]["gyro"], facts["sensors"]["accelerometer"]
    assert table1.gyro_turn_on_bias_deg_h == g["initial_bias_deg_per_h"]
    assert table1.gyro_bias_instability_deg_h == g["in_run_bias_stability_deg_per_h"]
    assert table1.gyro_arw_deg_sqrt_h == g["angular_random_walk_deg_per_sqrt_h"]
    assert table1.accel_turn_on_bias_mg == a["initial_bias_mg"]
    assert table1.accel_bias_instability_mg == a["in_run_bias_stability_mg"]
    assert table1.accel_noise_mg_sqrt_hz == a["noise_density_mg_per_sqrt_hz"]
    assert table1.pressure_error_percent == facts["sensors"]["pressure_depth"]["accuracy_percent"]
    assert table1.dvl_beamwidth_deg == facts["sensors"]["dvl"]["beamwidth_deg"]
    assert table1.altimeter_beamwidth_deg == facts["sensors"]["altimeter"]["beamwidth_deg"]
    assert len(table1.beam_azimuths_deg) == facts["sensors"]["dvl"]["beams"]
    scale_pct, noise_cm = (float(x) for x in re.findall(
        r"([\d.]+) % of speed plus ([\d.]+) cm/s", facts["sensors"]["dvl"]["velocity_error"])[0])
    assert table1.dvl_scale_error == pytest.approx(scale_pct / 100)
    assert table1.dvl_noise_mps == pytest.approx(noise_cm / 100)


# ---- ray casting ----------------------------------------------------------------------

@pytest.mark.parametrize("a,b,c", [(-80.0, 0.0, 0.0), (-60.0, 0.05, -0.03), (-40.0, -0.3, 0.2),
                                   (-120.0, 0.45, 0.45)])
def test_raycast_exact_on_planes_and_slopes(a, b, c):
    """Cast ranges on a flat floor and on slopes equal the closed-form ray/plane intersection (< 1 cm)."""
    m = plane_map(a, b, c)
    rng = np.random.default_rng(17)
    k = 4000
    pe, pn = rng.uniform(200, 400, k), rng.uniform(200, 400, k)
    pu = a + b * pe + c * pn + rng.uniform(2.0, 90.0, k)
    origins = np.stack([pe, pn, pu], axis=1)
    dirs = random_down_dirs(rng, k)
    denom = dirs[:, 2] - b * dirs[:, 0] - c * dirs[:, 1]
    s_exact = (a + b * pe + c * pn - pu) / np.where(denom < 0, denom, -1e-300)
    hits = (denom < -0.05) & (s_exact < MAX_RANGE - 1.0)
    assert hits.mean() > 0.8
    out = cast(m, origins, dirs)
    np.testing.assert_allclose(out[hits], s_exact[hits], rtol=0, atol=0.01)
    assert np.abs(out[hits] - s_exact[hits]).max() < 1e-6  # bilinear is exact on planes
    misses = (denom >= 0) | (s_exact > MAX_RANGE + 1.0)  # going up the slope or too far
    assert np.isnan(out[misses]).all()


@pytest.mark.parametrize("kind", ["plane", "rough"])
def test_raycast_jit_matches_numpy_reference(kind, paper_truth):
    """Jitted cast_rays equals cast_rays_numpy to 1e-9, NaNs included, on a slope and on rough terrain."""
    rng = np.random.default_rng(23)
    k = 3000
    if kind == "plane":
        m = plane_map(-50.0, 0.08, -0.11)
        pe, pn = rng.uniform(-20, 620, k), rng.uniform(-20, 620, k)  # some origins off the map
    else:
        m = paper_truth
        pe, pn = rng.uniform(700, 1450, k), rng.uniform(380, 800, k)
    pu = rng.uniform(-45.0, -15.0, k)
    pu[::50] = m.elevation(pe[::50], pn[::50]) - 1.0  # some origins below the floor
    origins = np.stack([pe, pn, pu], axis=1)
    dirs = random_down_dirs(rng, k, 75.0)
    dirs[::40, 2] *= -1.0  # some rays pointing up
    out = cast(m, origins, dirs)
    ref = cast_rays_numpy(*m.kernel_args(), origins, dirs, MAX_RANGE, STEP)
    assert 0 < np.isnan(ref).sum() < k // 2
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-9, equal_nan=True)
    single = [cast_ray(*m.kernel_args(), *origins[i], *dirs[i], MAX_RANGE, STEP) for i in range(100)]
    np.testing.assert_allclose(single, ref[:100], rtol=0, atol=1e-9, equal_nan=True)


def test_raycast_rough_terrain_hits_the_floor(paper_truth):
    """On the rough synthetic seafloor every cast range ends on the bilinear floor (< 1 mm)."""
    rng = np.random.default_rng(29)
    k = 2000
    pe, pn = rng.uniform(700, 1450, k), rng.uniform(380, 800, k)
    origins = np.stack([pe, pn, np.full(k, -20.0)], axis=1)
    dirs = random_down_dirs(rng, k, 35.0)
    out = cast(paper_truth, origins, dirs)
    assert np.isfinite(out).all()
    hit = origins + out[:, None] * dirs
    np.testing.assert_allclose(hit[:, 2], paper_truth.elevation(hit[:, 0], hit[:, 1]), atol=1e-3)


def test_raycast_off_map_below_floor_and_out_of_range_give_nan():
    """Rays leaving the map, from outside it, from below the floor or beyond max range are NaN."""
    m = plane_map(-80.0, 0.0, 0.0)
    down = [0.0, 0.0, -1.0]
    shallow_east = [math.cos(math.radians(5)), 0.0, -math.sin(math.radians(5))]
    origins = np.array([
        [590.0, 300.0, -20.0],  # heads east, meets the edge long before the floor
        [650.0, 300.0, -20.0],  # starts off the map
        [300.0, 300.0, -85.0],  # vehicle below the floor
        [300.0, 300.0, -80.0],  # vehicle exactly on the floor
        [300.0, 300.0, -20.0],  # floor 60 m down but max range 50 m
    ])
    dirs = np.array([shallow_east, down, down, down, down])
    for out in (cast(m, origins, dirs, max_range=50.0),
                cast_rays_numpy(*m.kernel_args(), origins, dirs, 50.0, STEP)):
        assert np.isnan(out).all()
    # control: a ray that meets the floor before the edge hits; the out-of-range one does with more range
    steeper_east = [math.cos(math.radians(20)), 0.0, -math.sin(math.radians(20))]
    ok = cast(m, np.array([[300.0, 300.0, -20.0]]), np.array([steeper_east]))
    assert ok[0] == pytest.approx(60.0 / math.sin(math.radians(20)), abs=1e-6)
    assert cast(m, origins[4:], dirs[4:], max_range=200.0)[0] == pytest.approx(60.0, abs=1e-6)


# ---- sonar beams and ranges -------------------------------------------------------------

@pytest.mark.parametrize("tilt", [20.0, 30.0])
def test_dvl_beam_vectors(tilt, table1):
    """DVL beams are unit vectors at the configured tilt, azimuth clockwise from forward."""
    beams = dvl_beam_vectors(tilt, table1.beam_azimuths_deg)
    assert beams.shape == (len(table1.beam_azimuths_deg), 3)
    np.testing.assert_allclose(np.linalg.norm(beams, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(np.degrees(np.arccos(-beams[:, 2])), tilt, atol=1e-12)
    az = np.degrees(np.arctan2(beams[:, 0], beams[:, 1])) % 360.0  # from +y (forward) towards +x
    np.testing.assert_allclose(az, table1.beam_azimuths_deg, atol=1e-12)
    np.testing.assert_allclose(altimeter_beam_vectors(), [[0.0, 0.0, -1.0]])
    assert table1.beam_tilt_deg == 30.0  # the configured default (paper: 20-30 deg typical)


def test_true_ranges_level_vehicle_over_flat_floor(table1):
    """Over a flat floor a level vehicle's ranges are altitude / cos(tilt), whatever its heading."""
    m = plane_map(-80.0, 0.0, 0.0)
    n = 8
    pos = np.column_stack([np.full(n, 300.0), np.full(n, 300.0), np.full(n, -30.0)])
    yaw = np.linspace(-np.pi, np.pi, n)
    beams = dvl_beam_vectors(table1.beam_tilt_deg, table1.beam_azimuths_deg)
    r = true_ranges(m, pos, np.zeros(n), np.zeros(n), yaw, beams)
    np.testing.assert_allclose(r, 50.0 / math.cos(math.radians(table1.beam_tilt_deg)), atol=1e-6)
    alt = true_ranges(m, pos, np.zeros(n), np.zeros(n), yaw, altimeter_beam_vectors())
    np.testing.assert_allclose(alt, 50.0, atol=1e-6)
    # a finite beam returns its first echo: the cone edge nearest the vertical
    hw = math.radians(table1.dvl_beamwidth_deg) / 2
    r_bw = true_ranges(m, pos, np.zeros(n), np.zeros(n), yaw, beams, table1.dvl_beamwidth_deg)
    np.testing.assert_allclose(r_bw, 50.0 / math.cos(math.radians(table1.beam_tilt_deg) - hw), atol=1e-6)


def test_beam_footprint_first_echo_when_an_edge_ray_misses(table1):
    """A finite beam whose far cone edge passes max range still returns its first (near-edge) echo."""
    # Known bug (sonar.true_ranges): ``min(axis=2)`` propagates the NaN of the missing cone ray,
    # so the whole beam reads "no bottom" although its axis and near edge hit.
    m = plane_map(-190.0, 0.0, 0.0)
    pos = np.array([[300.0, 300.0, -20.0]])
    zero = np.zeros(1)
    tilt = math.radians(table1.beam_tilt_deg)
    hw = math.radians(table1.dvl_beamwidth_deg) / 2
    beams = dvl_beam_vectors(table1.beam_tilt_deg, table1.beam_azimuths_deg)
    assert 170.0 / math.cos(tilt) < MAX_RANGE < 170.0 / math.cos(tilt + hw)  # only the far edge misses
    axis = true_ranges(m, pos, zero, zero, zero, beams, 0.0, MAX_RANGE)
    np.testing.assert_allclose(axis, 170.0 / math.cos(tilt), atol=1e-6)
    first = true_ranges(m, pos, zero, zero, zero, beams, table1.dvl_beamwidth_deg, MAX_RANGE)
    np.testing.assert_allclose(first, 170.0 / math.cos(tilt - hw), atol=1e-6)


def test_range_noise_uniform_and_common_across_levels():
    """Range noise is uniform within +-noise_m; with one seed, noise 2 is exactly twice noise 1."""
    rng = np.random.default_rng(31)
    true = rng.uniform(20.0, 120.0, (5000, 4))
    true[::97, 1] = np.nan  # no bottom stays no bottom
    r1 = measure_ranges(true, 1.0, np.random.default_rng(99))
    r2 = measure_ranges(true, 2.0, np.random.default_rng(99))
    r0 = measure_ranges(true, 0.0, np.random.default_rng(99))
    assert np.array_equal(np.isnan(r1), np.isnan(true)) and np.array_equal(r0, true, equal_nan=True)
    u = (r1 - true)[np.isfinite(true)]
    assert np.abs(u).max() <= 1.0 and np.abs(u).max() > 0.999
    assert abs(u.mean()) < 0.02 and u.std() == pytest.approx(1 / math.sqrt(3), rel=0.02)
    np.testing.assert_allclose(r2 - true, 2.0 * (r1 - true), rtol=0, atol=1e-12)


# ---- IMU -------------------------------------------------------------------------------

N_IMU = 100_000  # 1000 s at 100 Hz
DT = 0.01


def _imu(sensors, seed, n=N_IMU):
    zero = np.zeros((n, 3))
    return measure_imu(zero, zero, DT, sensors, np.random.default_rng(seed))


def test_imu_white_noise_levels(table1):
    """Per-sample white noise: gyro ARW * sqrt(rate) and accel density * sqrt(rate), to 3 %."""
    gyro, accel, err = _imu(table1, 41)
    g_noise = gyro - err.gyro_bias
    a_noise = accel - err.accel_bias
    arw = table1.gyro_arw_deg_sqrt_h * math.radians(1.0) / 60.0  # rad/sqrt(s)
    vrw = table1.accel_noise_mg_sqrt_hz * 9.80665e-3  # m/s^2/sqrt(Hz)
    np.testing.assert_allclose(g_noise.std(axis=0), arw / math.sqrt(DT), rtol=0.03)
    np.testing.assert_allclose(a_noise.std(axis=0), vrw / math.sqrt(DT), rtol=0.03)
    for x in (g_noise, a_noise):  # white: no lag-1 correlation, zero mean
        assert np.abs(np.mean(x[1:] * x[:-1], axis=0) / x.var(axis=0)).max() < 0.02
        assert np.all(np.abs(x.mean(axis=0)) < 5 * x.std(axis=0) / math.sqrt(N_IMU))


def test_imu_turn_on_bias_within_spec(table1):
    """Turn-on biases are constant over the run and uniform within +-spec (gyro deg/h, accel mg)."""
    spec = table1.model_copy(update={"gyro_bias_instability_deg_h": 0.0, "accel_bias_instability_mg": 0.0})
    g_max = table1.gyro_turn_on_bias_deg_h * math.radians(1.0) / 3600.0
    a_max = table1.accel_turn_on_bias_mg * 9.80665e-3
    g_draws, a_draws = [], []
    for seed in range(200):
        _, _, err = _imu(spec, seed, n=50)
        assert np.ptp(err.gyro_bias, axis=0).max() == 0 and np.ptp(err.accel_bias, axis=0).max() == 0
        g_draws.append(err.gyro_bias[0])
        a_draws.append(err.accel_bias[0])
    for draws, bound in ((np.array(g_draws), g_max), (np.array(a_draws), a_max)):
        u = draws.ravel() / bound
        assert np.abs(u).max() <= 1.0
        assert u.max() > 0.98 and u.min() < -0.98  # spans the whole +-spec
        assert np.mean(np.abs(u)) == pytest.approx(0.5, abs=0.05)  # uniform, not clustered


def test_gauss_markov_in_run_bias():
    """The in-run bias is a stationary first-order Gauss-Markov process: std sigma, lag-1 exp(-dt/tau)."""
    sigma, tau = 2.0, 1.0
    x = gauss_markov(200_000, DT, sigma, tau, np.random.default_rng(43), axes=3)
    np.testing.assert_allclose(x.std(axis=0), sigma, rtol=0.08)
    lag1 = np.mean(x[1:] * x[:-1], axis=0) / x.var(axis=0)
    np.testing.assert_allclose(lag1, math.exp(-DT / tau), atol=1e-3)
    starts = gauss_markov(2, DT, sigma, 300.0, np.random.default_rng(44), axes=20_000)[0]
    assert starts.std() == pytest.approx(sigma, rel=0.03)  # stationary from the first sample


@pytest.mark.parametrize("n, axes, a", [(119_001, 3, math.exp(-0.01 / 300.0)), (5, 2, 0.5), (1, 3, 0.9), (0, 3, 0.9)])
def test_first_order_recursion_equals_scipy_bit_for_bit(n, axes, a):
    """The jitted Gauss-Markov recursion gives exactly scipy.signal.lfilter's numbers (stored runs keep their bits)."""
    w = np.random.default_rng(7).standard_normal((n, axes)) * 1e-4
    np.testing.assert_array_equal(first_order_recursion(w, a), first_order_recursion_numpy(w, a))


def test_imu_in_run_bias_level(table1):
    """With no turn-on bias, the drawn in-run gyro bias has the Table 1 instability as its spread."""
    spec = table1.model_copy(update={"gyro_turn_on_bias_deg_h": 0.0, "gyro_bias_corr_time_s": 1.0})
    _, _, err = _imu(spec, 45)
    want = table1.gyro_bias_instability_deg_h * math.radians(1.0) / 3600.0
    np.testing.assert_allclose(err.gyro_bias.std(axis=0), want, rtol=0.1)


# ---- DVL and pressure ---------------------------------------------------------------------

def test_dvl_scale_error_and_noise(table1):
    """DVL velocity: one scale error per run uniform within +-0.4 %, 0.2 cm/s noise, held between pings."""
    n, step = 6000, 100
    vel = np.zeros((n, 3))
    vel[:, 1] = 2.0
    vel[:, 0] = 0.3 * np.sin(np.arange(n) * 0.001)
    ping_idx = np.arange(0, n, step)
    scales = []
    for seed in range(300):
        held, scale = measure_velocity(vel, ping_idx, table1.dvl_scale_error, table1.dvl_noise_mps,
                                       np.random.default_rng(seed))
        scales.append(scale)
    scales = np.array(scales) / table1.dvl_scale_error
    assert np.abs(scales).max() <= 1.0 and scales.max() > 0.97 and scales.min() < -0.97
    # noise and holding on one long run
    ping_idx = np.arange(0, 200_000, step)
    vel = np.tile([0.1, 2.0, 0.0], (200_000, 1))
    held, scale = measure_velocity(vel, ping_idx, table1.dvl_scale_error, table1.dvl_noise_mps,
                                   np.random.default_rng(7))
    resid = held[ping_idx] - vel[ping_idx] * (1 + scale)
    np.testing.assert_allclose(resid.std(axis=0), table1.dvl_noise_mps, rtol=0.05)
    assert np.array_equal(held, np.repeat(held[ping_idx], step, axis=0))


def test_pressure_depth_noise(table1):
    """Depth is minus up plus white noise of error_percent of full scale (0.01 % of 200 m = 2 cm)."""
    up = np.linspace(-20.0, -37.5, 100_000)
    depth = measure_depth(up, table1.pressure_error_percent, table1.pressure_full_scale_m,
                          np.random.default_rng(3))
    err = depth - (-up)
    want = table1.pressure_error_percent / 100.0 * table1.pressure_full_scale_m
    assert err.std() == pytest.approx(want, rel=0.02)
    assert abs(err.mean()) < 5 * want / math.sqrt(up.size)
