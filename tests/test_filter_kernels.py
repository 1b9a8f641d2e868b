"""Filter kernels against their plain-numpy references, fed the same random draws.

Particles are the columns of the kernels' arrays (a row per state); the tests build clouds a
particle per row, as they read, and hand the kernels the transpose (``columns``).

Every jitted kernel in ``tanbench.filters`` has a numpy reference next to it. Here both
get identical inputs (arrays drawn once from a seeded ``numpy.random.Generator``) and
must agree to 1e-9. The inputs are realistic (increments, map and ranges of a simulated
area-A run) and adversarial (headings far from the navigation heading, footprints off
the map, beams without a range, log-weights down to -1e5). Where a reference could
share a mistake with its kernel, a reference-free property is checked as well
(a beam without a range is the same as no beam; the resampling schemes are unbiased;
Liu-West jitter keeps the mean and variance; a heading cloud across +-180 deg averages
to 180 deg).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import logsumexp

from filters_support import KERNEL_SEED, VEHICLE_SEED
from tanbench.options import REGULARISATION, RESAMPLING
from tanbench.config import Scenario, position_noise
from tanbench.filters import estimate as est_mod
from tanbench.filters import likelihood as lik
from tanbench.filters import propagate as prop
from tanbench.filters import resample as rs
from tanbench.filters.likelihood import Likelihood
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.trig import attitude_reference
from tanbench.navigation import increments as incmod
from tanbench.navigation.increments import compute_increments
from tanbench.sensors.imu import DEG_PER_H
from tanbench.simulation import simulate_vehicle
from tanbench.terrain import navigation_map
from tanbench.terrain.grid import node_grid
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy, yaw_to_heading_deg

TOL = dict(rtol=1e-9, atol=1e-9)


def assert_loglik_matches(out, best, ref, best_ref):
    """A likelihood kernel's log-likelihoods and divergence statistic equal its reference's."""
    assert np.isfinite(out).all()
    np.testing.assert_allclose(out, ref, **TOL)
    if np.isinf(best_ref):
        assert best == np.inf
    else:
        assert best == pytest.approx(best_ref, rel=1e-9)


SCHEME_IDS = sorted(RESAMPLING, key=RESAMPLING.get)
PLAIN = Likelihood(False, 0, 4.0)  # the paper's Gaussian beam density


def columns(x: np.ndarray) -> np.ndarray:
    """A cloud built a particle per row, as the kernels take it: a particle per column."""
    return np.ascontiguousarray(x.T)


# --------------------------------------------------------------------------------------
# shared inputs
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def world():
    """A full area-A run (fixed seed) and its 10 m navigation map."""
    scenario = Scenario()
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(VEHICLE_SEED))
    return scenario, vehicle, navigation_map(scenario.terrain, scenario.map_resolution_m)


@pytest.fixture(scope="module", params=[1, 10], ids=["T1s", "T10s"])
def increments(request, world):
    """(update sample indices, increments table) at a sampling time of 1 s or 10 s."""
    _, v, _ = world
    upd = v.obs.ping_idx[:: request.param]
    nav = v.obs.nav
    return upd, compute_increments(v.obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)


def interesting_rows(inc: np.ndarray, rng) -> list[int]:
    """The sharpest turn, the steepest dive, the longest move, and a few random intervals."""
    rows = {int(np.argmax(np.abs(inc[:, incmod.DYAW]))), int(np.argmax(np.abs(inc[:, incmod.DPITCH]))),
            int(np.argmax(np.hypot(inc[:, incmod.D0E], inc[:, incmod.D0N]))), 0, inc.shape[0] - 1}
    rows.update(int(r) for r in rng.integers(0, inc.shape[0], 4))
    return sorted(rows)


def tight_cloud(rng, m, centre_en, up, pitch, roll, yaw_nav) -> np.ndarray:
    """A particle cloud with headings anywhere (also beyond +-pi of the nav heading) and wild biases."""
    x = np.empty((m, N_TIGHT))
    x[:, E] = centre_en[0] + rng.uniform(-200, 200, m)
    x[:, N] = centre_en[1] + rng.uniform(-200, 200, m)
    x[:, U] = up + rng.normal(0, 0.5, m)
    x[:, PITCH] = pitch + rng.normal(0, 0.02, m)
    x[:, ROLL] = roll + rng.normal(0, 0.02, m)
    yaw = yaw_nav + rng.uniform(-math.pi, math.pi, m)
    far = rng.random(m) < 0.25  # unwrapped headings several turns away
    yaw[far] += rng.choice([-4, -2, 2, 4], far.sum()) * math.pi
    x[:, YAW] = yaw
    x[:, BX] = rng.normal(0, 100 * DEG_PER_H, m)
    x[:, BZ] = rng.normal(0, 100 * DEG_PER_H, m)
    x[:5, [BX, BZ]] = [[1e-2, -1e-2], [-1e-2, 1e-2], [0, 0], [5e-3, 0], [0, -5e-3]]  # ~0.6 deg/s
    return columns(x)


# --------------------------------------------------------------------------------------
# propagation
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("dist_mode", [prop.DIST_NONE, prop.DIST_PARTICLE, prop.DIST_NAVIGATION],
                         ids=["none", "particle", "navigation"])
def test_propagate_tight_matches_numpy(world, increments, dist_mode):
    _, v, _ = world
    upd, inc = increments
    rng = np.random.default_rng([KERNEL_SEED, dist_mode])
    m = 257
    for row in interesting_rows(inc, rng):
        k0 = upd[row]
        nav = v.obs.nav
        x0 = tight_cloud(rng, m, nav.pos[k0, :2], nav.pos[k0, 2], nav.pitch[k0], nav.roll[k0], nav.yaw[k0])
        noise = rng.standard_normal((6, m))
        sig_pos = position_noise(0.1 * 10, 0.1, dist_mode)
        x = x0.copy()
        innov = np.full((2, m), np.nan)  # written for the navigation reading only
        prop.propagate_tight(x, inc[row], nav.yaw[k0], noise, sig_pos, 0.01, 3e-4, dist_mode, innov)
        x_ref, innov_ref = prop.propagate_tight_numpy(x0, inc[row], nav.yaw[k0], noise, sig_pos, 0.01, 3e-4,
                                                      dist_mode)
        np.testing.assert_allclose(x, x_ref, **TOL, err_msg=f"row {row}")
        if dist_mode == prop.DIST_NAVIGATION:
            np.testing.assert_allclose(innov, innov_ref, **TOL, err_msg=f"row {row}")
        else:
            assert np.isnan(innov).all() and (innov_ref == 0).all()


def test_propagate_tight_geometry(world, increments):
    """Reference-free: zero noise and biases move a particle by Rz(delta) D0 (Eq. 5 yaw, CCW)."""
    _, v, _ = world
    upd, inc = increments
    row = int(np.argmax(np.hypot(inc[:, incmod.D0E], inc[:, incmod.D0N])))
    k0 = upd[row]
    deltas = np.array([0.0, math.pi / 2, -math.pi / 2, math.pi, 0.3, 2 * math.pi + 0.3])
    x = np.zeros((N_TIGHT, deltas.size))
    x[YAW] = v.obs.nav.yaw[k0] + deltas
    x[E], x[N] = 100.0, 200.0
    innov = np.empty((2, deltas.size))
    prop.propagate_tight(x, inc[row], v.obs.nav.yaw[k0], np.zeros((6, deltas.size)), 1.0, 1.0, 1.0,
                         prop.DIST_NAVIGATION, innov)
    d0 = inc[row, [incmod.D0E, incmod.D0N]]
    c, s = np.cos(deltas), np.sin(deltas)
    expect = np.stack([c * d0[0] - s * d0[1], s * d0[0] + c * d0[1]], 1)
    moved = x[[E, N]].T - [100.0, 200.0]
    np.testing.assert_allclose(moved, expect, atol=1e-9)
    np.testing.assert_allclose(moved[0], d0, atol=1e-12)  # delta = 0: the nav move
    np.testing.assert_allclose(moved[1], [-d0[1], d0[0]], atol=1e-9)  # +90 deg: west of it
    np.testing.assert_allclose(x[YAW], v.obs.nav.yaw[k0] + deltas + inc[row, incmod.DYAW], atol=1e-12)
    np.testing.assert_allclose(x[U], inc[row, incmod.DUP], atol=1e-12)
    np.testing.assert_allclose(innov[:, 0], 0.0, atol=1e-12)  # the nav heading: no distance innovation


def test_position_noise():
    q, r = 1.0, 0.1
    assert position_noise(q, r, prop.DIST_PARTICLE) == pytest.approx(q * r / math.sqrt(q * q + r * r), rel=1e-15)
    assert position_noise(q, r, prop.DIST_NONE) == q
    assert position_noise(q, r, prop.DIST_NAVIGATION) == q
    # the combined noise is below both (the product of two Gaussians is narrower)
    assert position_noise(q, r, prop.DIST_PARTICLE) < min(q, r)


def test_propagate_loose_matches_numpy(world, increments):
    _, v, _ = world
    upd, _ = increments
    rng = np.random.default_rng([KERNEL_SEED, 11])
    d0 = np.diff(v.obs.nav.pos[upd, :2], axis=0)
    m = 301
    for row in rng.integers(0, d0.shape[0], 6):
        x0 = v.obs.nav.pos[upd[row], :2][:, None] + rng.uniform(-100, 100, (2, m))
        noise = rng.standard_normal((3, m))
        x = x0.copy()
        prop.propagate_loose(x, d0[row, 0], d0[row, 1], noise, 1.0, math.radians(30))
        ref = prop.propagate_loose_numpy(x0, d0[row, 0], d0[row, 1], noise, 1.0, math.radians(30))
        np.testing.assert_allclose(x, ref, **TOL)
    # the heading term is perpendicular to the move
    x = np.zeros((2, 1))
    prop.propagate_loose(x, 3.0, 4.0, np.array([[0.0], [0.0], [1.0]]), 1.0, 0.1)
    np.testing.assert_allclose(x[:, 0], [3.0 - 0.4, 4.0 + 0.3], atol=1e-12)


# --------------------------------------------------------------------------------------
# likelihood
# --------------------------------------------------------------------------------------
def likelihood_particles(rng, nmap, m=240):
    """Particles on the map, on its edges (footprints partly off) and far off it (all beams off)."""
    x = np.empty((m, N_TIGHT))
    third = m // 3
    e = rng.uniform(nmap.e0 + 60, nmap.e_max - 60, m)
    n = rng.uniform(nmap.n0 + 60, nmap.n_max - 60, m)
    e[third:2 * third] = nmap.e0 + rng.uniform(-30, 30, third)  # west edge: some beams off the map
    n[2 * third:2 * third + 10] = nmap.n_max + 500.0  # far off: every beam off the map
    x[:, E], x[:, N] = e, n
    x[:, U] = rng.uniform(-40, -25, m)
    x[:, PITCH] = rng.normal(0, 0.05, m)
    x[:, ROLL] = rng.normal(0, 0.05, m)
    x[:, YAW] = rng.uniform(-7, 7, m)
    x[:, BX:] = 0.0
    return columns(x), slice(2 * third, 2 * third + 10)


def nav_attitude(v, ping):
    """The navigation system's (pitch, roll, yaw) at a ping: the reference the tight kernel expands about."""
    k = v.obs.ping_idx[ping]
    return float(v.obs.nav.pitch[k]), float(v.obs.nav.roll[k]), float(v.obs.nav.yaw[k])


