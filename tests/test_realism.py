"""Issue 12: the navigation KF, the map-aware robust likelihoods, keep-on-map, world faults,
the closed-loop loose TAN and the recovery metrics.

Kernels are checked against their numpy references on the same inputs (1e-9) and by
reference-free properties; faults off must leave every random number of the world
unchanged; each fault changes exactly what it says.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from filters_support import KERNEL_SEED, VEHICLE_SEED, filter_seed, short_scenario, vehicle_seed
from tanbench.config import Scenario
from tanbench.filters import likelihood as lik
from tanbench.filters.likelihood import Likelihood
from tanbench.methods import run_method
from tanbench.scoring import recovery_stats
from tanbench.filters.state import E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.tight import keep_on_map, keep_on_map_numpy
from tanbench.filters.trig import LEVEL
from tanbench.navigation import eskf
from tanbench.options import LIKELIHOOD
from tanbench.simulation import simulate_vehicle
from tanbench.terrain import navigation_map
from tanbench.terrain.derive import map_error_field
from tanbench.terrain.grid import node_grid, node_grid_of
from tanbench.terrain.representation import (map_variance_grid, representation_variance,
                                              representation_variance_numpy)

TOL = dict(rtol=1e-9, atol=1e-9)


@pytest.fixture(scope="module")
def world():
    scenario = Scenario()
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(VEHICLE_SEED))
    return scenario, vehicle, navigation_map(scenario.terrain, scenario.map_resolution_m)


# --------------------------------------------------------------------------------------
# error-state Kalman filter
# --------------------------------------------------------------------------------------
def random_cov(rng, n, scale):
    a = rng.normal(size=(n, n)) * scale
    return a @ a.T + np.diag(scale**2)


def test_eskf_predict_matches_numpy():
    rng = np.random.default_rng([KERNEL_SEED, 120])
    for _ in range(5):
        p0 = random_cov(rng, 4, np.array([10.0, 10.0, 0.3, 1e-4]))
        args = (*rng.normal(0, 20, 2), *rng.normal(0, 50, 2), rng.uniform(0, 10), 0.1, 1e-3, 1e-6)
        p = p0.copy()
        eskf.eskf_predict(p, *args)
        np.testing.assert_allclose(p, eskf.eskf_predict_numpy(p0, *args), **TOL)


def test_eskf_update_matches_numpy_and_gates():
    rng = np.random.default_rng([KERNEL_SEED, 121])
    for gate in (1e9, 1.0):
        p0 = random_cov(rng, 4, np.array([10.0, 10.0, 0.3, 1e-4]))
        r = random_cov(rng, 2, np.array([3.0, 3.0]))
        nu = rng.normal(0, 15, 2)
        p = p0.copy()
        dx = np.full(4, np.nan)
        chi2 = eskf.eskf_update(p, nu[0], nu[1], r, gate, dx)
        chi2_ref, dx_ref, p_ref = eskf.eskf_update_numpy(p0, nu, r, gate)
        assert chi2 == pytest.approx(chi2_ref, rel=1e-9)
        np.testing.assert_allclose(dx, dx_ref, **TOL)
        np.testing.assert_allclose(p, p_ref, rtol=1e-9, atol=1e-12)
        if chi2 >= gate:
            assert (dx == 0).all() and (p == p0).all()


def test_heading_observable_from_fixes_while_moving():
    """Reference-free: a 20 deg heading error, perfect-ish fixes every 10 s along a straight
    track at 2 m/s: the KF's heading correction recovers the error (cross-track = error x
    distance). Without motion, fixes say nothing about the heading."""
    for speed, expect_observable in ((2.0, True), (0.0, False)):
        err = math.radians(20.0)
        p = np.diag([25.0, 25.0, math.radians(30.0) ** 2, 1e-12])
        heading_est = 0.0
        dx = np.zeros(4)
        true_pos = np.zeros(2)
        est_pos = np.zeros(2)
        for k in range(1, 61):
            d_est = np.array([0.0, speed])  # the corrected navigation's displacement (north)
            d_true = np.array([-math.sin(err - heading_est) * speed, math.cos(err - heading_est) * speed])
            # truth turned by the remaining heading error (CCW, Eq. 5 yaw)
            true_pos = true_pos + np.array([-math.sin(err) * speed, math.cos(err) * speed])
            est_pos = est_pos + np.array([-math.sin(heading_est) * speed, math.cos(heading_est) * speed])
            rot = np.array([[math.cos(heading_est), -math.sin(heading_est)], [math.sin(heading_est), math.cos(heading_est)]])
            d = rot @ d_est
            eskf.eskf_predict(p, d[0], d[1], 0.0, 0.0, 0.0, 0.05, 1e-5, 0.0)
            del d_true
            if k % 10 == 0:
                nu = true_pos - est_pos
                eskf.eskf_update(p, nu[0], nu[1], np.eye(2) * 1.0, 1e9, dx)
                est_pos = est_pos + dx[:2]
                heading_est += dx[2]
        if expect_observable:
            assert abs(math.degrees(err - heading_est)) < 1.0
            assert math.degrees(math.sqrt(p[2, 2])) < 2.0
        else:
            assert heading_est == pytest.approx(0.0, abs=1e-12)
            assert math.degrees(math.sqrt(p[2, 2])) > 29.0


def gaussian_window(rng):
    """A random window: prior (m_prior, p_prior), a terrain measurement (z_true, r_true) and the
    Bayesian posterior (m_post, p_post) they give."""
    p_prior = random_cov(rng, 2, np.array([20.0, 20.0]))
    r_true = random_cov(rng, 2, np.array([3.0, 3.0]))
    m_prior = rng.normal(0, 50, 2)
    z_true = rng.normal(0, 50, 2)
    p_post = np.linalg.inv(np.linalg.inv(p_prior) + np.linalg.inv(r_true))
    m_post = p_post @ (np.linalg.solve(p_prior, m_prior) + np.linalg.solve(r_true, z_true))
    return m_prior, p_prior, z_true, r_true, m_post, p_post


def test_terrain_only_fix_matches_numpy_and_removes_the_prior():
    rng = np.random.default_rng([KERNEL_SEED, 122])
    for _ in range(5):
        m_prior, p_prior, z_true, r_true, m_post, p_post = gaussian_window(rng)
        z, r = np.empty(2), np.empty((2, 2))
        assert eskf.terrain_only_fix(m_post, p_post, m_prior, p_prior, 1e3, z, r)
        ok, z_ref, r_ref = eskf.terrain_only_fix_numpy(m_post, p_post, m_prior, p_prior, 1e3)
        assert ok
        np.testing.assert_allclose(z, z_ref, rtol=1e-7, atol=1e-7)
        np.testing.assert_allclose(r, r_ref, rtol=1e-7, atol=1e-7)
        np.testing.assert_allclose(z, z_true, rtol=1e-6, atol=1e-6)  # the measurement is recovered
        np.testing.assert_allclose(r, r_true, rtol=1e-6, atol=1e-6)
    # no information in the window: posterior = prior -> no fix
    assert not eskf.terrain_only_fix(m_prior, p_prior, m_prior, p_prior, 1e3, z, r)
    # a weak window (terrain std ~30 m) is refused by max_std = 25 m
    p_post = np.linalg.inv(np.linalg.inv(p_prior) + np.eye(2) / 900.0)
    assert not eskf.terrain_only_fix(m_prior, p_post, m_prior, p_prior, 25.0, z, r)


def test_fix_prior_chi2_matches_numpy_and_equals_the_distance_from_the_posterior():
    """docs/filters.md 9: the fix's chi-square against its window prior equals the PF posterior
    mean's distance from the fix under the transformed covariance, and flags an extrapolated fix."""
    rng = np.random.default_rng([KERNEL_SEED, 123])
    z, r = np.empty(2), np.empty((2, 2))
    for _ in range(5):
        m_prior, p_prior, _, _, m_post, p_post = gaussian_window(rng)
        assert eskf.terrain_only_fix(m_post, p_post, m_prior, p_prior, 1e3, z, r)
        chi2 = eskf.fix_prior_chi2(z, r, m_prior, p_prior)
        assert chi2 == pytest.approx(eskf.fix_prior_chi2_numpy(z, r, m_prior, p_prior), rel=1e-9)
        # z - m_post = P_post P_prior^-1 (z - m_prior): the same chi-square about the posterior
        t = p_post @ np.linalg.inv(p_prior)
        d = z - m_post
        assert chi2 == pytest.approx(float(d @ np.linalg.solve(t @ (r + p_prior) @ t.T, d)), rel=1e-6)
    # the diagnosed case: a window prior nearly as tight as the posterior, means 1 m apart
    m_post, p_post = np.array([1109.9, 464.5]), np.array([[2.94, 0.61], [0.61, 1.61]])
    m_prior, p_prior = np.array([1108.9, 465.5]), np.array([[3.28, 0.90], [0.90, 1.91]])
    assert eskf.terrain_only_fix(m_post, p_post, m_prior, p_prior, 25.0, z, r)
    assert np.hypot(*(z - m_post)) > 50.0  # the fix lands far from the cloud it came from
    assert eskf.fix_prior_chi2(z, r, m_prior, p_prior) > 13.8
    assert eskf.fix_prior_chi2(m_prior, r, m_prior, p_prior) == 0.0
    assert eskf.fix_prior_chi2(z, np.zeros((2, 2)), m_prior, np.zeros((2, 2))) == np.inf

