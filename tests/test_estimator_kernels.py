"""Kernels of the point-mass filter, the iterated EKF, TERCOM and the marginalized PF against their
plain-numpy references (same inputs, agreement to 1e-9), plus reference-free properties where a
reference could share a kernel's mistake (a blur keeps the mass, re-gridding onto the same grid is
the identity, the IEKF's first pass is the textbook EKF update, TERCOM finds a known offset, the
MPF's Sherman-Morrison likelihood is the dense Gaussian density).

Inputs: a rough random 10 m map (fixed seed) and random states, beams and ranges.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tanbench.filters import ekf, mpf, pmf, tercom
from tanbench.navigation.increments import N_INCREMENTS, SZ
from tanbench.terrain.grid import Map

TOL = dict(rtol=1e-9, atol=1e-9)
SEED = 20261201


@pytest.fixture(scope="module")
def rough_map():
    """A smooth random seafloor, 10 m spacing, 2 km square (Gaussian-filtered white noise)."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(SEED)
    z = gaussian_filter(rng.normal(0, 1, (201, 201)), 4.0)
    z = -80.0 + 12.0 * z / z.std()
    return Map(z, 0.0, 0.0, 10.0, 10.0)


@pytest.fixture
def rng():
    return np.random.default_rng(SEED + 1)


def beam_offsets(rng, k=1, m=4, nan_rows=()):
    """(k, m, 3) beam vectors times ranges: 30 deg Janus beams of 40-60 m, some without a range."""
    az = np.radians([0, 90, 180, 270])[:m] + rng.uniform(-0.2, 0.2, (k, m))
    r = rng.uniform(40, 60, (k, m))
    o = np.stack([0.5 * r * np.sin(az), 0.5 * r * np.cos(az), -math.sqrt(0.75) * r], axis=-1)
    for kk, i in nan_rows:
        o[kk, i] = np.nan
    return o


# ---------------------------------------------------------------- point-mass filter
def test_pmf_grid_kernels_match_numpy(rng):
    n = 17
    out = np.empty((2, n * n))
    pmf.grid_nodes(100.5, -20.0, 2.5, n, out)
    np.testing.assert_allclose(out, pmf.grid_nodes_numpy(100.5, -20.0, 2.5, n), **TOL)
    p = rng.random((n, n))
    for sigma in (0.0, 0.3, 1.7):
        q = p.copy()
        pmf.blur_separable(q, sigma, np.empty_like(q))
        np.testing.assert_allclose(q, pmf.blur_separable_numpy(p, sigma), **TOL)
    got = np.empty_like(p)
    pmf.resample_grid(p, 10.0, 5.0, 2.0, 13.3, 2.1, 1.1, got)
    np.testing.assert_allclose(got, pmf.resample_grid_numpy(p, 10.0, 5.0, 2.0, 13.3, 2.1, 1.1), **TOL)
    np.testing.assert_allclose(pmf.slice_moments(p, 3.0, 4.0, 1.5), pmf.slice_moments_numpy(p, 3.0, 4.0, 1.5),
                               **TOL)
    stack = rng.random((4, n, n))
    centres = rng.uniform(-5, 5, (4, 2))
    mixed = np.empty_like(stack)
    pmf.mix_headings(stack, centres, 1.3, 0.1, np.empty((n, n)), mixed)
    np.testing.assert_allclose(mixed, pmf.mix_headings_numpy(stack, centres, 1.3, 0.1), **TOL)


def test_pmf_blur_and_regrid_properties(rng):
    """A blur away from the edges keeps the mass and adds sigma^2 of variance per axis;
    re-gridding onto the same grid changes nothing."""
    n = 41
    p = np.zeros((n, n))
    p[20, 20] = 1.0
    pmf.blur_separable(p, 2.0, np.empty_like(p))
    m, me, mn, ve, vn, cen = pmf.slice_moments(p, 0.0, 0.0, 1.0)
    assert m == pytest.approx(1.0, abs=1e-12)
    assert (me, mn) == (pytest.approx(0.0, abs=1e-12), pytest.approx(0.0, abs=1e-12))
    assert ve == pytest.approx(4.0, rel=0.02) and vn == pytest.approx(4.0, rel=0.02)
    q = rng.random((n, n))
    same = np.empty_like(q)
    pmf.resample_grid(q, 7.0, 8.0, 2.0, 7.0, 8.0, 2.0, same)
    np.testing.assert_allclose(same, q, **TOL)