RANGE_CASES = {
    "all": [],
    "one-nan": [1],
    "two-nan": [0, 3],
    "all-nan": [0, 1, 2, 3],
}


@pytest.mark.parametrize("reference", ["nav", "zero"])
@pytest.mark.parametrize("sensor, nan_beams", [("dvl", c) for c in RANGE_CASES] + [("sbe", "all"), ("sbe", "all-nan")])
def test_loglik_tight_matches_numpy(world, sensor, nan_beams, reference):
    """The attitude reference (the nav attitude in the filter, or an arbitrary one) only changes how
    the trigonometry is evaluated, never the result."""
    _, v, nmap = world
    attitude = (lambda ping: nav_attitude(v, ping)) if reference == "nav" else (lambda ping: (0.0, 0.0, 0.0))
    rng = np.random.default_rng([KERNEL_SEED, 21, len(RANGE_CASES[nan_beams])])
    beams = v.obs.dvl_beams if sensor == "dvl" else v.obs.sbe_beams
    measured = v.obs.dvl_ranges if sensor == "dvl" else v.obs.sbe_ranges
    drop = [i for i in RANGE_CASES[nan_beams] if i < beams.shape[0]]
    cloud, _ = likelihood_particles(rng, nmap)
    za = nmap.kernel_args()
    grid = node_grid(nmap)
    for ping in rng.integers(0, measured.shape[0], 3):
        # half the particles close to the navigation attitude
        x = cloud.copy()
        half = x[:, ::2].shape[1]
        x[[PITCH, ROLL, YAW], ::2] = np.array(nav_attitude(v, ping))[:, None] + rng.uniform(-0.25, 0.25, (3, half))
        ranges = measured[ping].copy()
        ranges[drop] = np.nan
        for dist in (None, rng.normal(0, 0.3, (2, x.shape[1]))):
            out = np.empty(x.shape[1])
            best = lik.loglik_tight(x, beams, ranges, grid, PLAIN, 1.0, 5.0, np.zeros((2, x.shape[1])) if dist is None
                                    else dist, 0.1, dist is not None, attitude_reference(*attitude(ping)), out)
            ref, best_ref = lik.loglik_tight_numpy(x, beams, ranges, za, None, PLAIN, 1.0, 5.0, dist, 0.1)
            assert_loglik_matches(out, best, ref, best_ref)