# --------------------------------------------------------------------------------------
# map representation variance and the map-aware likelihoods
# --------------------------------------------------------------------------------------
def test_representation_variance_matches_numpy_and_a_plane(world):
    _, _, nmap = world
    z = nmap.z.copy()
    z[5:8, 5:9] = np.nan  # a hole: one-sided differences around it
    out = np.empty_like(z)
    representation_variance(z, nmap.res_e, nmap.res_n, 0.3, 0.4, out)
    ref = representation_variance_numpy(z, nmap.res_e, nmap.res_n, 0.3, 0.4)
    np.testing.assert_allclose(out, ref, **TOL)
    assert np.isnan(out[6, 6]) and np.isfinite(out[4, 4])
    # a plane of slope 0.2 (east) and 0.1 (north): (c |grad| res)^2 + error^2 everywhere
    ee, nn = np.meshgrid(np.arange(30) * 10.0, np.arange(20) * 10.0)
    plane = 0.2 * ee + 0.1 * nn
    representation_variance(plane, 10.0, 10.0, 1 / math.sqrt(12), 0.4, out := np.empty_like(plane))
    np.testing.assert_allclose(out, (math.hypot(0.2, 0.1) * 10 / math.sqrt(12)) ** 2 + 0.16, rtol=1e-12)


