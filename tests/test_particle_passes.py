"""The filter loops' particle passes: blocks of the cloud, attitude references, streams, grids.

The loops run their particle passes over blocks of the cloud (``likelihood.BLOCK``
particles) so that a block's arrays stay in the core's caches; a block is particles
``lo .. lo + n - 1`` of the whole cloud. Moving and weighing the cloud block by block must
give exactly (bit for bit) what the kernels give on the whole cloud at once. Also here:
the attitude references of the trigonometry change nothing but the last bits, the numpy
stream the fills draw is numpy's own, one look-up serves two interleaved grids, the
map-aware likelihood stays finite with hundreds of beams, and the normalisation with ESS
is the two kernels.
"""

from __future__ import annotations

import numpy as np
import pytest

from filters_support import KERNEL_SEED, VEHICLE_SEED
from tanbench.config import Scenario
from tanbench.filters import likelihood as lik
from tanbench.filters import propagate as prop
from tanbench.filters import resample as rs
from tanbench.filters.likelihood import Likelihood
from tanbench.filters.rng import FastRng, fill_normals, fill_uniforms, loop_rng
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.trig import LEVEL, attitude_reference
from tanbench.navigation.increments import compute_increments
from tanbench.numpy_stream import Pcg64Stream
from tanbench.options import LIKELIHOOD
from tanbench.simulation import simulate_vehicle
from tanbench.terrain import navigation_map
from tanbench.terrain.grid import MapArgs, bilinear_numpy, node_grid, node_grid_at, node_grid_of
from tanbench.terrain.representation import map_variance_grid


@pytest.fixture(scope="module")
def world():
    scenario = Scenario()
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(VEHICLE_SEED))
    nmap = navigation_map(scenario.terrain, scenario.map_resolution_m)
    return vehicle, nmap, map_variance_grid(nmap, 0.2887, 0.4)


def _tight_cloud(rng, nav, k, m, yaw_off=0.0, yaw_std=0.5):
    """A cloud (8, M) around the navigation solution (its heading ``yaw_off`` from the
    navigation's), some particles near and off the map edge."""
    x = np.empty((N_TIGHT, m))
    x[E] = nav.pos[k, 0] + rng.uniform(-300, 300, m)
    x[N] = nav.pos[k, 1] + rng.uniform(-300, 300, m)
    x[U] = nav.pos[k, 2] + rng.normal(0, 0.5, m)
    x[PITCH] = nav.pitch[k] + rng.normal(0, 0.02, m)
    x[ROLL] = nav.roll[k] + rng.normal(0, 0.02, m)
    x[YAW] = nav.yaw[k] + yaw_off + rng.normal(0, yaw_std, m)
    x[BX] = rng.normal(0, 1e-4, m)
    x[BZ] = rng.normal(0, 1e-4, m)
    return x


LIKELIHOODS = {"plain": Likelihood(False, LIKELIHOOD["gaussian"], 4.0),
               "mapaware-gaussian": Likelihood(True, LIKELIHOOD["gaussian"], 4.0),
               "mapaware-student": Likelihood(True, LIKELIHOOD["student-t"], 4.0)}


def _grid(nmap, mvar, likelihood):
    return node_grid(nmap, mvar) if likelihood.mapaware else node_grid(nmap)