def test_loglik_tight_outside_penalty_and_best(world):
    """Reference-free: a particle with every footprint off the map is charged outside_sigma per beam;
    the returned statistic is the smallest per-beam chi^2 over the particles."""
    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 22])
    x, off = likelihood_particles(rng, nmap)
    ranges = v.obs.dvl_ranges[100].copy()
    dist = rng.normal(0, 0.3, (2, x.shape[1]))
    out = np.empty(x.shape[1])
    sig_u, outside, sig_d = 1.5, 5.0, 0.1
    best = lik.loglik_tight(x, v.obs.dvl_beams, ranges, node_grid(nmap), PLAIN, sig_u, outside, dist, sig_d, True,
                            attitude_reference(*nav_attitude(v, 100)), out)
    dist_term = (dist ** 2).sum(axis=0) / sig_d ** 2
    np.testing.assert_allclose(out[off], -0.5 * (4 * outside ** 2 + dist_term[off]), rtol=1e-12)
    chi = -2.0 * out - dist_term
    assert best == pytest.approx(chi.min() / 4, rel=1e-9)
    # an edge particle with a footprint off the map but its others on it is charged in between
    edge = (chi > 0) & (chi < 4 * outside ** 2)
    assert edge.any()


@pytest.mark.parametrize("drop", [[1], [0, 2], [3]])
def test_loglik_tight_nan_range_is_no_beam(world, drop):
    """Reference-free: a beam without a range (NaN, no bottom lock) is skipped, exactly as if the
    beam were not there; in particular it is not charged as a footprint off the map."""
    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 23, *drop])
    x, _ = likelihood_particles(rng, nmap)
    grid = node_grid(nmap)
    ranges = v.obs.dvl_ranges[200].copy()
    keep = [i for i in range(4) if i not in drop]
    dist = rng.normal(0, 0.3, (2, x.shape[1]))
    with_nan = ranges.copy()
    with_nan[drop] = np.nan
    out_nan = np.empty(x.shape[1])
    out_sub = np.empty(x.shape[1])
    att = attitude_reference(*nav_attitude(v, 200))
    best_nan = lik.loglik_tight(x, v.obs.dvl_beams, with_nan, grid, PLAIN, 1.0, 5.0, dist, 0.1, True, att, out_nan)
    best_sub = lik.loglik_tight(x, np.ascontiguousarray(v.obs.dvl_beams[keep]), np.ascontiguousarray(ranges[keep]),
                                grid, PLAIN, 1.0, 5.0, dist, 0.1, True, att, out_sub)
    np.testing.assert_allclose(out_nan, out_sub, rtol=1e-12, atol=1e-12)
    assert best_nan == pytest.approx(best_sub, rel=1e-12)


def test_loglik_tight_no_ranges_at_all(world):
    """No beam has a range: only the distance innovation weighs, and the statistic is inf (no evidence)."""
    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 24])
    x, _ = likelihood_particles(rng, nmap)
    dist = rng.normal(0, 0.3, (2, x.shape[1]))
    out = np.empty(x.shape[1])
    best = lik.loglik_tight(x, v.obs.sbe_beams, np.array([np.nan]), node_grid(nmap), PLAIN, 1.0, 5.0, dist, 0.1, True,
                            attitude_reference(*nav_attitude(v, 0)), out)
    np.testing.assert_allclose(out, -0.5 * (dist ** 2).sum(axis=0) / 0.01, rtol=1e-12)
    assert best == np.inf


def loose_offsets(v, ping, drop=()):
    """Beam offsets (m, 3) of one ping, projected with the navigation attitude."""
    k = v.obs.ping_idx[ping]
    c = dcm_body_to_nav_numpy(v.obs.nav.pitch[k], v.obs.nav.roll[k], v.obs.nav.yaw[k])
    off = (v.obs.dvl_beams @ c.T) * v.obs.dvl_ranges[ping][:, None]
    off[list(drop)] = np.nan
    return np.ascontiguousarray(off), v.obs.nav.pos[k, 2]


@pytest.mark.parametrize("nan_beams", list(RANGE_CASES), ids=list(RANGE_CASES))
def test_loglik_loose_matches_numpy(world, nan_beams):
    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 31])
    x8, _ = likelihood_particles(rng, nmap)
    x = np.ascontiguousarray(x8[:2])
    za = nmap.kernel_args()
    for ping in rng.integers(0, v.obs.dvl_ranges.shape[0], 3):
        off, up = loose_offsets(v, ping, RANGE_CASES[nan_beams])
        out = np.empty(x.shape[1])
        best = lik.loglik_loose(x, off, up, node_grid(nmap), PLAIN, 1.0, 5.0, out)
        ref, best_ref = lik.loglik_loose_numpy(x, off, up, za, None, PLAIN, 1.0, 5.0)
        assert_loglik_matches(out, best, ref, best_ref)


def test_loglik_loose_nan_row_is_no_beam(world):
    """Reference-free: a NaN offset row (no range) is the same as leaving the beam out."""
    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 32])
    x8, off_idx = likelihood_particles(rng, nmap)
    x = np.ascontiguousarray(x8[:2])
    full, up = loose_offsets(v, 300)
    with_nan, _ = loose_offsets(v, 300, drop=[2])
    out_nan = np.empty(x.shape[1])
    out_sub = np.empty(x.shape[1])
    grid = node_grid(nmap)
    b1 = lik.loglik_loose(x, with_nan, up, grid, PLAIN, 1.0, 5.0, out_nan)
    b2 = lik.loglik_loose(x, np.ascontiguousarray(full[[0, 1, 3]]), up, grid, PLAIN, 1.0, 5.0, out_sub)
    np.testing.assert_allclose(out_nan, out_sub, rtol=1e-12, atol=1e-12)
    assert b1 == pytest.approx(b2, rel=1e-12)
    # every footprint off the map: 3 beams x outside_sigma^2
    np.testing.assert_allclose(out_sub[off_idx], -0.5 * 3 * 25.0, rtol=1e-12)


# --------------------------------------------------------------------------------------
# weights
# --------------------------------------------------------------------------------------
def test_normalize_log_weights_extreme():
    rng = np.random.default_rng([KERNEL_SEED, 41])
    m = 5000
    logw = rng.uniform(-1e5, 0, m)
    logw[1234] = 0.0
    logw[17] = -1e-3
    w = np.empty(m)
    lml = rs.normalize_log_weights(logw, w)
    w_ref, lml_ref = rs.normalize_log_weights_numpy(logw)
    assert np.isfinite(w).all() and (w >= 0).all()
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(w, w_ref, rtol=1e-12, atol=1e-300)
    assert lml == pytest.approx(lml_ref, rel=1e-12)
    assert lml == pytest.approx(logsumexp(logw) - math.log(m), rel=1e-12)
    assert w[1234] == w.max()
    assert w[1234] / w[17] == pytest.approx(math.exp(1e-3), rel=1e-12)

    # all equally tiny: uniform, no underflow to 0/0
    w2 = np.empty(m)
    lml2 = rs.normalize_log_weights(np.full(m, -1e5), w2)
    np.testing.assert_allclose(w2, 1.0 / m, rtol=1e-12)
    assert lml2 == pytest.approx(-1e5, rel=1e-15)

    # invariant under a common shift (the loop subtracts the maximum)
    small = rng.uniform(-50, 0, m)
    wa, wb = np.empty(m), np.empty(m)
    la = rs.normalize_log_weights(small, wa)
    lb = rs.normalize_log_weights(small + 1e3, wb)
    np.testing.assert_allclose(wa, wb, rtol=1e-9, atol=1e-300)
    assert lb - la == pytest.approx(1e3, rel=1e-12)