def _cloud(rng, nmap, m=301):
    """A tight cloud (8, M), a column per particle."""
    x = np.zeros((N_TIGHT, m))
    x[E] = rng.uniform(nmap.e0 - 50, nmap.e_max + 50, m)  # some footprints off the map
    x[N] = rng.uniform(nmap.n0 - 50, nmap.n_max + 50, m)
    x[U] = rng.uniform(-60, -20, m)
    x[PITCH] = rng.normal(0, 0.05, m)
    x[ROLL] = rng.normal(0, 0.05, m)
    x[YAW] = rng.uniform(-7, 7, m)
    return x


@pytest.mark.parametrize("kind", sorted(LIKELIHOOD))
def test_loglik_tight_mapaware_matches_numpy(world, kind):
    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 130, LIKELIHOOD[kind]])
    mvar = map_variance_grid(nmap, 0.2887, 0.4)
    za = nmap.kernel_args()
    grid = node_grid(nmap, mvar)
    for ping in rng.integers(0, v.obs.dvl_ranges.shape[0], 3):
        x = _cloud(rng, nmap)
        ranges = v.obs.dvl_ranges[ping].copy()
        ranges[rng.integers(0, 4)] = np.nan
        dist = rng.normal(0, 0.3, (2, x.shape[1]))
        out = np.empty(x.shape[1])
        best = lik.loglik_tight(x, v.obs.dvl_beams, ranges, grid, Likelihood(True, LIKELIHOOD[kind], 4.0), 1.0, 5.0,
                                dist, 0.1, True, LEVEL, out)
        ref, best_ref = lik.loglik_tight_numpy(x, v.obs.dvl_beams, ranges, za, mvar,
                                               Likelihood(True, LIKELIHOOD[kind], 4.0), 1.0, 5.0, dist, 0.1)
        np.testing.assert_allclose(out, ref, **TOL)
        assert best == pytest.approx(best_ref, rel=1e-9)