# ---------------------------------------------------------------- iterated EKF
def test_ekf_kernels_match_numpy(rough_map, rng):
    zargs = rough_map.kernel_args()
    for e, n, step in [(500.3, 700.1, 10.0), (1234.5, 98.7, 37.0), (5.0, 5.0, 10.0)]:
        np.testing.assert_allclose(ekf.terrain_slope(*zargs, e, n, step),
                                   ekf.terrain_slope_numpy(*zargs, e, n, step), **TOL, equal_nan=True)
    x = np.array([800.0, 900.0, 0.3, 1e-4])
    a = rng.normal(size=(4, 4))
    p = a @ a.T + np.diag([100.0, 100.0, 0.1, 1e-8])
    xk, pk = x.copy(), p.copy()
    ekf.ekf_predict(xk, pk, 1.5, -0.7, 0.9, 0.01, 1e-6, 1e-12)
    xr, pr = ekf.ekf_predict_numpy(x, p, 1.5, -0.7, 0.9, 0.01, 1e-6, 1e-12)
    np.testing.assert_allclose(xk, xr, **TOL)
    np.testing.assert_allclose(pk, pr, **TOL)
    offs = beam_offsets(rng, nan_rows=[(0, 2)])[0]
    up = -20.0
    p = np.diag([400.0, 400.0, 0.05, 1e-9])
    for iterations in (1, 3):
        xk, pk = x.copy(), p.copy()
        nis, used = ekf.iekf_update(xk, pk, offs, up, zargs, 10.0, 1.0, iterations, 1e9)
        xr, pr, nis_r, used_r = ekf.iekf_update_numpy(x, p, offs, up, zargs, 10.0, 1.0, iterations, 1e9)
        assert used == used_r == 3
        assert nis == pytest.approx(nis_r, rel=1e-9)
        np.testing.assert_allclose(xk, xr, **TOL)
        np.testing.assert_allclose(pk, pr, **TOL)