def test_normalize_log_weights_minus_inf():
    """All weight on one particle: the others have log-weight -inf."""
    logw = np.full(64, -np.inf)
    logw[9] = -3.0
    w = np.empty(64)
    lml = rs.normalize_log_weights(logw, w)
    assert not np.isnan(w).any()
    assert w[9] == 1.0 and w.sum() == 1.0
    assert lml == pytest.approx(-3.0 - math.log(64), rel=1e-15)


def test_effective_sample_size():
    rng = np.random.default_rng([KERNEL_SEED, 42])
    m = 1000
    assert rs.effective_sample_size(np.full(m, 1.0 / m)) == pytest.approx(m, rel=1e-12)
    one = np.zeros(m)
    one[3] = 1.0
    assert rs.effective_sample_size(one) == 1.0
    w = rng.random(m) ** 4
    w /= w.sum()
    assert rs.effective_sample_size(w) == pytest.approx(1.0 / np.sum(w ** 2), rel=1e-12)
    assert 1.0 <= rs.effective_sample_size(w) <= m


# --------------------------------------------------------------------------------------
# resampling
# --------------------------------------------------------------------------------------
def weight_cases(rng, m):
    """Weight vectors from flat to spiky, with exact zeros."""
    cases = []
    for power in (0.0, 1.0, 4.0, 20.0):
        w = rng.random(m) ** power
        w[rng.random(m) < 0.2] = 0.0
        w[0] = max(w[0], 1e-3)
        cases.append(w / w.sum())
    logw = rng.normal(0, 30, m)  # a realistic converged-filter spike
    w = np.exp(logw - logw.max())
    cases.append(w / w.sum())
    return cases


@pytest.mark.parametrize("scheme", SCHEME_IDS)
def test_resample_indices_match_numpy(scheme):
    code = RESAMPLING[scheme]
    rng = np.random.default_rng([KERNEL_SEED, 51, code])
    for m in (1, 2, 7, 1000, 4099):
        for w in weight_cases(rng, m):
            for _ in range(3):
                u = rng.random(m)
                idx = np.empty(m, dtype=np.int64)
                rs.resample_indices(code, w, u, idx)
                ref = rs.resample_indices_numpy(code, w, u)
                np.testing.assert_array_equal(idx, ref, err_msg=f"m={m}")
                assert ((idx >= 0) & (idx < m)).all()
                assert (w[idx] > 0).all(), "a zero-weight particle was resampled"


@pytest.mark.parametrize("scheme", SCHEME_IDS)
def test_resample_all_weight_on_one(scheme):
    code = RESAMPLING[scheme]
    rng = np.random.default_rng([KERNEL_SEED, 52, code])
    m = 500
    for j in (0, 1, 250, m - 1):
        w = np.zeros(m)
        w[j] = 1.0
        idx = np.empty(m, dtype=np.int64)
        rs.resample_indices(code, w, rng.random(m), idx)
        assert (idx == j).all()


@pytest.mark.parametrize("u", [1e-6, 0.25, 0.5, 0.999])
def test_systematic_uniform_weights_is_identity(u):
    m = 1000
    idx = np.empty(m, dtype=np.int64)
    uni = np.full(m, u)
    rs.resample_indices(rs.SYSTEMATIC, np.full(m, 1.0 / m), uni, idx)
    np.testing.assert_array_equal(idx, np.arange(m))


def test_systematic_and_residual_counts():
    """Systematic gives floor(M w) or ceil(M w) copies of each particle; residual at least floor(M w)."""
    rng = np.random.default_rng([KERNEL_SEED, 53])
    m = 400
    for w in weight_cases(rng, m):
        lo = np.floor(m * w).astype(int)
        for _ in range(20):
            idx = np.empty(m, dtype=np.int64)
            rs.resample_indices(rs.SYSTEMATIC, w, rng.random(m), idx)
            counts = np.bincount(idx, minlength=m)
            assert ((counts >= lo) & (counts <= lo + 1)).all()
            rs.resample_indices(rs.RESIDUAL, w, rng.random(m), idx)
            counts = np.bincount(idx, minlength=m)
            assert (counts >= lo).all() and counts.sum() == m


@pytest.mark.parametrize("scheme", SCHEME_IDS)
def test_resample_counts_unbiased(scheme):
    """Statistical: every scheme's expected number of copies is M w (seeded, 4000 repetitions).

    The z-scores use the multinomial variance M w (1 - w), an upper bound for the other
    schemes; a scheme with a bias of even 0.1 copy per particle fails.
    """
    code = RESAMPLING[scheme]
    rng = np.random.default_rng([KERNEL_SEED, 54, code])
    m, reps = 20, 4000
    w = rng.dirichlet(np.full(m, 0.7))
    w[3] += 0.3  # one heavy particle
    w /= w.sum()
    counts = np.zeros(m)
    idx = np.empty(m, dtype=np.int64)
    for _ in range(reps):
        rs.resample_indices(code, w, rng.random(m), idx)
        counts += np.bincount(idx, minlength=m)
    mean = counts / reps
    se = np.sqrt(m * w * (1 - w) / reps)
    z = (mean - m * w) / np.maximum(se, 1e-12)
    assert np.abs(z).max() < 4.5, (mean - m * w)
    assert np.abs(mean - m * w).max() < 0.1


def test_apply_resample():
    rng = np.random.default_rng([KERNEL_SEED, 55])
    for rows in (N_TIGHT, 2):
        x0 = rng.normal(size=(rows, 333))
        idx = np.sort(rng.integers(0, 333, 333))  # duplicates, in place (aliasing would show)
        idx[:50] = 332
        x = x0.copy()
        rs.apply_resample(x, idx, np.empty_like(x))
        np.testing.assert_array_equal(x, x0[:, idx])


# --------------------------------------------------------------------------------------
# regularisation
# --------------------------------------------------------------------------------------
REG_COLS = np.array([E, N, YAW, BX, BZ], dtype=np.int64)


def cloud_for_jitter(rng, m):
    x = np.empty((m, N_TIGHT))
    x[:, E] = rng.uniform(1000, 1150, m)
    x[:, N] = rng.normal(500, 20, m)
    x[:, U] = rng.normal(-30, 0.1, m)
    x[:, PITCH] = rng.normal(0, 1e-3, m)
    x[:, ROLL] = rng.normal(0, 1e-3, m)
    x[:, YAW] = rng.normal(0.5, 0.5, m)
    x[:, BX] = rng.normal(0, 25 * DEG_PER_H, m)
    x[:, BZ] = rng.normal(1e-4, 25 * DEG_PER_H, m)
    return columns(x)