def test_mapaware_gaussian_with_zero_variance_is_the_plain_kernel(world):
    """Reference-free: a zero variance grid and the Gaussian density reproduce loglik_tight."""
    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 131])
    zero = np.where(np.isnan(nmap.z), np.nan, 0.0)
    x = _cloud(rng, nmap)
    dist = rng.normal(0, 0.3, (2, x.shape[1]))
    a, b = np.empty(x.shape[1]), np.empty(x.shape[1])
    best_a = lik.loglik_tight(x, v.obs.dvl_beams, v.obs.dvl_ranges[100], node_grid(nmap),
                              Likelihood(False, lik.LIK_GAUSSIAN, 4.0), 1.3, 5.0, dist, 0.1, True, LEVEL, a)
    best_b = lik.loglik_tight(x, v.obs.dvl_beams, v.obs.dvl_ranges[100], node_grid(nmap, zero),
                              Likelihood(True, lik.LIK_GAUSSIAN, 4.0), 1.3, 5.0, dist, 0.1, True, LEVEL, b)
    np.testing.assert_allclose(a, b, **TOL)
    assert best_a == pytest.approx(best_b, rel=1e-12)


@pytest.mark.parametrize("kind", sorted(LIKELIHOOD))
def test_loglik_loose_mapaware_matches_numpy(world, kind):
    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 132, LIKELIHOOD[kind]])
    mvar = map_variance_grid(nmap, 0.2887, 0.4)
    za = nmap.kernel_args()
    x = np.ascontiguousarray(_cloud(rng, nmap)[:2])
    off = np.ascontiguousarray(v.obs.dvl_beams * v.obs.dvl_ranges[200][:, None])
    off[1] = np.nan
    out = np.empty(x.shape[1])
    best = lik.loglik_loose(x, off, -40.0, node_grid(nmap, mvar), Likelihood(True, LIKELIHOOD[kind], 4.0), 1.0, 5.0,
                            out)
    ref, best_ref = lik.loglik_loose_numpy(x, off, -40.0, za, mvar, Likelihood(True, LIKELIHOOD[kind], 4.0), 1.0,
                                           5.0)
    np.testing.assert_allclose(out, ref, **TOL)
    assert best == pytest.approx(best_ref, rel=1e-9)


def test_student_t_bounds_the_pull_of_an_outlier():
    """Reference-free: a 30-sigma range costs a Gaussian 450 log units, a Student-t (nu = 4)
    5/2 log(1 + 900/4) = 13.6."""
    g = lik._beam_logpdf_numpy(np.array(900.0), 1.0, 1.0, True, lik.LIK_GAUSSIAN, 4.0)
    t = lik._beam_logpdf_numpy(np.array(900.0), 1.0, 1.0, True, lik.LIK_STUDENT, 4.0)
    assert g == pytest.approx(-450.0)
    assert t == pytest.approx(-2.5 * math.log(226.0), rel=1e-12)