@pytest.mark.parametrize("likelihood", sorted(LIKELIHOODS))
@pytest.mark.parametrize("dist_mode", [prop.DIST_PARTICLE, prop.DIST_NAVIGATION], ids=["particle", "navigation"])
def test_tight_blocks_are_the_whole_cloud(world, likelihood, dist_mode):
    """Propagating (both readings of Eq. 1) and weighing the cloud block by block, with the
    loop's block buffers, equals the kernels on the whole cloud, bit for bit."""
    vehicle, nmap, mvar = world
    obs, nav = vehicle.obs, vehicle.obs.nav
    upd = obs.ping_idx
    inc = compute_increments(obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    lk = LIKELIHOODS[likelihood]
    grid = _grid(nmap, mvar, lk)
    rng = np.random.default_rng([KERNEL_SEED, 170])
    m, block, row = 1333, 500, len(inc) // 3
    k = upd[row]
    x0 = _tight_cloud(rng, nav, k, m)
    noise = rng.standard_normal((6, m))
    u = np.array([1.2, 0.05, 0.01, -0.02])
    ranges = obs.dvl_ranges[row + 1].copy()
    ranges[2] = np.nan
    vec = lik.beam_vectors(obs.dvl_beams, ranges)
    att = attitude_reference(nav.pitch[k], nav.roll[k], nav.yaw[k] + 0.1)
    consts = lik.beam_constants(1.0, 0.1, 5.0)
    for euler in (False, True):
        whole, dist_whole, ll_whole = x0.copy(), np.zeros((2, m)), np.empty(m)
        blocks, ll_blocks = x0.copy(), np.empty(m)
        if euler:
            prop.propagate_tight_euler(whole, u, 1.0, inc[row], noise, 0.07, 0.01, 3e-4, dist_mode, dist_whole,
                                       attitude_reference(nav.pitch[k], nav.roll[k], nav.yaw[k]))
        else:
            prop.propagate_tight(whole, inc[row], nav.yaw[k], noise, 0.07, 0.01, 3e-4, dist_mode, dist_whole, 0.1)
        best_whole = lik.loglik_tight_pass(whole, 0, vec, grid, lk, consts, att, dist_whole, True,
                                           lik.work_block(lik.new_likelihood_work(m, 4 * grid.grids), m), ll_whole)
        work = lik.new_likelihood_work(block, 4 * grid.grids)
        best_blocks = np.inf
        for lo in range(0, m, block):
            n = min(block, m - lo)
            nz = np.ascontiguousarray(noise[:, lo:lo + n])
            dist = np.zeros((2, n))
            if euler:
                prop.propagate_tight_euler(blocks, u, 1.0, inc[row], nz, 0.07, 0.01, 3e-4, dist_mode, dist,
                                           attitude_reference(nav.pitch[k], nav.roll[k], nav.yaw[k]), lo)
            else:
                prop.propagate_tight(blocks, inc[row], nav.yaw[k], nz, 0.07, 0.01, 3e-4, dist_mode, dist, 0.1, lo)
            best_blocks = min(best_blocks, lik.loglik_tight_pass(blocks, lo, vec, grid, lk, consts, att, dist,
                                                                 True, lik.work_block(work, n),
                                                                 ll_blocks[lo:lo + n]))
        assert np.array_equal(blocks, whole)
        assert np.array_equal(ll_blocks, ll_whole)
        assert best_blocks == best_whole and np.isfinite(best_whole)


@pytest.mark.parametrize("likelihood", sorted(LIKELIHOODS))
def test_loose_blocks_are_the_whole_cloud(world, likelihood):
    vehicle, nmap, mvar = world
    obs = vehicle.obs
    lk = LIKELIHOODS[likelihood]
    grid = _grid(nmap, mvar, lk)
    rng = np.random.default_rng([KERNEL_SEED, 171])
    m, block = 1100, 512
    nav = obs.nav
    k = obs.ping_idx[300]
    x0 = _tight_cloud(rng, nav, k, m)[:2].copy()
    noise = rng.standard_normal((3, m))
    off = np.ascontiguousarray(obs.dvl_beams * obs.dvl_ranges[300][:, None])
    rows = lik.used_offsets(off)
    consts = lik.beam_constants(1.0, 1.0, 5.0)
    whole, ll_whole = x0.copy(), np.empty(m)
    prop.propagate_loose(whole, 3.0, -2.0, noise, 0.1, 0.3)
    best_whole = lik.loglik_loose_pass(whole, 0, rows, nav.pos[k, 2], grid, lk, consts,
                                       lik.work_block(lik.new_likelihood_work(m, 4 * grid.grids), m), ll_whole)
    blocks, ll_blocks, best_blocks = x0.copy(), np.empty(m), np.inf
    work = lik.new_likelihood_work(block, 4 * grid.grids)
    for lo in range(0, m, block):
        n = min(block, m - lo)
        prop.propagate_loose(blocks, 3.0, -2.0, np.ascontiguousarray(noise[:, lo:lo + n]), 0.1, 0.3, lo)
        best_blocks = min(best_blocks, lik.loglik_loose_pass(blocks, lo, rows, nav.pos[k, 2], grid, lk, consts,
                                                             lik.work_block(work, n), ll_blocks[lo:lo + n]))
    assert np.array_equal(blocks, whole)
    assert np.array_equal(ll_blocks, ll_whole)
    assert best_blocks == best_whole


def test_trigonometry_references_change_nothing_but_the_last_bits(world):
    """A cloud 30 degrees off the navigation heading: centring the particles' sines and cosines on
    its offset (``yaw_off``, the attitude reference ``att`` of the likelihood and the Euler step) gives the numpy references'
    motion and likelihood, as centring them on the navigation attitude does."""
    vehicle, nmap, mvar = world
    obs, nav = vehicle.obs, vehicle.obs.nav
    upd = obs.ping_idx
    inc = compute_increments(obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    za = nmap.kernel_args()
    rng = np.random.default_rng([KERNEL_SEED, 172])
    m, row, yaw_off = 400, len(inc) // 2, 0.52
    k = upd[row]
    x0 = _tight_cloud(rng, nav, k, m, yaw_off, yaw_std=0.05)
    noise = rng.standard_normal((6, m))
    want, want_dist = prop.propagate_tight_numpy(x0, inc[row], nav.yaw[k], noise, 0.07, 0.01, 3e-4,
                                                 prop.DIST_NAVIGATION)
    for off in (0.0, yaw_off):
        x, dist = x0.copy(), np.empty((2, m))
        prop.propagate_tight(x, inc[row], nav.yaw[k], noise, 0.07, 0.01, 3e-4, prop.DIST_NAVIGATION, dist, off)
        np.testing.assert_allclose(x, want, rtol=0, atol=1e-9)
        np.testing.assert_allclose(dist, want_dist, rtol=0, atol=1e-9)
    u = np.array([1.2, 0.05, 0.01, -0.02])
    want, _ = prop.propagate_tight_euler_numpy(x0, u, 1.0, inc[row], noise, 0.07, 0.01, 3e-4, prop.DIST_NONE)
    for ref in ((0.0, 0.0, 0.0), (nav.pitch[k], nav.roll[k], nav.yaw[k] + yaw_off)):
        x, dist = x0.copy(), np.empty((2, m))
        prop.propagate_tight_euler(x, u, 1.0, inc[row], noise, 0.07, 0.01, 3e-4, prop.DIST_NONE, dist,
                                   attitude_reference(*ref))
        np.testing.assert_allclose(x, want, rtol=0, atol=1e-9)
    ranges = obs.dvl_ranges[row + 1]
    dist = np.zeros((2, m))
    for lk in LIKELIHOODS.values():
        want_ll, want_best = lik.loglik_tight_numpy(x0, obs.dvl_beams, ranges, za, mvar, lk, 1.0, 5.0, None, 0.1)
        for ref_yaw in (nav.yaw[k], nav.yaw[k] + yaw_off):
            ll = np.empty(m)
            best = lik.loglik_tight(x0, obs.dvl_beams, ranges, _grid(nmap, mvar, lk), lk, 1.0, 5.0, dist, 0.1, False,
                                    attitude_reference(nav.pitch[k], nav.roll[k], ref_yaw), ll)
            np.testing.assert_allclose(ll, want_ll, rtol=1e-9, atol=1e-9)
            assert best == pytest.approx(want_best, rel=1e-9)


def test_normalisation_with_ess_is_the_two_kernels():
    rng = np.random.default_rng([KERNEL_SEED, 173])
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


def test_pcg64_stream_is_numpys_stream():
    """400k normals (about 4800 through the ziggurat's wedges and tail) and uniforms equal the
    Generator's own, and the Generator goes on from the same state."""
    n = 400_000
    g, h = np.random.default_rng([KERNEL_SEED, 174]), np.random.default_rng([KERNEL_SEED, 174])
    stream = loop_rng(h, "numpy")
    assert isinstance(stream, Pcg64Stream)
    a = np.empty((4, n // 4))
    fill_normals(stream, a)
    assert np.array_equal(a.ravel(), g.standard_normal(n))
    b = np.empty(1000)
    fill_uniforms(stream, b, -3.0, 7.0)
    assert np.array_equal(b, g.uniform(-3.0, 7.0, 1000))
    assert g.bit_generator.state == h.bit_generator.state
    assert np.array_equal(g.standard_normal(5), h.standard_normal(5))


def test_other_bit_generators_are_drawn_from_as_they_are():
    gen = np.random.Generator(np.random.Philox(5))
    assert loop_rng(gen, "numpy") is gen
    with pytest.raises(ValueError, match="PCG64"):
        Pcg64Stream(gen)
    same = np.random.Generator(np.random.Philox(5))
    a = np.empty(300)
    fill_normals(gen, a)
    assert np.array_equal(a, same.standard_normal(300))
    fast = loop_rng(np.random.default_rng(1), "fast")
    assert fast.dtype == np.uint64 and np.array_equal(fast, FastRng.from_seed(np.random.SeedSequence(1)).state)


def test_one_look_up_serves_two_interleaved_grids():
    rng = np.random.default_rng([KERNEL_SEED, 175])
    z = rng.normal(-50, 5, (23, 31))
    z2 = rng.random((23, 31))
    z[4, 7] = np.nan  # a NaN node poisons its cells in one grid only
    pair = node_grid_of(z, 0.0, 0.0, 0.1, 0.1, z2=z2)
    assert np.array_equal(pair.nodes.reshape(23, 31, 2), np.stack([z, z2], axis=-1), equal_nan=True)
    e = rng.uniform(-20, 330, 5000)  # the grid spans 0..300 m east, 0..220 m north
    n = rng.uniform(-20, 240, 5000)
    heights, variances = node_grid_at(pair, e, n, 0), node_grid_at(pair, e, n, 1)
    assert np.array_equal(heights, bilinear_numpy(z, 0.0, 0.0, 0.1, 0.1, e, n), equal_nan=True)
    assert np.array_equal(variances, bilinear_numpy(z2, 0.0, 0.0, 0.1, 0.1, e, n), equal_nan=True)
    assert np.isnan(heights).any() and np.isnan(variances).any()
    assert np.array_equal(node_grid_at(node_grid_of(z, 0.0, 0.0, 0.1, 0.1), e, n), heights, equal_nan=True)


def test_mapaware_log_of_products_stays_finite_with_many_beams():
    """500 beams with a large map variance: the products would overflow without being moved
    into the log sum every FOLD_BEAMS beams; the kernel still equals its numpy reference."""
    rng = np.random.default_rng([KERNEL_SEED, 176])
    z = rng.normal(-60, 3, (60, 60))
    mvar = np.full_like(z, 50.0)  # factor 51 per beam: 51^500 overflows a double
    beams = rng.normal(0, 0.3, (500, 3))
    beams[:, 2] = -1.0
    beams /= np.linalg.norm(beams, axis=1)[:, None]
    ranges = rng.uniform(20, 30, 500)
    x = np.zeros((N_TIGHT, 64))
    x[E] = rng.uniform(250, 350, 64)
    x[N] = rng.uniform(250, 350, 64)
    x[U] = -35.0
    dist = rng.normal(0, 0.1, (2, 64))
    grid = node_grid_of(z, 0.0, 0.0, 0.1, 0.1, z2=mvar)
    for kind in LIKELIHOOD.values():
        out = np.empty(64)
        best = lik.loglik_tight(x, beams, ranges, grid, Likelihood(True, kind, 4.0), 1.0, 5.0, dist, 0.1, True,
                                LEVEL, out)
        ref, best_ref = lik.loglik_tight_numpy(x, beams, ranges, MapArgs(z, 0.0, 0.0, 0.1, 0.1), mvar,
                                               Likelihood(True, kind, 4.0), 1.0, 5.0, dist, 0.1)
        assert np.isfinite(out).all()
        np.testing.assert_allclose(out, ref, rtol=1e-9)
        assert best == pytest.approx(best_ref, rel=1e-12)