def test_iekf_first_pass_is_the_ekf_update_and_the_gate_holds(rough_map, rng):
    """One iteration is x + K nu, P - K H P with H the slope rows; a gate below the NIS changes nothing."""
    zargs = rough_map.kernel_args()
    offs = beam_offsets(rng)[0]
    x = np.array([1000.0, 1000.0, 0.0, 0.0])
    p = np.diag([25.0, 25.0, 1e-4, 1e-10])
    hm = np.zeros((4, 4))
    nu = np.zeros(4)
    rv = np.zeros(4)
    step = 10.0
    ekf.beam_linearisation(x, offs, -20.0, zargs, step, 1.0, hm, nu, rv)
    g = -hm  # d h / d x
    k = p @ g.T @ np.linalg.inv(g @ p @ g.T + np.diag(rv))
    xk, pk = x.copy(), p.copy()
    nis, _ = ekf.iekf_update(xk, pk, offs, -20.0, zargs, step, 1.0, 1, 1e9)
    np.testing.assert_allclose(xk, x + k @ nu, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(pk, (np.eye(4) - k @ g) @ p, rtol=1e-7, atol=1e-12)
    xg, pg = x.copy(), p.copy()
    ekf.iekf_update(xg, pg, offs, -20.0 + 50.0, zargs, step, 1.0, 3, 1.0)
    np.testing.assert_array_equal(xg, x)
    np.testing.assert_array_equal(pg, p)


# ---------------------------------------------------------------- TERCOM
def test_tercom_surface_matches_numpy_and_finds_a_known_offset(rough_map, rng):
    zargs = rough_map.kernel_args()
    # a profile along a curved track, measured on the map itself, shifted by (+13, -7) m and turned 4 deg
    t = np.linspace(0, 1, 60)
    te = 900 + 120 * t
    tn = 1000 + 40 * np.sin(3 * t)
    truth_h = rough_map.elevation(te, tn) + 3.0  # a constant bias: the demeaned scores ignore it
    ang = math.radians(-4.0)
    pivot = np.array([te[-1], tn[-1]])
    rel = np.stack([te, tn], 1) - pivot
    rot = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
    shown = pivot + rel @ rot.T + [-13.0, 7.0]
    deltas = np.radians([-8.0, -4.0, 0.0, 4.0, 8.0])
    half = 20
    msd = np.empty((5, 2 * half + 1, 2 * half + 1))
    mad = np.empty_like(msd)
    pe, pn = np.ascontiguousarray(shown[:, 0]), np.ascontiguousarray(shown[:, 1])
    tercom.profile_surface(pe, pn, truth_h, pe[-1], pn[-1], half, 1.0, deltas, zargs, msd, mad)
    msd_r, mad_r = tercom.profile_surface_numpy(pe, pn, truth_h, pe[-1], pn[-1], half, 1.0, deltas, zargs)
    np.testing.assert_allclose(msd, msd_r, **TOL)
    np.testing.assert_allclose(mad, mad_r, **TOL)
    d, i, j = np.unravel_index(np.argmin(msd), msd.shape)
    assert deltas[d] == pytest.approx(math.radians(4.0))
    assert (j - half, i - half) == (13, -7)
    assert msd.min() < 1e-6
    mom = tercom.surface_likelihood_moments(msd, deltas, half, 1.0, 30, 1.0)
    np.testing.assert_allclose(mom, tercom.surface_likelihood_moments_numpy(msd, deltas, half, 1.0, 30, 1.0),
                               rtol=1e-9, atol=1e-12)
    assert mom[0] == pytest.approx(13.0, abs=0.5) and mom[1] == pytest.approx(-7.0, abs=0.5)


def test_tercom_surface_off_map_is_infinite(rough_map):
    zargs = rough_map.kernel_args()
    pe = np.array([5.0, 6.0])
    pn = np.array([5.0, 6.0])
    msd = np.empty((1, 3, 3))
    mad = np.empty_like(msd)
    tercom.profile_surface(pe, pn, np.array([-80.0, -80.0]), 5.0, 5.0, 1, 10.0, np.zeros(1), zargs, msd, mad)
    assert np.isinf(msd[0, 0, 0]) and np.isfinite(msd[0, 1, 1])


# ---------------------------------------------------------------- marginalized PF
def mpf_cloud(rng, m=64):
    """An MPF cloud (7, M), a column per particle."""
    x = np.empty((mpf.N_MPF, m))
    x[mpf.E] = rng.uniform(600, 1400, m)
    x[mpf.N] = rng.uniform(600, 1400, m)
    x[mpf.PSI] = 0.4 + rng.normal(0, 0.5, m)
    x[mpf.B] = rng.normal(0, 1, m)
    x[mpf.PB] = rng.uniform(0.1, 4.0, m)
    x[mpf.EPS] = rng.normal(0, 1e-4, m)
    x[mpf.PEPS] = rng.uniform(1e-10, 1e-8, m)
    return x


def test_mpf_kernels_match_numpy(rough_map, rng):
    zargs = rough_map.kernel_args()
    x = mpf_cloud(rng)
    x[mpf.E, 0] = 1.0  # footprints off the map
    inc = rng.normal(0, 1, N_INCREMENTS)
    inc[SZ] = 0.98
    noise = rng.standard_normal((3, x.shape[1]))
    xk = x.copy()
    mpf.mpf_propagate(xk, inc, 0.35, noise, 0.07, 1e-7, 1e-12, 1e-6)
    np.testing.assert_allclose(xk, mpf.mpf_propagate_numpy(x, inc, 0.35, noise, 0.07, 1e-7, 1e-12, 1e-6), **TOL)
    offs = beam_offsets(rng, nan_rows=[(0, 1)])[0]
    xl = x.copy()
    out = np.empty(x.shape[1])
    best = mpf.mpf_loglik_update(xl, offs, -20.0, 0.4, *zargs, 1.0, 5.0, out)
    ll_r, best_r, x_r = mpf.mpf_loglik_update_numpy(x, offs, -20.0, 0.4, *zargs, 1.0, 5.0)
    np.testing.assert_allclose(out, ll_r, **TOL)
    assert best == pytest.approx(best_r, rel=1e-9)
    np.testing.assert_allclose(xl, x_r, **TOL)


def test_mpf_depth_bias_kalman_filter_finds_the_bias(rough_map, rng):
    """Particles on the truth, beams measured with a 2.5 m depth bias: the per-particle KF moves to it as the
    Gaussian posterior does and its variance shrinks as 1 / (1 / P0 + k m / sigma^2)."""
    zargs = rough_map.kernel_args()
    x = mpf_cloud(rng, 8)
    x[mpf.PSI] = 0.0
    x[mpf.B] = 0.0
    x[mpf.PB] = 4.0
    out = np.empty(8)
    for k in range(20):
        offs = beam_offsets(rng)[0]
        # nu = up + o_up - h = bias, with up = -20 m
        offs[:, 2] = rough_map.elevation(x[mpf.E, 0] + offs[:, 0], x[mpf.N, 0] + offs[:, 1]) + 20.0 + 2.5
        x[mpf.E] = x[mpf.E, 0]
        x[mpf.N] = x[mpf.N, 0]
        mpf.mpf_loglik_update(x, offs, -20.0, 0.0, *zargs, 1.0, 5.0, out)
    # noise-free measurements of 2.5 m against the N(0, 4) prior: the posterior mean 2.5 * 80 / (1/4 + 80)
    assert x[mpf.B, 0] == pytest.approx(2.5 * 80.0 / (0.25 + 80.0), rel=1e-9)
    assert x[mpf.PB, 0] == pytest.approx(1.0 / (1.0 / 4.0 + 80.0), rel=1e-9)


def test_beam_projection_matches_numpy(rng):
    from tanbench.filters import beams as bm

    k = 20
    pitch, roll, yaw = rng.normal(0, 0.1, k), rng.normal(0, 0.1, k), rng.uniform(-3, 3, k)
    b = rng.normal(size=(4, 3))
    r = rng.uniform(20, 60, (k, 4))
    r[3, 2] = np.nan
    got = bm.nav_frame_offsets(pitch, roll, yaw, b, r)
    np.testing.assert_allclose(got, bm.nav_frame_offsets_numpy(pitch, roll, yaw, b, r), **TOL, equal_nan=True)
    assert np.isnan(got[3, 2]).all() and np.isfinite(np.delete(got.reshape(-1, 3), 3 * 4 + 2, 0)).all()