def test_steep_map_weighs_less():
    """A particle whose footprint lands on a steep part of the map is charged less for the same
    innovation than on a flat part (its variance includes the representation error)."""
    z = np.zeros((20, 20))
    z[:, 10:] = np.arange(10) * 5.0  # 0.5 slope east of the middle, flat west
    mvar = np.empty_like(z)
    representation_variance(z, 10.0, 10.0, 0.2887, 0.0, mvar)
    x = np.array([[35.0, 165.0], [100.0, 100.0]])  # flat, steep (a column each)
    off = np.array([[0.0, 0.0, -30.0]])
    up = np.array([30.0 + 3.0, 30.0 + np.interp(165.0, np.arange(20) * 10.0, z[10]) + 3.0])  # 3 m innovation
    out = np.empty(1)
    grid = node_grid_of(z, 0.0, 0.0, 0.1, 0.1, z2=mvar)
    lls = []
    for j in range(2):
        lik.loglik_loose(np.ascontiguousarray(x[:, j:j + 1]), off, up[j], grid, Likelihood(True, lik.LIK_GAUSSIAN, 4.0),
                         1.0, 5.0, out)
        lls.append(out[0])
    assert lls[1] > lls[0]


# --------------------------------------------------------------------------------------
# keep on map, recovery statistics
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("point", [(50.0, 50.0), (-10.0, 50.0), (50.0, 150.0), (-5.0, -5.0), (120.0, 120.0)])
def test_keep_on_map_matches_numpy(point):
    bounds = np.array([0.0, 100.0, 0.0, 110.0])
    mean = np.array([*point, 7.0])
    clamped, out_ref = keep_on_map_numpy(mean, bounds)
    out = keep_on_map(mean, bounds)
    assert out == out_ref
    np.testing.assert_array_equal(mean, clamped)
    assert 0.0 <= mean[0] <= 100.0 and 0.0 <= mean[1] <= 110.0 and mean[2] == 7.0
    # disabled bounds never clamp
    far = np.array([1e6, -1e6])
    assert not keep_on_map(far, np.array([1.0, 0.0, 0.0, 0.0])) and far[0] == 1e6


@pytest.mark.parametrize("point", [(np.nan, 50.0), (np.nan, 150.0), (-10.0, np.nan)])
def test_keep_on_map_numpy_agrees_on_a_nan_estimate(point):
    """A NaN coordinate compares False with both bounds: the kernel leaves it and reports only the
    other coordinate; the reference said the NaN had left the map (NaN != NaN; found by an audit)."""
    bounds = np.array([0.0, 100.0, 0.0, 110.0])
    mean = np.array([*point, 7.0])
    clamped, out_ref = keep_on_map_numpy(mean, bounds)
    assert keep_on_map(mean, bounds) == out_ref
    np.testing.assert_array_equal(mean, clamped)


def test_recovery_stats():
    t = np.arange(40.0)
    reinit = np.zeros(40, dtype=np.int64)
    healthy = np.zeros(40, dtype=np.int64)
    reinit[[5, 30]] = 1
    healthy[8:14] = 1  # 6 healthy updates after the first reinit: recovered at k = 12 with steps = 5
    healthy[31:34] = 1  # only 3 after the second
    assert recovery_stats(t, reinit, healthy, 5) == (1, 5.0, 7.0)
    n, first, mean = recovery_stats(t, np.zeros(40, dtype=np.int64), healthy, 5)
    assert n == 0 and math.isnan(first) and math.isnan(mean)


# --------------------------------------------------------------------------------------
# world faults
# --------------------------------------------------------------------------------------
SHORT = dict(duration_s=200.0)


def _pair(**faults):
    base = short_scenario(**SHORT)
    faulty = short_scenario(**SHORT, faults=faults)
    return base, faulty, simulate_vehicle(base, vehicle_seed(0)), simulate_vehicle(faulty, vehicle_seed(0))


