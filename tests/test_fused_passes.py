"""The filter loops' fused passes compute exactly what the array kernels compute.

``tight.propagate_and_weigh`` and ``loose.propagate_and_weigh_loose`` draw, move and weigh
each particle in one pass; the array kernels (``propagate_*``, ``loglik_*``, checked
against their numpy references in test_filter_kernels.py and test_realism.py) do the
same in separate passes from an (M, 6) or (M, 3) noise array. Fed the same seeded
Generator, both must give the same cloud, log-likelihoods, divergence statistic and
Generator state, bit for bit. Also here: the inline PCG64 stream is numpy's own, the
normalisation with ESS is the two kernels, one cell look-up serves two interleaved grids,
and the map-aware likelihood's log-of-products stays finite with hundreds of beams.
"""

from __future__ import annotations


import numba as nb
import numpy as np
import pytest

from filters_support import KERNEL_SEED, VEHICLE_SEED
from tanbench.config import Scenario
from tanbench.filters import likelihood as lik
from tanbench.filters import propagate as prop
from tanbench.filters import resample as rs
from tanbench.filters.loose import propagate_and_weigh_loose
from tanbench.filters.params import Likelihood, Readings, TightModel
from tanbench.filters.rng import FastRng, Pcg64Stream, loop_rng
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.tight import propagate_and_weigh
from tanbench.navigation.increments import compute_increments
from tanbench.options import LIKELIHOOD, PROPAGATION
from tanbench.simulation import simulate_vehicle
from tanbench.terrain import navigation_map
from tanbench.terrain.grid import bilinear, bilinear_pair, stack_grids
from tanbench.terrain.representation import map_variance_grid


@pytest.fixture(scope="module")
def world():
    scenario = Scenario()
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(VEHICLE_SEED))
    nmap = navigation_map(scenario.terrain, scenario.map_resolution_m)
    return vehicle, nmap, map_variance_grid(nmap, 0.2887, 0.4)


def _tight_cloud(rng, nav, k, m, yaw_off=0.0):
    """A cloud around the navigation solution (its heading ``yaw_off`` from the navigation's),
    some particles near and off the map edge."""
    x = np.empty((m, N_TIGHT))
    x[:, E] = nav.pos[k, 0] + rng.uniform(-300, 300, m)
    x[:, N] = nav.pos[k, 1] + rng.uniform(-300, 300, m)
    x[:, U] = nav.pos[k, 2] + rng.normal(0, 0.5, m)
    x[:, PITCH] = nav.pitch[k] + rng.normal(0, 0.02, m)
    x[:, ROLL] = nav.roll[k] + rng.normal(0, 0.02, m)
    x[:, YAW] = nav.yaw[k] + yaw_off + rng.normal(0, 0.5, m)  # beyond the small-angle range too
    x[:, BX] = rng.normal(0, 1e-4, m)
    x[:, BZ] = rng.normal(0, 1e-4, m)
    return x


LIKELIHOODS = {"plain": (False, "gaussian"), "mapaware-gaussian": (True, "gaussian"),
               "mapaware-student": (True, "student-t")}


