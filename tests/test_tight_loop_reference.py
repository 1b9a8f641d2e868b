"""The tight particle filter's loop and its initial clouds against their plain-numpy references.

``filters/tight_reference.py`` writes the jitted loop (``tight.tight_filter_loop`` without a search)
again from the numpy references of its kernels and of the generator (``rng.fill_numpy``); the
initial clouds (``cloud.uniform_horizontal``, ``tight.init_tight`` / ``draw_tight``, ``mpf.init_mpf``)
have references beside them. Fed the same cloud and the same generator state, each must draw the
same numbers and leave the generator in the same state (checked exactly).

The clouds agree to the last bit. The loop's outputs agree within ``RTOL`` = 1e-9 of each output
column's largest magnitude (the normwise error of a column; integers exactly): the kernels compute
sines and cosines about a reference angle with their own polynomials, exponentials and logarithms of
their own, sums over four accumulators, moments about the first particle and a Cholesky factor of
their own, where the references call numpy and LAPACK, so the two differ in the last bits of each
update (about 1e-13 of a column over these runs). Resampling, the divergence test and the re-draws
are discrete decisions that such differences could flip only if a value fell within ~1e-13 of a
threshold; on the runs below none does (the integer outputs and the final generator states are equal,
so every decision and every draw was the same). A different seed or scenario could in principle flip
one; the comparison would then fail at that update rather than drift.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba.core.dispatcher import Dispatcher

from filters_support import (assert_close_by_column, copy_of_rng, forbid_jitted_calls, same_rng_state,
                             short_scenario)
from tanbench.config import Scenario
from tanbench.filters import tight_reference as ref
from tanbench.filters.cloud import uniform_horizontal, uniform_horizontal_numpy
from tanbench.filters.likelihood import likelihood_grid
from tanbench.filters.mpf import N_MPF, init_mpf, init_mpf_numpy
from tanbench.filters.rng import fill_normals, fill_numpy, fill_uniforms, loop_rng, rng_state, set_rng_state
from tanbench.filters.state import E, N_TIGHT
from tanbench.filters.tight import (draw_tight, init_tight, new_tight_outputs, tight_filter_loop, tight_prior_of,
                                    tight_settings)
from tanbench.methods import get, method_context
from tanbench.methods import tight as tight_method
from tanbench.runner.seeds import vehicle_seed
from tanbench.simulation import simulate_vehicle

RTOL = 1e-9  # of each output column's largest magnitude (module docstring)
STREAMS = ["fast", "numpy-stream", "generator"]


def _stream(kind, seed):
    """(what a kernel draws from, an independent copy in the same state) for a stream kind: the fast
    generator's words, numpy's stream (``Pcg64Stream``) or a bare Generator (what ``mpf.run_mpf`` passes)."""
    if kind == "generator":
        return np.random.default_rng(seed), np.random.default_rng(seed)
    rng = loop_rng(np.random.default_rng(seed), "fast" if kind == "fast" else "numpy")
    return rng, copy_of_rng(rng)






# --------------------------------------------------------------------------------------
# the fills and the initial clouds
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", STREAMS)
def test_fill_numpy_draws_what_the_fills_draw(kind):
    """Fills of sizes below, at and beyond a round of the lanes and a chunk, one after the other."""
    rng, twin = _stream(kind, 11)
    for size in (1, 15, 16, 17, 333, 1024, 1025, 2600):
        for normal in (True, False):
            got = np.empty((2, size))
            if normal:
                fill_normals(rng, got)
            else:
                fill_uniforms(rng, got, -3.0, 5.5)
            want = fill_numpy(twin, (2, size), True) if normal else fill_numpy(twin, (2, size), False, -3.0, 5.5)
            np.testing.assert_array_equal(got, want, err_msg=f"size {size} normal {normal}")
        assert same_rng_state(rng, twin)


@pytest.mark.parametrize("kind", STREAMS)
@pytest.mark.parametrize("m", [300, 1037])
def test_initial_clouds_equal_their_references(kind, m):
    """uniform_horizontal, init_tight, draw_tight (a re-draw's own square) and init_mpf, in turn on one
    stream: the same clouds bit for bit, the stream left in the same state."""
    rng, twin = _stream(kind, [7, m])
    prior = tight_prior_of(Scenario(filter={"reinit_area_m": 40.0}).filter)
    x = np.full((N_TIGHT, m), np.nan)
    uniform_horizontal(x, rng, 1234.5, -678.25, 75.0)
    want = uniform_horizontal_numpy(np.full((N_TIGHT, m), np.nan), fill_numpy(twin, (2, m), False), 1234.5, -678.25,
                                    75.0)
    np.testing.assert_array_equal(x[:2], want[:2])
    assert np.isnan(x[2:]).all() and np.isnan(want[2:]).all()  # the other rows untouched
    assert np.abs(x[0] - 1234.5).max() <= 75.0 and np.abs(x[1] + 678.25).max() <= 75.0
    args = (5012.0, 3987.5, -31.0, 0.02, -0.01, 2.5)
    init_tight(x, rng, *args, prior)
    np.testing.assert_array_equal(x, ref.init_tight_numpy(x, twin, *args, prior))
    draw_tight(x, rng, *args, prior, prior.reinit_half_side)
    np.testing.assert_array_equal(x, ref.draw_tight_numpy(x, twin, *args, prior, prior.reinit_half_side))
    assert np.abs(x[E] - args[0]).max() <= prior.reinit_half_side
    xm = np.empty((N_MPF, m))
    init_mpf(xm, rng, 100.0, 200.0, -1.0, 75.0, 0.5, 4.0, 1e-8)
    np.testing.assert_array_equal(xm, init_mpf_numpy(xm, twin, 100.0, 200.0, -1.0, 75.0, 0.5, 4.0, 1e-8))
    assert same_rng_state(rng, twin)


# --------------------------------------------------------------------------------------
# the loop
# --------------------------------------------------------------------------------------
# (method, filter settings, start): each a short default scenario (120 s, 300 particles) with a few
# settings changed; "start" "off-map" draws the initial cloud 400 m east of the map instead of at the
# navigation solution (a deliberately wrong initial position: re-drawn, on the map, at the first update)
CASES = {
    "dvl-defaults": ("tight-dvl", {}, "nav"),
    "sbe-defaults": ("tight-sbe", {}, "nav"),
    # a converged cloud that spreads beyond 3 m counts as diverged: re-drawn around the last healthy estimate
    "sbe-last-healthy": ("tight-sbe", {"recovery": "last-healthy", "divergence_spread_m": 3.0}, "nav"),
    # collapsed clouds redrawn whole (filter.collapse_reinit: initial), a Gaussian initial cloud
    "dvl-collapse-gaussian": ("tight-dvl", {"collapse_reinit": "initial", "min_spread_m": 20.0,
                                            "initial_cloud": "gaussian"}, "nav"),
    # numpy's stream, the navigation's distance innovations, multinomial resampling, the re-spread
    "dvl-numpy-stream": ("tight-dvl", {"random_numbers": "numpy", "distance_innovation": "navigation",
                                       "resampling": "multinomial", "tight_min_spread_m": 5.0}, "nav"),
    "sbe-off-map": ("tight-sbe", {}, "off-map"),
}


def _loop_inputs(name, filt, start):
    """The loop's arguments as ``methods.tight.run_tight`` builds them (search None), and its cloud's start."""
    scenario = short_scenario(duration_s=120.0, particles=300, filter=filt)
    vehicle = simulate_vehicle(scenario, vehicle_seed(11, scenario, 0))
    ctx = method_context(scenario, name, vehicle, np.random.SeedSequence(5, spawn_key=(0, 1)), get(name))
    dvl = name == "tight-dvl"
    beams = np.ascontiguousarray(ctx.obs.dvl_beams if dvl else ctx.obs.sbe_beams)
    ranges = np.ascontiguousarray((ctx.obs.dvl_ranges if dvl else ctx.obs.sbe_ranges)[ctx.updates.rows])
    settings = tight_settings(scenario, ctx.nmap, beams.shape[0])
    x, rng = tight_method.tight_start(ctx, settings)
    if start == "off-map":
        k0 = ctx.updates.imu[0]
        nav = ctx.nav
        init_tight(x, rng, ctx.nmap.e_max + 400.0, nav.pos[k0, 1], nav.pos[k0, 2], nav.pitch[k0], nav.roll[k0],
                   nav.yaw[k0], settings.prior)
    grid = likelihood_grid(scenario.filter, ctx.nmap)
    return (x, rng, rng_state(rng), tight_method.tight_track(ctx), ranges, beams, grid, settings), ctx


def _run_both(inputs):
    """(the jitted loop's outputs and generator, the reference's) from the same cloud and generator state
    (the inputs' initial one: a case can run again); the reference run with every jitted function of
    tanbench's modules replaced by one that fails."""
    x, rng, state, track, ranges, beams, grid, settings = inputs
    set_rng_state(rng, state)
    x0, twin = x.copy(), copy_of_rng(rng)
    out = new_tight_outputs(ranges.shape[0])
    tight_filter_loop(x, rng, track, ranges, beams, grid, settings, out, None)
    assert np.array_equal(x, x0)  # the loop works on a copy
    with pytest.MonkeyPatch.context() as mp:
        forbid_jitted_calls(mp)
        want = ref.tight_loop_numpy(x0, twin, track, ranges, beams, grid, settings)
    return out, rng, want, twin




def test_the_reference_runs_without_jitted_functions():
    """What the loop comparisons rely on: the reference's module holds no jitted function, and inside
    :func:`filters_support.forbid_jitted_calls` one called through its module fails (the kernels' modules lose theirs)."""
    from tanbench.filters import tight as tight_module

    assert not [name for name, value in vars(ref).items() if isinstance(value, Dispatcher)]
    with pytest.MonkeyPatch.context() as mp:
        assert forbid_jitted_calls(mp) > 100
        with pytest.raises(AssertionError, match="jitted function was called"):
            tight_module.keep_on_map(np.zeros(2), np.array([1.0, 2.0, 1.0, 2.0]))


def assert_outputs_close(got, want, rng, twin, rtol=RTOL):
    """Every output of the loop: integers exactly, floats within ``rtol`` of each column's largest
    magnitude; the generators in the same state (every draw the same)."""
    assert same_rng_state(rng, twin), "the reference drew other random numbers"
    for field in got._fields:
        assert_close_by_column(field, getattr(got, field), getattr(want, field), rtol)


@pytest.fixture(scope="module")
def inputs():
    cache = {}

    def get_inputs(case):
        if case not in cache:
            cache[case] = _loop_inputs(*CASES[case])
        return cache[case]

    return get_inputs


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_loop_equals_its_reference(inputs, case):
    loop_inputs, ctx = inputs(case)
    got, rng, want, twin = _run_both(loop_inputs)
    assert_outputs_close(got, want, rng, twin)
    # what each case is there for happened
    assert not np.isnan(got.est).any() and (got.particles == 300).all() and (got.stages == 1).all()
    reinit = np.flatnonzero(got.reinit)
    if case == "sbe-last-healthy":
        assert reinit.size > 0 and got.healthy[:reinit[0]].any()  # re-drawn around a last healthy estimate
    elif case == "dvl-collapse-gaussian":
        assert reinit.size > 10
    elif case == "sbe-off-map":
        # clamped to the map's edge and re-drawn there, again and again (the lost cloud's particles off the
        # map, charged outside_map_sigma per beam, outweigh its particles on the map)
        assert reinit[0] == 0 and got.est[0, E] == ctx.nmap.e_max and reinit.size > 10
        assert (got.est[:, E] <= ctx.nmap.e_max).all()
    else:
        assert reinit.size == 0
    if case == "dvl-numpy-stream":
        assert not isinstance(rng, np.ndarray)


def test_a_perturbed_reference_is_caught(inputs, monkeypatch):
    """The comparison can fail: the reference with its regularisation bandwidth 1e-6 wider, or a re-draw's
    square 1 mm wider, no longer agrees (the generators still do: only the numbers change)."""
    loop_inputs, _ = inputs("dvl-defaults")
    bandwidth = ref.posterior_bandwidth
    with monkeypatch.context() as mp:
        mp.setattr(ref, "posterior_bandwidth", lambda d, m, factor: bandwidth(d, m, factor) * (1.0 + 1e-6))
        got, rng, want, twin = _run_both(loop_inputs)
    with pytest.raises(AssertionError, match="first difference"):
        assert_outputs_close(got, want, rng, twin)
    loop_inputs, _ = inputs("sbe-last-healthy")
    square = ref.recovery_square_numpy
    with monkeypatch.context() as mp:
        mp.setattr(ref, "recovery_square_numpy", lambda *a: square(*a)[:2] + (square(*a)[2] + 1e-3,))
        got, rng, want, twin = _run_both(loop_inputs)
    with pytest.raises(AssertionError, match="first difference"):
        assert_outputs_close(got, want, rng, twin)


@pytest.mark.parametrize("filt, search", [({"propagation": "euler-last-second"}, None),
                                          ({"tight_regularisation": "shared"}, None),
                                          ({"tempering_ess": 0.5}, None),
                                          ({"kld_epsilon": 0.05}, None),
                                          ({}, "a search")])
def test_settings_outside_the_reference_are_refused(filt, search):
    scenario = Scenario(filter=filt)
    settings = tight_settings(scenario, _TinyMap(), 4)
    with pytest.raises(ValueError, match="default path only"):
        ref.check_scope(settings, search)
    if search is None:
        with pytest.raises(ValueError, match="default path only"):
            ref.tight_loop_numpy(np.zeros((N_TIGHT, 4)), None, None, np.zeros((1, 4)), np.zeros((4, 3)), None,
                                 settings)


class _TinyMap:
    """What tight_settings reads of a navigation map (the bounds of filter.keep_on_map)."""
    e0, n0, e_max, n_max = 0.0, 0.0, 100.0, 100.0


def test_the_default_settings_are_in_scope():
    scenario = Scenario()
    ref.check_scope(tight_settings(scenario, _TinyMap(), 4))
    assert tight_settings(scenario, _TinyMap(), 4).model.sig_bias > 0.0  # the bias walk is on the default path
    assert math.isfinite(tight_settings(scenario, _TinyMap(), 1).rs.size)