def test_faults_off_is_the_default_world():
    explicit = short_scenario(**SHORT, faults=dict(tide_bias_m=0.0, outlier_fraction=0.0, current_east_mps=0.0),
                              terrain=dict(map_error_correlation_m=0.0))
    plain = short_scenario(**SHORT)
    a, b = simulate_vehicle(plain, vehicle_seed(1)), simulate_vehicle(explicit, vehicle_seed(1))
    for name in ("gyro", "accel", "dvl_velocity", "depth", "dvl_ranges", "sbe_ranges"):
        np.testing.assert_array_equal(getattr(a.obs, name), getattr(b.obs, name))
    np.testing.assert_array_equal(a.obs.nav.pos, b.obs.nav.pos)


def test_fault_cells_are_paired_with_the_fault_free_cell():
    """The vehicle seed leaves the faults out (pairing key), the world cache key does not."""
    plain = short_scenario(**SHORT)
    for faulty in (short_scenario(**SHORT, faults=dict(current_east_mps=0.2)),
                   short_scenario(**SHORT, terrain=dict(map_error_correlation_m=50.0))):
        assert faulty.pairing_key() == plain.pairing_key() and faulty.world_key() != plain.world_key()
    no_multibeam = short_scenario(**SHORT, sensors=dict(multibeam_beams=0))
    assert no_multibeam.pairing_key() == no_multibeam.world_key()  # without faults and multibeam the two agree
    assert plain.pairing_key() != plain.world_key()  # the shared short scenario carries a small multibeam
    assert short_scenario(**SHORT, trajectory=dict(speed_mps=1.5)).pairing_key() != plain.pairing_key()


def test_outliers_change_only_a_fraction_of_ranges():
    base, faulty, a, b = _pair(outlier_fraction=0.05)
    changed = a.obs.dvl_ranges != b.obs.dvl_ranges
    assert 0.03 < changed.mean() < 0.07
    np.testing.assert_array_equal(a.obs.dvl_velocity, b.obs.dvl_velocity)
    np.testing.assert_array_equal(a.obs.nav.pos, b.obs.nav.pos)
    assert np.nanmax(b.obs.dvl_ranges[changed]) <= faulty.sensors.max_range_m


def test_sound_speed_scales_true_ranges():
    base, faulty, a, b = _pair(sound_speed_scale_error=0.01)
    from tanbench.simulation import noise_free_world
    import json
    _, _, dvl_true, _ = noise_free_world(json.dumps(base.world_spec(), sort_keys=True))
    np.testing.assert_allclose(b.obs.dvl_ranges - a.obs.dvl_ranges, 0.01 * dvl_true, rtol=1e-9, atol=1e-9)


def test_tide_offsets_the_depth():
    base, faulty, a, b = _pair(tide_bias_m=1.5, tide_amplitude_m=0.5, tide_period_s=100.0)
    diff = b.obs.depth - a.obs.depth
    assert diff.min() >= 1.0 - 1e-9 and diff.max() <= 2.0 + 1e-9 and diff.max() - diff.min() > 0.9
    np.testing.assert_array_equal(a.obs.dvl_ranges, b.obs.dvl_ranges)


def test_dropouts_are_runs_of_missing_pings_with_held_velocity():
    base, faulty, a, b = _pair(dropout_rate_per_ping=0.02, dropout_mean_pings=10.0)
    lost = np.isnan(b.obs.dvl_ranges).all(axis=1) & ~np.isnan(a.obs.dvl_ranges).all(axis=1)
    assert 0.05 < lost.mean() < 0.4
    starts = np.flatnonzero(np.diff(lost.astype(int)) == 1)
    assert lost.sum() / max(starts.size, 1) > 3  # runs, not isolated pings
    k = b.obs.ping_idx[np.flatnonzero(lost)[-1]]
    np.testing.assert_array_equal(b.obs.dvl_velocity[k], b.obs.dvl_velocity[k - 1])  # held through the dropout
    np.testing.assert_array_equal(a.obs.sbe_ranges, b.obs.sbe_ranges)