def test_roughen_matches_numpy():
    rng = np.random.default_rng([KERNEL_SEED, 61])
    x0 = cloud_for_jitter(rng, 777)
    noise = rng.standard_normal((REG_COLS.size, 777))
    x = x0.copy()
    rs.roughen(x, REG_COLS, 0.2, N_TIGHT, noise)
    np.testing.assert_allclose(x, rs.roughen_numpy(x0, REG_COLS, 0.2, N_TIGHT, noise), **TOL)
    untouched = [c for c in range(N_TIGHT) if c not in REG_COLS]
    np.testing.assert_array_equal(x[untouched], x0[untouched])


@pytest.mark.parametrize("h", [0.1, 0.5])
def test_shrink_jitter_matches_numpy(h):
    rng = np.random.default_rng([KERNEL_SEED, 62])
    x0 = cloud_for_jitter(rng, 777)
    noise = rng.standard_normal((REG_COLS.size, 777))
    x = x0.copy()
    rs.shrink_jitter(x, REG_COLS, h, noise)
    np.testing.assert_allclose(x, rs.shrink_jitter_numpy(x0, REG_COLS, h, noise), **TOL)
    untouched = [c for c in range(N_TIGHT) if c not in REG_COLS]
    np.testing.assert_array_equal(x[untouched], x0[untouched])


@pytest.mark.parametrize("h", [0.1, 0.5])
def test_shrink_jitter_preserves_mean_and_variance(h):
    """Liu-West: a x + (1 - a) mean + h std N(0, 1) keeps every jittered column's mean and
    variance, up to the sampling error of the noise (M = 400 000: ~5 standard errors)."""
    rng = np.random.default_rng([KERNEL_SEED, 63])
    m = 400_000
    x0 = cloud_for_jitter(rng, m)
    x = x0.copy()
    rs.shrink_jitter(x, REG_COLS, h, rng.standard_normal((REG_COLS.size, m)))
    a = math.sqrt(1 - h * h)
    for c in REG_COLS:
        sd = x0[c].std()
        assert abs(x[c].mean() - x0[c].mean()) < 5 * h * sd / math.sqrt(m)
        rel_se = math.sqrt((2 * h ** 4 + 4 * a * a * h * h) / m)
        assert abs(x[c].var() / x0[c].var() - 1) < 5 * rel_se
    # and the particles did move (by about h std)
    moved = np.abs(x[E] - x0[E]).mean() / x0[E].std()
    assert 0.5 * h < moved < 2 * h


