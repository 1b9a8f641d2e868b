"""The fast generator of the jitted loops (tanbench/filters/rng.py).

The jitted lanes of xoshiro256++ and the ziggurat must equal their plain-Python
references word for word; xoshiro256++ is also checked against words printed by the
authors' C reference algorithm (compiled once with gcc for the fixed state below). The
normals must be N(0, 1): moments within 5 standard errors and a Kolmogorov-Smirnov test
(p > 0.001) on 10^6 draws for each of three fixed seeds, and the tail beyond the
ziggurat's base edge r at its N(0, 1) frequency. These thresholds were fixed before the
first run (of the scalar generator, whose statistics the lanes generator must meet too).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import pytest
from scipy import stats

from tanbench.filters import rng as fr

C_STATE = np.array([0x0123456789ABCDEF, 0xFEDCBA9876543210, 0x0F1E2D3C4B5A6978, 0x8796A5B4C3D2E1F0],
                   dtype=np.uint64)
# words 0, 1, 2 and 999 of the C reference (prng.di.unimi.it/xoshiro256plusplus.c) from C_STATE
C_WORDS = {0: 10325070316122942180, 1: 3650558535895781571, 2: 14823629923424836590, 999: 6709908881530730455}
N_DRAWS = 1_000_000


def lanes_state(first_lane=C_STATE, seed=5):
    """A fast generator's state words: lane 0 on ``first_lane``, the others and the scalar stream
    from a seed."""
    words = np.random.SeedSequence(seed).generate_state(fr.FAST_WORDS, np.uint64)
    words[0:fr.STATE_WORDS * fr.LANES:fr.LANES] = first_lane
    return words


@nb.njit(cache=True)
def _fill_in_blocks(words, sizes, out):
    """Fill ``out`` in consecutive blocks of the given sizes, as the loops draw."""
    start = 0
    for size in sizes:
        fr.fill_normals(words, out[start:start + size])
        start += size


def test_ziggurat_edge_is_the_published_constant():
    # Marsaglia & Tsang's 256-layer base edge (r = 3.6541528853610088 in their paper and numpy)
    assert fr.ZIG_R == pytest.approx(3.6541528853610088, rel=1e-14)
    assert fr.ZIG_KI[fr.LAYERS - 1] == 0 and np.all(np.diff(fr.ZIG_FI) > 0)


def test_xoshiro_lanes_match_c_reference_and_numpy_reference():
    ref, ref_state = fr.xoshiro_numpy(C_STATE, 1000)
    for k, word in C_WORDS.items():
        assert int(ref[k]) == word
    words = lanes_state()
    jit = np.empty(1000 * fr.LANES, dtype=np.uint64)
    fr.lane_words(words, jit)
    np.testing.assert_array_equal(jit[::fr.LANES], ref)  # lane 0
    np.testing.assert_array_equal(words[0:fr.STATE_WORDS * fr.LANES:fr.LANES], ref_state)
    lanes_ref, words_ref = fr.lane_words_numpy(lanes_state(), 1000)
    np.testing.assert_array_equal(jit, lanes_ref)  # every lane
    np.testing.assert_array_equal(words, words_ref)


def test_jitted_normals_and_uniforms_equal_reference_including_tail_and_wedges():
    rng_words = np.random.PCG64(3).random_raw(40_000).astype(np.uint64)
    scalar = lanes_state()[fr.STATE_WORDS * fr.LANES:]
    ref = fr.normals_from_words_numpy(rng_words, scalar)
    jit = np.empty(rng_words.size)
    fr.normals_from_words(rng_words, scalar.copy(), jit)
    np.testing.assert_array_equal(jit, ref)
    assert np.abs(ref).max() > fr.ZIG_R  # the tail path was exercised
    u = np.empty(rng_words.size)
    fr.uniforms_from_words(rng_words, -2.0, 3.0, u)
    np.testing.assert_array_equal(u, fr.uniforms_from_words_numpy(rng_words, -2.0, 3.0))
    assert (u >= -2).all() and (u < 3).all()


def test_fills_are_the_words_in_order_whatever_the_block_sizes():
    """A fill draws the lanes' words in order (dropping what a last round leaves over): a whole
    fill equals the words' normals, and block sizes that are multiples of LANES give the same
    numbers as one fill."""
    n = 3 * fr.CHUNK + 5 * fr.LANES
    words = lanes_state()
    whole = np.empty(n)
    fr.fill_normals(words.copy(), whole)
    w, _ = fr.lane_words_numpy(lanes_state(), n // fr.LANES)
    np.testing.assert_array_equal(whole, fr.normals_from_words_numpy(w, lanes_state()[fr.STATE_WORDS * fr.LANES:]))
    blocks = np.empty(n)
    _fill_in_blocks(words.copy(), np.array([fr.LANES * 7, fr.CHUNK, fr.LANES * 40, n - fr.LANES * 47 - fr.CHUNK]),
                    blocks)
    np.testing.assert_array_equal(blocks, whole)
    g = fr.FastRng(lanes_state())
    np.testing.assert_array_equal(g.standard_normal(n), whole)


def test_seeding_reproducible_and_own_stream():
    seed = np.random.SeedSequence(2017, spawn_key=(2, 5))
    s1 = fr.FastRng.from_seed(seed).state
    s2 = fr.FastRng.from_seed(np.random.SeedSequence(2017, spawn_key=(2, 5))).state
    np.testing.assert_array_equal(s1, s2)
    assert not np.array_equal(s1, fr.FastRng.from_seed(np.random.SeedSequence(2017, spawn_key=(2, 6))).state)
    # not the words numpy's own PCG64 is seeded with from the same sequence
    assert not np.array_equal(s1[:4], seed.generate_state(4, np.uint64))
    assert fr.loop_rng(np.random.default_rng(seed), "numpy").bit_generator.seed_seq is not None
    np.testing.assert_array_equal(fr.loop_rng(np.random.default_rng(seed), "fast"), s1)
    with pytest.raises(ValueError):
        fr.FastRng(np.zeros(4, dtype=np.uint64))
    bad = s1.copy()
    bad[3:fr.STATE_WORDS * fr.LANES:fr.LANES] = 0  # lane 3 all zeros: xoshiro's forbidden state
    with pytest.raises(ValueError):
        fr.FastRng(bad)


@pytest.mark.parametrize("seed", [1, 2017, 987654321])
def test_normals_are_standard_normal(seed):
    x = fr.FastRng.from_seed(np.random.SeedSequence(seed)).standard_normal(N_DRAWS)
    n = x.size
    assert abs(x.mean()) < 5 / math.sqrt(n)
    assert abs(x.var() - 1) < 5 * math.sqrt(2 / n)
    assert abs(stats.skew(x)) < 5 * math.sqrt(6 / n)
    assert abs(stats.kurtosis(x)) < 5 * math.sqrt(24 / n)
    assert stats.kstest(x, "norm").pvalue > 1e-3
    # the tail beyond the base edge, sampled separately, at its N(0, 1) frequency
    p_tail = 2 * stats.norm.sf(fr.ZIG_R)
    count = int((np.abs(x) > fr.ZIG_R).sum())
    assert abs(count - n * p_tail) < 5 * math.sqrt(n * p_tail)
    # both signs equally often
    assert abs((x > 0).mean() - 0.5) < 5 * 0.5 / math.sqrt(n)


@pytest.mark.parametrize("seed", [3, 4])
def test_uniforms_are_uniform(seed):
    u = fr.FastRng.from_seed(np.random.SeedSequence(seed)).random(N_DRAWS)
    assert u.min() >= 0 and u.max() < 1
    assert stats.kstest(u, "uniform").pvalue > 1e-3
    # consecutive pairs uncorrelated
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 5 / math.sqrt(N_DRAWS)


# ---- the option in the methods ------------------------------------------------------------
def _run(method, random_numbers, seed=5, particles=300, duration_s=60.0):
    from tanbench.config import Scenario
    from tanbench.methods import run_method
    from tanbench.simulation import simulate_vehicle

    sc = Scenario(duration_s=duration_s, particles=particles, filter={"random_numbers": random_numbers})
    vehicle = simulate_vehicle(sc, np.random.SeedSequence(99))
    return run_method(sc, method, vehicle, np.random.SeedSequence(seed))


def _run_east(args):
    return np.asarray(_run(*args).series["est_e"])


def test_the_stream_is_in_the_key_and_not_in_the_world():
    from tanbench.config import Scenario

    assert Scenario().filter.random_numbers == "fast"
    numpy_stream = Scenario(filter={"random_numbers": "numpy"})
    assert numpy_stream.cell_key() != Scenario().cell_key()
    assert numpy_stream.world_key() == Scenario().world_key()  # same vehicle data: paired comparisons


@pytest.mark.parametrize("method", ["tight-dvl", "loose-dvl"])
def test_fast_runs_are_reproducible_in_a_spawned_worker(method):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    here = _run_east((method, "fast"))
    assert np.isfinite(here).all()
    np.testing.assert_array_equal(here, _run_east((method, "fast")))
    assert not np.array_equal(here, _run_east((method, "numpy")))  # another stream
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        there = pool.submit(_run_east, (method, "fast")).result()
    np.testing.assert_array_equal(here, there)


def test_systematic_resampling_draws_one_uniform():
    """Systematic resampling reads one uniform, the other schemes one per particle: the
    generator is advanced by exactly that."""
    from tanbench.filters.resample import Resampling
    from tanbench.filters.resample import MULTINOMIAL, REG_NONE, SYSTEMATIC, resample_and_regularise

    m = 50
    w = np.full(m, 1.0 / m)
    for scheme, draws in ((SYSTEMATIC, 1), (MULTINOMIAL, m)):
        rs = Resampling(scheme, 1.0 + 1e-9, REG_NONE, np.array([0], dtype=np.int64), 0.1, 0.0)
        gen = np.random.default_rng(1)
        x = np.arange(2.0 * m).reshape(2, m)
        resample_and_regularise(x, w, np.zeros(m), 0.5 * m, gen, rs, 2, 10.0, np.empty(m),
                                np.empty(m, dtype=np.int64), np.empty_like(x))
        replay = np.random.default_rng(1)
        replay.random(draws)
        assert replay.bit_generator.state == gen.bit_generator.state
