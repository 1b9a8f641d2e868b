"""KLD sampling, the adaptive particle count (filters/kld.py, docs/filters.md section 23): its kernels against
their numpy references, resampling to another count, and what the tight loop does with it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tanbench.filters import resample as rs
from tanbench.filters.kld import (KLD_Z, bin_table, kld_count, kld_count_numpy, kld_of, occupied_bins,
                                  occupied_bins_numpy)


def _cloud(m, sd, seed=1):
    rng = np.random.default_rng(seed)
    x = np.zeros((8, m))
    x[0] = 1000.0 + sd * rng.standard_normal(m)
    x[1] = -300.0 + sd * rng.standard_normal(m)
    x[5] = 0.3 + 0.02 * sd * rng.standard_normal(m)
    w = rng.random(m) ** 3
    return x, w / w.sum()


@pytest.mark.parametrize("m, sd", [(3000, 60.0), (3000, 1.0), (1000, 8.0), (257, 0.2)])
@pytest.mark.parametrize("share", [0.0, 1.0, 5.0])
def test_occupied_bins_match_numpy(m, sd, share):
    x, w = _cloud(m, sd)
    keys, weights = bin_table(m)
    min_weight = share / m
    got = occupied_bins(x, w, 2.0, math.radians(5.0), min_weight, keys, weights)
    assert got == occupied_bins_numpy(x, w, 2.0, math.radians(5.0), min_weight)
    assert got >= 1 if share <= 1.0 else got >= 0


def test_kld_count_matches_numpy_and_fox():
    for k in list(range(0, 60)) + [100, 1000, 5000]:
        for eps in (0.02, 0.05, 0.2):
            assert kld_count(k, eps, KLD_Z, 300, 3000) == kld_count_numpy(k, eps, KLD_Z, 300, 3000)
    # Fox (2003): k = 10 bins, epsilon 0.05, delta 0.01 -> about 217 particles
    assert kld_count(10, 0.05, KLD_Z, 1, 10**6) == math.ceil(9 / 0.1 * (1 - 2 / 81 + math.sqrt(2 / 81) * KLD_Z) ** 3)
    assert kld_count(1, 0.05, KLD_Z, 300, 3000) == 300 and kld_count(10**6, 0.05, KLD_Z, 300, 3000) == 3000


@pytest.mark.parametrize("scheme", [rs.SYSTEMATIC, rs.STRATIFIED, rs.MULTINOMIAL, rs.RESIDUAL])
@pytest.mark.parametrize("n", [37, 500, 1000])
def test_resampling_to_another_count_matches_numpy(scheme, n):
    rng = np.random.default_rng(3)
    w = rng.random(1000) ** 4
    w /= w.sum()
    u = rng.random(n)
    idx = np.empty(n, dtype=np.int64)
    rs.resample_indices(scheme, w, u, idx)
    np.testing.assert_array_equal(idx, rs.resample_indices_numpy(scheme, w, u, n))


def test_gather_into_a_smaller_view_of_the_same_memory():
    rng = np.random.default_rng(4)
    m, n = 50, 20
    buf = rng.random(8 * m)
    x = buf.reshape((8, m))
    want = x[:, rng.integers(0, m, n)].copy()
    idx = np.asarray([list(x[0]).index(v) for v in want[0]], dtype=np.int64)
    out = buf[:8 * n].reshape((8, n))
    rs.gather_columns(x, idx, np.empty((8, n)), out)
    np.testing.assert_array_equal(out, want)


def test_resample_posterior_into_draws_the_ancestors_numpy_draws(monkeypatch):
    """With a vanishing kernel width, resampling 3000 particles into 400 gives x[:, ancestors] for the
    ancestors the numpy reference draws from the same uniform."""
    from tanbench.filters.posterior import resample_posterior_into
    from tanbench.filters.resample import Resampling
    from tanbench.filters.rng import fill_uniforms, loop_rng, rng_state, set_rng_state

    m, n = 3000, 400
    x, w = _cloud(m, 5.0)
    buf = x.ravel().copy()
    rng = loop_rng(np.random.default_rng(7), "fast")
    state = rng_state(rng)
    u = np.empty(1)
    fill_uniforms(rng, u)
    set_rng_state(rng, state)
    cols = np.array([0, 1, 5, 6, 7], dtype=np.int64)
    rsp = Resampling(rs.SYSTEMATIC, 0.5, 3, cols, 1e-9, 0.0)
    out = buf[:8 * n].reshape((8, n))
    resample_posterior_into(buf.reshape((8, m)), w, rng, rsp, 5, 0.3, 10.0, np.empty(n), np.empty(n, dtype=np.int64),
                            np.empty((8, n)), out)
    ancestors = rs.resample_indices_numpy(rs.SYSTEMATIC, w, u, n)
    np.testing.assert_allclose(out, x[:, ancestors], rtol=0, atol=1e-6)


def test_options_and_refusals():
    from tanbench.config import FilterSpec

    assert kld_of(FilterSpec(), 3000).epsilon == 0.0
    k = kld_of(FilterSpec(kld_epsilon=0.05, kld_min_particles=500), 300)
    assert k.epsilon == 0.05 and k.min_particles == 300 and k.bin_rad == pytest.approx(math.radians(5.0))
    with pytest.raises(ValueError, match="kld_epsilon needs filter.tight_regularisation: posterior"):
        FilterSpec(kld_epsilon=0.05, tight_regularisation="shared")
    with pytest.raises(ValueError, match="kld_epsilon needs"):
        FilterSpec(kld_epsilon=0.05, regularisation="none")


@pytest.mark.parametrize("name, late", [("tight-dvl", 1000), ("tight-sbe", 2000)])
def test_the_loop_adapts_its_count(monkeypatch, name, late):
    """Off: the count stays. On: the first updates use the most particles (the 150 m square), the count falls as
    the cloud converges (tight-dvl within the 90 s; tight-sbe's single beam converges and resamples more slowly),
    never below the least nor above the most, and the run tracks."""
    from test_tempering import _run_tight

    _, off = _run_tight(monkeypatch, name, {}, particles=2000)
    assert np.all(off.particles == 2000)
    out, on = _run_tight(monkeypatch, name, {"kld_epsilon": 0.05, "kld_min_particles": 200}, particles=2000)
    assert on.particles[0] == 2000 and on.particles.min() >= 200 and on.particles.max() <= 2000
    assert on.particles[-20:].mean() < late and on.particles[-1] < 2000
    assert np.all(np.isfinite(out.east)) and np.all(np.isfinite(out.north))


def test_the_bins_spread_over_the_table():
    """A wide cloud's bins start their searches at nearly as many slots as there are bins (a hash of the packed
    key's low bits alone gave 3 slots for about 2900 bins, and one chain of millions of probes)."""
    from tanbench.filters.kld import home_slot

    x, _ = _cloud(3000, 100.0)
    keys, _ = bin_table(3000)
    size = keys.shape[0]
    bins = {(int(np.floor(x[0, j] / 2.0)), int(np.floor(x[1, j] / 2.0)), int(np.floor(x[5, j] / math.radians(5.0))))
            for j in range(3000)}
    slots = {home_slot(ie + 600000, jn + 600000, iy + 600000, size) for ie, jn, iy in bins}
    assert len(bins) > 2500 and len(slots) > 0.6 * len(bins)


def test_kld_count_for_a_tiny_epsilon_is_the_most():
    assert kld_count(50, 1e-300, KLD_Z, 300, 3000) == 3000 == kld_count_numpy(50, 1e-300, KLD_Z, 300, 3000)


def test_kld_with_tempering_is_refused():
    from tanbench.config import FilterSpec

    with pytest.raises(ValueError, match="kld_epsilon with filter.tempering_ess"):
        FilterSpec(kld_epsilon=0.05, tempering_ess=0.5)