def test_current_sets_the_vehicle_off_its_plan():
    base, faulty, a, b = _pair(current_east_mps=0.3)
    drift = b.truth.pos[:, 0] - a.truth.pos[:, 0]
    np.testing.assert_allclose(drift, 0.3 * (a.truth.t - a.truth.t[0]), atol=1e-9)
    # the DVL measures over ground: the navigation system follows the drifted truth as well as before
    err_a = np.hypot(*(a.obs.nav.pos[-1, :2] - a.truth.pos[-1, :2]))
    err_b = np.hypot(*(b.obs.nav.pos[-1, :2] - b.truth.pos[-1, :2]))
    assert abs(err_b - err_a) < 0.1 * err_a + 2.0


def test_correlated_map_error_field():
    rng = np.random.default_rng(3)
    white = rng.standard_normal((200, 200))
    np.testing.assert_array_equal(map_error_field(white, 0.0), white)
    f = map_error_field(white, 5.0)
    assert f.std() == pytest.approx(1.0)
    assert np.corrcoef(f[:, :-1].ravel(), f[:, 1:].ravel())[0, 1] > 0.9
    # the navigation maps: same smooth relief, i.i.d. against correlated errors of the same std
    spec = short_scenario().terrain
    iid = navigation_map(spec, 10.0)
    corr = navigation_map(spec.model_copy(update={"map_error_correlation_m": 100.0}), 10.0)
    clean = navigation_map(spec.model_copy(update={"map_error_m": 0.0}), 10.0)
    e_iid, e_corr = iid.z - clean.z, corr.z - clean.z
    assert e_iid.std() == pytest.approx(0.4, rel=0.05) and e_corr.std() == pytest.approx(0.4, rel=0.05)
    lag1 = [np.corrcoef(e[:, :-1].ravel(), e[:, 1:].ravel())[0, 1] for e in (e_iid, e_corr)]
    assert abs(lag1[0]) < 0.05 and lag1[1] > 0.9


# --------------------------------------------------------------------------------------
# the closed-loop loose TAN
# --------------------------------------------------------------------------------------
FEEDBACK_RUNS = 200
FEEDBACK_ORIGINAL_RUNS = 3
_FEEDBACK_ERRORS: dict = {}


def _feedback_heading_errors(runs: int):
    """Final heading errors of both loose architectures over the first ``runs`` runs; each run computed
    once per process (the 3-run case does not pay for the 200 when it runs first or alone)."""
    errs = _FEEDBACK_ERRORS.setdefault("errors", {"kalman-feedback": [], "fix-only": []})
    for r in range(len(errs["fix-only"]), runs):
        v = simulate_vehicle(short_scenario(duration_s=600.0), vehicle_seed(r))  # one world for both
        for arch in errs:
            sc = short_scenario(duration_s=600.0, particles=1500, filter=dict(loose_architecture=arch))
            m = run_method(sc, "loose-dvl", v, filter_seed(r, 2)).metrics
            errs[arch].append(m["final_heading_error_deg"])
    return {k: np.array(e[:runs]) for k, e in errs.items()}


@pytest.mark.parametrize("runs", [pytest.param(FEEDBACK_ORIGINAL_RUNS, id="original-3runs"),
                                  pytest.param(FEEDBACK_RUNS, id="200runs")])
def test_kalman_feedback_corrects_the_heading_fix_only_does_not(runs):
    """Area A, 600 s, 1500 particles: the closed loop ends within 5 deg of the true heading on
    average (the navigation system starts 30 deg off), the fix-only variant keeps the
    navigation heading (> 25 deg).

    Set with 3 runs; that version is kept and counted (it passes on the vectorised code). The closed loop loses a run now and
    then (4 of runs 20-79 with the code before the vectorised passes, 5 with it), each ending
    8-58 deg off, so a 3-run mean passes or fails by luck; the same statistic and threshold are
    also reported over 200 runs (the first 3 are the original ones; standard error ~0.7 deg)."""
    errs = _feedback_heading_errors(runs)
    assert np.mean(errs["kalman-feedback"]) < 5.0, errs
    assert np.mean(errs["fix-only"]) > 25.0, errs