def test_shrink_jitter_collapsed_cloud_stays_finite():
    """A cloud collapsed onto one particle (zero variance) is left in place, no NaN."""
    x = columns(np.tile(np.arange(N_TIGHT, dtype=float), (100, 1)))
    x0 = x.copy()
    rs.shrink_jitter(x, REG_COLS, 0.1, np.random.default_rng(0).standard_normal((REG_COLS.size, 100)))
    np.testing.assert_allclose(x, x0, rtol=1e-14, atol=1e-14)
    rs.roughen(x, REG_COLS, 0.2, N_TIGHT, np.random.default_rng(1).standard_normal((REG_COLS.size, 100)))
    np.testing.assert_allclose(x, x0, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("kind", sorted(REGULARISATION))
def test_regularise_draws_like_numpy(kind):
    """``regularise`` draws its noise a state at a time from the Generator it is given: the same as
    ``standard_normal((len(rows), M))`` from an identically seeded numpy Generator."""
    code = REGULARISATION[kind]
    rng = np.random.default_rng([KERNEL_SEED, 64])
    x0 = cloud_for_jitter(rng, 300)
    x = x0.copy()
    size = 0.2 if kind == "gordon" else 0.1
    rs.regularise(x, np.random.default_rng(99), code, REG_COLS, size, N_TIGHT)
    noise = np.random.default_rng(99).standard_normal((REG_COLS.size, 300))
    if code == rs.REG_NONE:
        expect = x0
    elif code == rs.REG_LIU_WEST:
        expect = rs.shrink_jitter_numpy(x0, REG_COLS, size, noise)
    else:
        expect = rs.roughen_numpy(x0, REG_COLS, size, N_TIGHT, noise)
    np.testing.assert_allclose(x, expect, **TOL)


# --------------------------------------------------------------------------------------
# estimate
# --------------------------------------------------------------------------------------
def run_estimate(x, w, yaw_col, yaw_ref):
    nc = x.shape[0]
    mean, var, cov = np.empty(nc), np.empty(nc), np.empty((2, 2))
    est_mod.weighted_estimate(x, w, yaw_col, yaw_ref, mean, var, cov)
    return mean, var, cov


def test_weighted_estimate_matches_numpy(world):
    rng = np.random.default_rng([KERNEL_SEED, 71])
    _, v, _ = world
    for _ in range(5):
        k = rng.integers(0, v.obs.nav.yaw.size)
        x = tight_cloud(rng, 500, v.obs.nav.pos[k, :2], v.obs.nav.pos[k, 2], v.obs.nav.pitch[k], v.obs.nav.roll[k], v.obs.nav.yaw[k])
        w = rng.random(500) ** 3
        w /= w.sum()
        got = run_estimate(x, w, YAW, v.obs.nav.yaw[k])
        ref = est_mod.weighted_estimate_numpy(x, w, YAW, v.obs.nav.yaw[k])
        for a, b in zip(got, ref):
            np.testing.assert_allclose(a, b, **TOL)
        # the east/north covariance is the ordinary weighted covariance
        np.testing.assert_allclose(got[2], np.cov(x[:2], aweights=w, bias=True), rtol=1e-9)
        xl = np.ascontiguousarray(x[:2])
        got = run_estimate(xl, w, -1, 0.0)
        ref = est_mod.weighted_estimate_numpy(xl, w, -1, 0.0)
        for a, b in zip(got, ref):
            np.testing.assert_allclose(a, b, **TOL)


@pytest.mark.parametrize("yaw_ref_deg", [180.0, -170.0, 175.0, 130.0])
def test_weighted_estimate_heading_across_180(yaw_ref_deg):
    """A heading cloud around 180 deg, stored half as +pi - a and half as -pi + a: the mean must be
    near 180 deg (a naive average gives ~0 deg) and the yaw variance small, not ~pi^2."""
    rng = np.random.default_rng([KERNEL_SEED, 72])
    m = 2000
    x = np.zeros((N_TIGHT, m))
    yaw = math.pi + rng.normal(0, math.radians(5), m)
    x[YAW] = (yaw + math.pi) % (2 * math.pi) - math.pi  # wrapped: straddles +-pi
    assert (x[YAW] > 0).mean() == pytest.approx(0.5, abs=0.05)
    w = rng.random(m)
    w /= w.sum()
    assert abs(w @ x[YAW]) < 0.5  # what a naive weighted mean would give: ~0
    yaw_ref = math.radians(yaw_ref_deg)
    mean, var, _ = run_estimate(x, w, YAW, yaw_ref)
    ref_mean, ref_var, _ = est_mod.weighted_estimate_numpy(x, w, YAW, yaw_ref)
    np.testing.assert_allclose(mean, ref_mean, **TOL)
    np.testing.assert_allclose(var, ref_var, **TOL)
    heading = float(yaw_to_heading_deg(mean[YAW]))
    assert abs(heading - 180.0) < 1.0
    assert abs(mean[YAW] - yaw_ref) <= math.pi  # unwrapped around the reference
    assert math.sqrt(var[YAW]) == pytest.approx(math.radians(5), rel=0.1)


def test_weighted_estimate_one_particle():
    """All weight on one particle: the estimate is that particle, variances zero, no NaN."""
    rng = np.random.default_rng([KERNEL_SEED, 73])
    x = rng.normal(size=(N_TIGHT, 50))
    w = np.zeros(50)
    w[7] = 1.0
    mean, var, cov = run_estimate(x, w, YAW, x[YAW, 7])
    np.testing.assert_allclose(mean, x[:, 7], atol=1e-12)
    assert (var >= 0).all()
    np.testing.assert_allclose(var, 0.0, atol=1e-12)
    np.testing.assert_allclose(cov, 0.0, atol=1e-12)


@pytest.mark.parametrize("spread", [1e-3, 1.0])
def test_weighted_estimate_tight_cloud_at_map_coordinates(spread):
    """A converged cloud (std ``spread`` m) kilometres from the origin, with an outlier as the first
    particle: the variances keep their precision (no cancellation in E[x^2] - E[x]^2) and are
    never negative."""
    rng = np.random.default_rng([KERNEL_SEED, 74])
    m = 3000
    x = np.zeros((N_TIGHT, m))
    x[E] = 2987.3 + rng.normal(0, spread, m)
    x[N] = 1133.9 + rng.normal(0, spread, m)
    x[YAW] = 2.5 + rng.normal(0, 1e-3, m)
    x[[E, N], 0] += 50.0 * spread  # the first particle (the kernel's shift) is an outlier
    w = rng.random(m)
    w[0] = 1e-6
    w /= w.sum()
    mean, var, cov = run_estimate(x, w, YAW, 2.4)
    ref_mean, ref_var, ref_cov = est_mod.weighted_estimate_numpy(x, w, YAW, 2.4)
    np.testing.assert_allclose(mean, ref_mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(var[[E, N, YAW]], ref_var[[E, N, YAW]], rtol=1e-6)
    np.testing.assert_allclose(cov, ref_cov, rtol=1e-6, atol=1e-9 * spread ** 2)
    assert (var >= 0).all()


# --------------------------------------------------------------------------------------
# branch-free trigonometry, logarithm and exponential (vectorised loops)
# --------------------------------------------------------------------------------------
def test_sin_cos_matches_numpy():
    """``trig.sin_cos`` (branch free, fdlibm polynomials) against numpy's sin and cos: within 2 ulp
    of 1 over the angles the kernels meet (offsets up to a few turns), exact at 0."""
    from tanbench.filters import trig

    rng = np.random.default_rng([KERNEL_SEED, 81])
    d = np.concatenate([np.linspace(-0.3, 0.3, 6001), rng.uniform(-40.0, 40.0, 20000),
                        [0.0, -0.0, 1e-300, math.pi / 4, -math.pi / 4, math.pi / 2, math.pi, 3.0, -7.0]])
    s, c = np.empty_like(d), np.empty_like(d)
    trig_pass(d, s, c)
    assert np.abs(s - np.sin(d)).max() < 4.5e-16 and np.abs(c - np.cos(d)).max() < 4.5e-16
    assert trig.sin_cos(0.0) == (0.0, 1.0)
    for ref, a in zip(rng.uniform(-7, 7, 2000), rng.uniform(-0.5, 0.5, 2000)):
        s1, c1 = trig.sin_cos_about(math.sin(ref), math.cos(ref), a)
        assert abs(s1 - math.sin(ref + a)) < 1e-15 and abs(c1 - math.cos(ref + a)) < 1e-15


def test_sin_cos_of_wound_angles_is_a_bounded_pseudo_random_direction():
    """Beyond ``trig.WOUND`` (1e5 rad) the heading of a lost filter can wind up without bound
    (range-scaled roughening): sin_cos must still give a unit vector, spread evenly over the
    circle (as the C library's exact reduction of such angles is, for all a filter can tell),
    and NaN for NaN and infinities, as numpy's. At and below WOUND it is numpy's value."""
    from tanbench.filters.trig import WOUND

    rng = np.random.default_rng([KERNEL_SEED, 82])
    d = np.concatenate([rng.uniform(WOUND * 1.0000001, 1e12, 40000), -np.logspace(5.1, 300, 20000)])
    s, c = np.empty_like(d), np.empty_like(d)
    trig_pass(d, s, c)
    assert np.abs(s * s + c * c - 1.0).max() < 1e-15
    counts = np.histogram(np.arctan2(s, c), bins=12, range=(-math.pi, math.pi))[0]
    assert counts.min() > 0.9 * d.size / 12 and counts.max() < 1.1 * d.size / 12
    edge = np.array([WOUND, -WOUND, np.nextafter(WOUND, 0.0)])
    trig_pass(edge, s[:3], c[:3])
    assert np.abs(s[:3] - np.sin(edge)).max() < 1e-11 and np.abs(c[:3] - np.cos(edge)).max() < 1e-11
    bad = np.array([np.nan, np.inf, -np.inf])
    trig_pass(bad, s[:3], c[:3])
    assert np.isnan(s[:3]).all() and np.isnan(c[:3]).all()


def test_sin_cos_near_and_the_exact_conversion_give_the_same_bits():
    """The loops take ``trig.sin_cos_near`` when ``wound_count`` finds no angle beyond WOUND: it is
    ``sin_cos`` bit for bit there; ``vecmath.exact_float_53`` is ``np.float64`` of an integer below
    2^53, bit for bit (its numpy twin)."""
    import numba as nb

    from tanbench.filters.trig import WOUND, sin_cos_near, wound_count
    from tanbench.filters.vecmath import exact_float_53

    @nb.njit(cache=True)
    def near_pass(d, s, c):
        for j in range(d.shape[0]):
            s[j], c[j] = sin_cos_near(d[j])

    @nb.njit(cache=True)
    def exact_pass(v, out):
        for j in range(v.shape[0]):
            out[j] = exact_float_53(v[j])

    rng = np.random.default_rng([KERNEL_SEED, 83])
    d = np.concatenate([rng.uniform(-40.0, 40.0, 20000), rng.uniform(-WOUND, WOUND, 20000), [WOUND, -WOUND, 0.0]])
    s, c, s2, c2 = (np.empty_like(d) for _ in range(4))
    trig_pass(d, s, c)
    near_pass(d, s2, c2)
    assert np.array_equal(s, s2) and np.array_equal(c, c2)
    assert wound_count(d, 0.0, 0.0) == 0
    assert wound_count(np.array([0.0, np.nan, 2 * WOUND, -0.5]), 0.5, 0.0) == 2
    v = np.concatenate([rng.integers(0, 2**53, 50000), [0, 1, 2**32 - 1, 2**32, 2**53 - 1]]).astype(np.int64)
    out = np.empty(v.size)
    exact_pass(v, out)
    assert np.array_equal(out, v.astype(np.float64))


def test_blocks_with_wound_angles_give_the_bits_of_sin_cos():
    """A block with wound angles (beyond WOUND, NaN, infinite: a filter that lost its heading) runs
    the near loops too: the attitude matrices and the Euler step on the offsets unwound
    (``trig.unwound``), the tight propagation with the wound particles' horizontal step taken again.
    Each equals, bit for bit, one loop of ``trig.sin_cos`` over every angle (the loops these replace,
    :func:`_sin_cos_loops`), with wound angles in the block and without; ``unwound`` + ``sin_cos_near``
    is ``sin_cos`` for any double."""
    from tanbench.filters import likelihood as lk
    from tanbench.filters.trig import WOUND, sin_cos_near, unwound

    rng = np.random.default_rng([KERNEL_SEED, 84])
    d = np.concatenate([rng.uniform(-40.0, 40.0, 2000), np.logspace(5.0, 300.0, 4000),
                        -np.logspace(5.0, 300.0, 4000), [WOUND, -WOUND, np.nextafter(WOUND, np.inf), 0.0, -0.0],
                        [np.nan, np.inf, -np.inf]])
    s, c = np.empty_like(d), np.empty_like(d)
    trig_pass(d, s, c)
    near = np.array([sin_cos_near(unwound(v)) for v in d])
    assert np.array_equal(near[:, 0], s, equal_nan=True) and np.array_equal(near[:, 1], c, equal_nan=True)
    attitude_ref, propagate_ref, euler_ref = _sin_cos_loops()
    m, lo, n = 4000, 1000, 2500
    att = attitude_reference(0.01, -0.02, 0.5)
    inc, noise, u = rng.normal(0.0, 1.0, 12), rng.standard_normal((6, n)), rng.normal(0.0, 1.0, 4)
    for wound in (False, True):
        x = rng.normal(0.0, 0.3, (8, m))
        if wound:  # wound headings (and, to cover every row, pitches and rolls)
            picks = rng.choice(np.arange(lo, lo + n), 60, replace=False)
            x[YAW, picks[:40]] = rng.choice([-1.0, 1.0], 40) * np.logspace(5.01, 17, 40)
            x[YAW, picks[40:43]] = [np.nan, np.inf, -np.inf]
            x[PITCH, picks[43:50]] = -3e6
            x[ROLL, picks[50:]] = 2e9
        blk = slice(lo, lo + n)
        dcm, dcm_ref = np.empty((9, n)), np.empty((9, n))
        lk.attitude_matrices(x, lo, att, dcm)
        attitude_ref(x[PITCH, blk].copy(), x[ROLL, blk].copy(), x[YAW, blk].copy(), att, dcm_ref)
        assert np.array_equal(dcm, dcm_ref, equal_nan=True)
        for move, ref, args in ((prop.propagate_tight, propagate_ref, (inc, 0.3, noise, 0.1, 0.01, 1e-3, 2)),
                                (prop.propagate_tight_euler, euler_ref, (u, 1.0, inc, noise, 0.1, 0.01, 1e-3, 2))):
            x1, x2, dist1, dist2 = x.copy(), x.copy(), np.zeros((2, n)), np.zeros((2, n))
            if move is prop.propagate_tight:
                move(x1, *args, dist1, 0.2, lo)
                ref(x2, *args, dist2, 0.2, lo)
            else:
                move(x1, *args, dist1, att, lo)
                ref(x2, *args, dist2, att, lo)
            assert np.array_equal(x1, x2, equal_nan=True) and np.array_equal(dist1, dist2, equal_nan=True)
            assert np.isnan(x1).any() == wound
    for yaw in (0.3, -2e6, 5e15, np.nan):  # the loose loops' corrected navigation: one particle, no noise
        one = rng.normal(0.0, 1.0, (8, 1))
        one[YAW, 0] = yaw
        two = one.copy()
        prop.dead_reckon(one, inc, 0.25)
        propagate_ref(two, inc, 0.25, np.zeros((6, 1)), 0.0, 0.0, 0.0, prop.DIST_NONE, np.zeros((2, 1)), 0.0, 0)
        assert np.array_equal(one, two, equal_nan=True)


def _sin_cos_loops():
    """The attitude matrices, the tight propagation and its Euler step as single loops of
    ``trig.sin_cos`` (the same arithmetic and fastmath flags as the kernels; the references of
    the wound blocks' paths)."""
    import numba as nb

    from tanbench.fastmath import FASTMATH
    from tanbench.filters.trig import sin_cos

    @nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
    def about(s_ref, c_ref, d):
        s, c = sin_cos(d)
        return s_ref * c + c_ref * s, c_ref * c - s_ref * s

    @nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
    def angles(pitch, roll, yaw, att):
        st, ct = about(att[1], att[2], pitch - att[0])
        sg, cg = about(att[4], att[5], roll - att[3])
        sp, cp = about(att[7], att[8], yaw - att[6])
        return st, ct, sg, cg, sp, cp

    @nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
    def attitude_ref(pitch, roll, yaw, att, dcm):
        for j in range(dcm.shape[1]):
            st, ct, sg, cg, sp, cp = angles(pitch[j], roll[j], yaw[j], att)
            dcm[0, j], dcm[1, j], dcm[2, j] = cg * cp - st * sg * sp, -ct * sp, sg * cp + st * cg * sp
            dcm[3, j], dcm[4, j], dcm[5, j] = cg * sp + st * sg * cp, ct * cp, sg * sp - st * cg * cp
            dcm[6, j], dcm[7, j], dcm[8, j] = -ct * sg, st, ct * cg

    @nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
    def move(x, j, noise, dist, k, de, dn, dyaw, inc, sig_up, sig_att, dist_mode):
        x[E, j] += de
        x[N, j] += dn
        x[U, j] += inc[incmod.DUP] + sig_up * noise[2, k]
        x[PITCH, j] += inc[incmod.DPITCH] + sig_att * noise[3, k]
        x[ROLL, j] += inc[incmod.DROLL] + sig_att * noise[4, k]
        x[YAW, j] += dyaw + sig_att * noise[5, k]
        if dist_mode == prop.DIST_NAVIGATION:
            dist[0, k] = inc[incmod.D0E] - de
            dist[1, k] = inc[incmod.D0N] - dn

    @nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
    def propagate_ref(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist, yaw_off, lo):
        s_off, c_off = math.sin(yaw_off), math.cos(yaw_off)
        for k in range(noise.shape[1]):
            j = lo + k
            bx, bz = x[BX, j], x[BZ, j]
            s, c = about(s_off, c_off, (x[YAW, j] - yaw_nav0) - yaw_off)
            ue = inc[incmod.D0E] + bx * inc[incmod.JAXE] - bz * inc[incmod.JAZE]
            un = inc[incmod.D0N] + bx * inc[incmod.JAXN] - bz * inc[incmod.JAZN]
            move(x, j, noise, dist, k, c * ue - s * un + sig_pos * noise[0, k], s * ue + c * un + sig_pos * noise[1, k],
                 inc[incmod.DYAW] + bx * inc[incmod.SX] - bz * inc[incmod.SZ], inc, sig_up, sig_att, dist_mode)

    @nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
    def euler_ref(x, u, dt, inc, noise, sig_pos, sig_up, sig_att, dist_mode, dist, att, lo):
        vx, vy, wx, wz = u[incmod.EU_VX] * dt, u[incmod.EU_VY] * dt, u[incmod.EU_WX], u[incmod.EU_WZ]
        for k in range(noise.shape[1]):
            j = lo + k
            st, ct, sg, cg, sp, cp = angles(x[PITCH, j], x[ROLL, j], x[YAW, j], att)
            de = (cg * cp - st * sg * sp) * vx - ct * sp * vy + sig_pos * noise[0, k]
            dn = (cg * sp + st * sg * cp) * vx + ct * cp * vy + sig_pos * noise[1, k]
            yaw_rate = (-sg * (wx - x[BX, j]) + cg * (wz - x[BZ, j])) / ct
            move(x, j, noise, dist, k, de, dn, yaw_rate * dt, inc, sig_up, sig_att, dist_mode)

    return attitude_ref, propagate_ref, euler_ref


def _trig_pass():
    import numba as nb

    from tanbench.filters.trig import sin_cos

    @nb.njit(cache=True)
    def run(d, s, c):
        for j in range(d.shape[0]):
            s[j], c[j] = sin_cos(d[j])

    return run


trig_pass = _trig_pass()


def _vecmath_passes():
    import numba as nb

    from tanbench.filters.vecmath import exp_nonpositive, log_positive

    @nb.njit(cache=True)
    def logs(x, out):
        for j in range(x.shape[0]):
            out[j] = log_positive(x[j])

    @nb.njit(cache=True)
    def exps(x, out):
        for j in range(x.shape[0]):
            out[j] = exp_nonpositive(x[j])

    return logs, exps


log_pass, exp_pass = _vecmath_passes()


def test_log_and_exp_match_numpy():
    """``vecmath.log_positive`` and ``exp_nonpositive`` (branch free, fdlibm's algorithms) against
    numpy's log and exp: within 1 ulp over the whole normal range; +inf, NaN, 0 and -inf as numpy,
    and 0 below -708 (where exp leaves the normal range)."""
    rng = np.random.default_rng([KERNEL_SEED, 82])
    x = np.concatenate([np.exp(rng.uniform(-700, 700, 100000)), 1.0 + rng.uniform(-1e-3, 1e-3, 10000),
                        [1.0, 2.0, np.nextafter(1.0, 2.0), np.nextafter(1.0, 0.0), 2.2250738585072014e-308,
                         1.7976931348623157e308]])
    out = np.empty_like(x)
    log_pass(x, out)
    ref = np.log(x)
    assert (np.abs(out - ref) <= np.spacing(np.abs(ref))).all()
    special = np.array([np.inf, np.nan])
    log_pass(special, out[:2])
    assert out[0] == np.inf and np.isnan(out[1])
    y = np.concatenate([-np.exp(rng.uniform(-30, math.log(708.0), 100000)), [0.0, -0.0, -1e-300, -708.0]])
    out = np.empty_like(y)
    exp_pass(y, out)
    ref = np.exp(y)
    assert (np.abs(out - ref) <= np.spacing(ref)).all()
    assert out[-4] == 1.0
    special = np.array([-np.inf, -709.0, -1e5, np.nan])
    exp_pass(special, out[:4])
    assert out[0] == 0.0 and out[1] == 0.0 and out[2] == 0.0 and np.isnan(out[3])


def test_sorted_uniforms_are_uniform_order_statistics():
    """Multinomial resampling sorts its M uniforms by drawing their order statistics directly:
    ascending, in (0, 1], equal to the numpy reference, and distributed as sorted uniforms
    (the k-th of M has mean k / (M + 1); Kolmogorov-Smirnov on the pooled values, p > 0.001)."""
    from scipy import stats

    rng = np.random.default_rng([KERNEL_SEED, 56])
    m, reps = 200, 2000
    pooled, means = [], np.zeros(m)
    for _ in range(reps):
        u = rng.random(m)
        out = np.empty(m)
        rs.sorted_uniforms(u, out)
        np.testing.assert_allclose(out, rs.sorted_uniforms_numpy(u), rtol=1e-14)
        assert (np.diff(out) >= 0).all() and out[0] > 0 and out[-1] <= 1
        pooled.append(out)
        means += out / reps
    np.testing.assert_allclose(means, np.arange(1, m + 1) / (m + 1), atol=5 * 0.5 / math.sqrt(reps * m))
    assert stats.kstest(np.concatenate(pooled), "uniform").pvalue > 1e-3


@pytest.mark.parametrize("nan_beams", ["all", "one-nan", "two-nan", "all-nan"])
def test_fit_without_worst_beam_matches_numpy(world, nan_beams):
    """loose_turned.fit_without_worst_beam (docs/filters.md 11.2): the most likely particle's d^2 / v per
    beam, its worst beam left out when 3 or more have a range; against the numpy likelihood reference, beam by
    beam, and the reference's last step."""
    from tanbench.filters import loose_turned as lt

    _, v, nmap = world
    rng = np.random.default_rng([KERNEL_SEED, 29, len(RANGE_CASES[nan_beams])])
    cloud, _ = likelihood_particles(rng, nmap, m=64)
    grid, za = node_grid(nmap), nmap.kernel_args()
    beams = v.obs.dvl_beams
    consts = lik.beam_constants(1.0, 1.0, 5.0)
    one = lt.OneParticle(np.zeros((N_TIGHT, 1)), np.empty((1, 3)), lik.new_likelihood_work(1, 4 * grid.grids),
                         np.zeros((2, 1)), np.empty(1))
    for ping in rng.integers(0, v.obs.dvl_ranges.shape[0], 3):
        ranges = v.obs.dvl_ranges[ping].copy()
        ranges[RANGE_CASES[nan_beams]] = np.nan
        if nan_beams == "one-nan":
            ranges[2] = ranges[2] + 40.0  # a wild range on one of the three beams left
        ll, _ = lik.loglik_tight_numpy(cloud, beams, ranges, za, None, PLAIN, 1.0, 5.0, None, 0.1)
        att = attitude_reference(*nav_attitude(v, ping))
        got = lt.fit_without_worst_beam(cloud, ll, lik.beam_vectors(beams, ranges), grid, PLAIN, consts, att, False,
                                        one)
        j = int(np.argmax(ll))
        per_beam = [lik.loglik_tight_numpy(cloud[:, [j]], beams[[b]], ranges[[b]], za, None, PLAIN, 1.0, 5.0, None,
                                           0.1)[1] for b in range(beams.shape[0]) if not np.isnan(ranges[b])]
        want = lt.fit_without_worst_beam_numpy(per_beam)
        if np.isinf(want):
            assert np.isinf(got)
        else:
            assert got == pytest.approx(want, rel=1e-9, abs=1e-12)
        if nan_beams == "one-nan":  # the wild beam is the one left out
            assert want < max(per_beam)