@pytest.mark.parametrize("yaw_off", [0.0, 0.52], ids=["cloud-on-navigation-heading", "cloud-30-deg-off"])
@pytest.mark.parametrize("propagation", ["exact", "euler-last-second"])
@pytest.mark.parametrize("likelihood", sorted(LIKELIHOODS))
@pytest.mark.parametrize("dist_mode", [prop.DIST_PARTICLE, prop.DIST_NAVIGATION], ids=["particle", "navigation"])
def test_tight_fused_pass_is_the_array_kernels(world, propagation, likelihood, dist_mode, yaw_off):
    vehicle, nmap, mvar = world
    obs, nav = vehicle.obs, vehicle.obs.nav
    upd = obs.ping_idx
    inc = compute_increments(obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    mapaware, kind = LIKELIHOODS[likelihood]
    bundle = Likelihood(mapaware, LIKELIHOOD[kind], 4.0, stack_grids(nmap.z, mvar))
    model = TightModel(0.07, 0.01, 3e-4, dist_mode, 0.1, 1.0, 5.0)
    readings = Readings(PROPAGATION[propagation], 1.0, 0.0, True, 0.0)
    za = nmap.kernel_args()
    rng = np.random.default_rng([KERNEL_SEED, 170, dist_mode, PROPAGATION[propagation], LIKELIHOOD[kind]])
    m = 513
    for row in (0, len(inc) // 3, len(inc) // 2):
        k = upd[row]
        x0 = _tight_cloud(rng, nav, k, m, yaw_off)
        ranges = obs.dvl_ranges[row + 1].copy()
        ranges[rng.integers(0, ranges.size)] = np.nan  # a beam without a range
        euler_in = np.array([1.2, 0.05, 0.01, -0.02])
        ref = (nav.pitch[upd[row + 1]], nav.roll[upd[row + 1]], nav.yaw[upd[row + 1]] + yaw_off)
        start = (nav.pitch[k], nav.roll[k])
        seed = int(rng.integers(2**32))

        # separate passes: the noise array first, then the array kernels
        gen = np.random.default_rng(seed)
        noise = gen.standard_normal((m, 6))
        x, dist, ll = x0.copy(), np.empty((m, 2)), np.empty(m)
        if readings.propagation:
            prop.propagate_tight_euler(x, euler_in, readings.dt, inc[row], noise, *model[:4], dist, *start,
                                       nav.yaw[k] + yaw_off)
        else:
            prop.propagate_tight(x, inc[row], nav.yaw[k], noise, *model[:4], dist, yaw_off)
        if mapaware:
            best = lik.loglik_tight_mapaware(x, obs.dvl_beams, ranges, za[0], mvar, *za[1:], 1.0, 5.0, dist, 0.1,
                                             *ref, LIKELIHOOD[kind], 4.0, ll)
        else:
            best = lik.loglik_tight(x, obs.dvl_beams, ranges, *za, 1.0, 5.0, dist, 0.1, *ref, ll)

        # the fused pass, drawing from the same stream
        fused_gen = np.random.default_rng(seed)
        xf, llf = x0.copy(), np.empty(m)
        best_f = propagate_and_weigh(xf, loop_rng(fused_gen, "numpy"), True, inc[row], nav.yaw[k], yaw_off, *start,
                                     euler_in, readings, model, np.ascontiguousarray(obs.dvl_beams), ranges, za,
                                     bundle, *ref, llf)
        assert np.array_equal(xf, x)
        assert np.array_equal(llf, ll)
        assert best_f == best
        assert fused_gen.bit_generator.state == gen.bit_generator.state

        # no propagation (update 0): the cloud is left alone and weighed with zero innovations
        xs, lls = x0.copy(), np.empty(m)
        best_s = propagate_and_weigh(xs, loop_rng(fused_gen, "numpy"), False, inc[row], nav.yaw[k], yaw_off, *start,
                                     euler_in, readings, model, np.ascontiguousarray(obs.dvl_beams), ranges, za,
                                     bundle, *ref, lls)
        assert np.array_equal(xs, x0)
        zero = np.zeros((m, 2))
        if mapaware:
            best_z = lik.loglik_tight_mapaware(x0, obs.dvl_beams, ranges, za[0], mvar, *za[1:], 1.0, 5.0, zero, 0.1,
                                               *ref, LIKELIHOOD[kind], 4.0, ll)
        else:
            best_z = lik.loglik_tight(x0, obs.dvl_beams, ranges, *za, 1.0, 5.0, zero, 0.1, *ref, ll)
        assert np.array_equal(lls, ll) and best_s == best_z
        assert fused_gen.bit_generator.state == gen.bit_generator.state  # nothing drawn


def test_trigonometry_references_change_nothing_but_the_last_bits(world):
    """A cloud 30 degrees off the navigation heading: centring the particles' sines and cosines on
    its offset (``yaw_off``, ``ref_yaw``, the Euler step's ``ref_*``) gives the numpy references'
    motion and likelihood, as centring them on the navigation attitude does."""
    vehicle, nmap, mvar = world
    obs, nav = vehicle.obs, vehicle.obs.nav
    upd = obs.ping_idx
    inc = compute_increments(obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    za = nmap.kernel_args()
    rng = np.random.default_rng([KERNEL_SEED, 171])
    m, row, yaw_off = 400, len(inc) // 2, 0.52
    k = upd[row]
    x0 = _tight_cloud(rng, nav, k, m, yaw_off)
    x0[:, YAW] = nav.yaw[k] + yaw_off + rng.normal(0, 0.05, m)  # converged: within the series' range of the offset
    noise = rng.standard_normal((m, 6))
    want, want_dist = prop.propagate_tight_numpy(x0, inc[row], nav.yaw[k], noise, 0.07, 0.01, 3e-4,
                                                 prop.DIST_NAVIGATION)
    for off in (0.0, yaw_off):
        x, dist = x0.copy(), np.empty((m, 2))
        prop.propagate_tight(x, inc[row], nav.yaw[k], noise, 0.07, 0.01, 3e-4, prop.DIST_NAVIGATION, dist, off)
        np.testing.assert_allclose(x, want, rtol=0, atol=1e-9)
        np.testing.assert_allclose(dist, want_dist, rtol=0, atol=1e-9)
    u = np.array([1.2, 0.05, 0.01, -0.02])
    want, _ = prop.propagate_tight_euler_numpy(x0, u, 1.0, inc[row], noise, 0.07, 0.01, 3e-4, prop.DIST_NONE)
    for ref in ((0.0, 0.0, 0.0), (nav.pitch[k], nav.roll[k], nav.yaw[k] + yaw_off)):
        x, dist = x0.copy(), np.empty((m, 2))
        prop.propagate_tight_euler(x, u, 1.0, inc[row], noise, 0.07, 0.01, 3e-4, prop.DIST_NONE, dist, *ref)
        np.testing.assert_allclose(x, want, rtol=0, atol=1e-9)
    ranges = obs.dvl_ranges[row + 1]
    dist = np.zeros((m, 2))
    want_ll, want_best = lik.loglik_tight_numpy(x0, obs.dvl_beams, ranges, *za, 1.0, 5.0, dist, 0.1)
    want_ma, want_ma_best = lik.loglik_tight_mapaware_numpy(x0, obs.dvl_beams, ranges, za[0], mvar, *za[1:], 1.0, 5.0,
                                                            dist, 0.1, LIKELIHOOD["student-t"], 4.0)
    for ref_yaw in (nav.yaw[k], nav.yaw[k] + yaw_off):
        ll = np.empty(m)
        best = lik.loglik_tight(x0, obs.dvl_beams, ranges, *za, 1.0, 5.0, dist, 0.1, nav.pitch[k], nav.roll[k],
                                ref_yaw, ll)
        np.testing.assert_allclose(ll, want_ll, rtol=1e-9, atol=1e-9)
        assert best == pytest.approx(want_best, rel=1e-9)
        best = lik.loglik_tight_mapaware(x0, obs.dvl_beams, ranges, za[0], mvar, *za[1:], 1.0, 5.0, dist, 0.1,
                                         nav.pitch[k], nav.roll[k], ref_yaw, LIKELIHOOD["student-t"], 4.0, ll)
        np.testing.assert_allclose(ll, want_ma, rtol=1e-9, atol=1e-9)
        assert best == pytest.approx(want_ma_best, rel=1e-9)


@pytest.mark.parametrize("likelihood", sorted(LIKELIHOODS))
def test_loose_fused_pass_is_the_array_kernels(world, likelihood):
    vehicle, nmap, mvar = world
    obs, nav = vehicle.obs, vehicle.obs.nav
    mapaware, kind = LIKELIHOODS[likelihood]
    bundle = Likelihood(mapaware, LIKELIHOOD[kind], 4.0, stack_grids(nmap.z, mvar))
    za = nmap.kernel_args()
    rng = np.random.default_rng([KERNEL_SEED, 171, LIKELIHOOD[kind], int(mapaware)])
    m = 401
    for ping in (5, 300, 900):
        k = obs.ping_idx[ping]
        x0 = np.ascontiguousarray(nav.pos[k, :2] + rng.uniform(-300, 300, (m, 2)))
        offsets = rng.normal(0, 15, (4, 3))
        offsets[:, 2] = -np.abs(offsets[:, 2]) - 20
        offsets[rng.integers(0, 4)] = np.nan  # a beam without a range
        d_e, d_n, up = 1.5, -0.7, nav.pos[k, 2]
        seed = int(rng.integers(2**32))

        gen = np.random.default_rng(seed)
        noise = gen.standard_normal((m, 3))
        x, ll = x0.copy(), np.empty(m)
        prop.propagate_loose(x, d_e, d_n, noise, 0.1, 0.5)
        if mapaware:
            best = lik.loglik_loose_mapaware(x, offsets, up, za[0], mvar, *za[1:], 1.0, 5.0, LIKELIHOOD[kind], 4.0, ll)
        else:
            best = lik.loglik_loose(x, offsets, up, *za, 1.0, 5.0, ll)

        fused_gen = np.random.default_rng(seed)
        xf, llf = x0.copy(), np.empty(m)
        best_f = propagate_and_weigh_loose(xf, loop_rng(fused_gen, "numpy"), True, d_e, d_n, 0.1, 0.5, offsets, up,
                                           za, 1.0, 5.0, bundle, llf)
        assert np.array_equal(xf, x)
        assert np.array_equal(llf, ll)
        assert best_f == best
        assert fused_gen.bit_generator.state == gen.bit_generator.state


def test_normalisation_with_ess_is_the_two_kernels():
    rng = np.random.default_rng([KERNEL_SEED, 172])
    for scale in (1.0, 1e3, 1e5):
        logw = -scale * rng.random(2001)
        ll = -rng.random(2001)
        acc = logw.copy()
        mx = rs.add_log_weights(acc, ll)
        assert np.array_equal(acc, logw + ll) and mx == (logw + ll).max()
        w_ref = np.empty_like(acc)
        rs.normalize_log_weights(acc, w_ref)
        w = np.empty_like(acc)
        ess = rs.normalise_with_ess(acc, mx, w)
        assert np.array_equal(w, w_ref)
        assert ess == rs.effective_sample_size(w_ref)


@nb.njit(cache=True)
def _draws(rng, n, out):
    """Every kind of draw the loops make, interleaved."""
    for j in range(n):
        kind = j % 4
        if kind == 0:
            out[j] = rng.standard_normal()
        elif kind == 1:
            out[j] = rng.random()
        elif kind == 2:
            out[j] = rng.uniform(-3.0, 7.0)
        else:
            out[j] = rng.normal(2.0, 0.5)


def test_pcg64_stream_is_numpys_stream():
    """400k draws (about 4000 through the ziggurat's wedges and tail) equal the Generator's own,
    and the Generator goes on from the same state."""
    n = 400_000
    a, b = np.empty(n), np.empty(n)
    g, h = np.random.default_rng([KERNEL_SEED, 173]), np.random.default_rng([KERNEL_SEED, 173])
    _draws(g, n, a)
    stream = loop_rng(h, "numpy")
    assert isinstance(stream, Pcg64Stream)
    _draws(stream, n, b)
    assert np.array_equal(a, b)
    assert g.bit_generator.state == h.bit_generator.state
    assert np.array_equal(g.standard_normal(5), h.standard_normal(5))
    # plain-Python draws (set-up code) come from the same Generator
    assert np.array_equal(stream.normal(1.0, 2.0, 4), g.normal(1.0, 2.0, 4))
    assert stream.uniform(-1.0, 1.0) == g.uniform(-1.0, 1.0)


def test_other_bit_generators_are_drawn_from_as_they_are():
    gen = np.random.Generator(np.random.Philox(5))
    assert loop_rng(gen, "numpy") is gen
    with pytest.raises(ValueError, match="PCG64"):
        Pcg64Stream(gen)
    assert isinstance(loop_rng(np.random.default_rng(1), "fast"), FastRng)


@nb.njit(cache=True)
def _pair_and_singles(zz, z, z2, e0, n0, inv_re, inv_rn, e, n, out):
    for k in range(e.shape[0]):
        out[k, 0], out[k, 1] = bilinear_pair(zz, e0, n0, inv_re, inv_rn, e[k], n[k])
        out[k, 2] = bilinear(z, e0, n0, inv_re, inv_rn, e[k], n[k])
        out[k, 3] = bilinear(z2, e0, n0, inv_re, inv_rn, e[k], n[k])


def test_one_cell_look_up_serves_two_interleaved_grids():
    rng = np.random.default_rng([KERNEL_SEED, 174])
    z = rng.normal(-50, 5, (23, 31))
    z2 = rng.random((23, 31))
    z[4, 7] = np.nan  # a NaN node poisons its cells in one grid only
    zz = stack_grids(z, z2)
    assert np.array_equal(zz, np.stack([z, z2], axis=-1), equal_nan=True)
    e = rng.uniform(-20, 330, 5000)  # the grid spans 0..300 m east, 0..220 m north
    n = rng.uniform(-20, 240, 5000)
    out = np.empty((5000, 4))
    _pair_and_singles(zz, z, z2, 0.0, 0.0, 0.1, 0.1, e, n, out)
    assert np.array_equal(out[:, 0], out[:, 2], equal_nan=True)
    assert np.array_equal(out[:, 1], out[:, 3], equal_nan=True)
    assert np.isnan(out[:, 0]).any() and np.isnan(out[:, 1]).any()


def test_mapaware_log_of_products_stays_finite_with_many_beams():
    """500 beams with a large map variance: the products would overflow without being moved
    into the log sum; the kernel still equals its numpy reference."""
    rng = np.random.default_rng([KERNEL_SEED, 175])
    z = rng.normal(-60, 3, (60, 60))
    mvar = np.full_like(z, 50.0)  # factor 51 per beam: 51^500 overflows a double
    beams = rng.normal(0, 0.3, (500, 3))
    beams[:, 2] = -1.0
    beams /= np.linalg.norm(beams, axis=1)[:, None]
    ranges = rng.uniform(20, 30, 500)
    x = np.zeros((64, N_TIGHT))
    x[:, E] = rng.uniform(250, 350, 64)
    x[:, N] = rng.uniform(250, 350, 64)
    x[:, U] = -35.0
    dist = rng.normal(0, 0.1, (64, 2))
    for kind in LIKELIHOOD.values():
        out = np.empty(64)
        best = lik.loglik_tight_mapaware(x, beams, ranges, z, mvar, 0.0, 0.0, 0.1, 0.1, 1.0, 5.0, dist, 0.1,
                                         0.0, 0.0, 0.0, kind, 4.0, out)
        ref, best_ref = lik.loglik_tight_mapaware_numpy(x, beams, ranges, z, mvar, 0.0, 0.0, 0.1, 0.1, 1.0, 5.0,
                                                        dist, 0.1, kind, 4.0)
        assert np.isfinite(out).all()
        np.testing.assert_allclose(out, ref, rtol=1e-9)
        assert best == pytest.approx(best_ref, rel=1e-12)
