"""The other estimators' loops (point-mass filter, TERCOM, iterated EKF, marginalized PF) against their
plain-numpy references.

``filters/estimator_reference.py`` writes each jitted loop again from the numpy references of its kernels
(``pmf.pmf_loop``, ``tercom.tercom_loop``, ``ekf.ekf_loop``, ``mpf.mpf_loop``; for the MPF also of the
generator's fills, ``rng.fill_numpy``). Both are fed the same inputs, built from a short default scenario
(120 s, 300 particles) as ``tanbench/methods/<name>.py`` builds them (checked: the method's own run gives
the loop's east estimates bit for bit), and the MPF's two runs start from the same cloud and generator
state, which must end in the same state (checked exactly). The references run with every jitted function
of tanbench's modules replaced by one that fails.

Every output agrees within ``RTOL`` = 1e-9 of each output column's largest magnitude (the normwise error
of a column; integers exactly), the loops' final states (the EKF's state and covariance, the MPF's cloud)
as well. A variance column may in addition differ by (``RTOL`` x its state's largest magnitude)^2: the
spread over the cloud of the MPF's Kalman variances (``var``'s columns P_b and P_eps) is 0 in the kernel,
every particle's being the same (moments about the first particle), and about 1e-34 in numpy (moments
about the mean): a column made of rounding alone. Elsewhere the kernels sum in their own orders and take
moments about a grid's centre or the first particle, the MPF's with sines, cosines and exponentials of
their own and Sherman-Morrison's closed form, where the references call numpy and LAPACK: they differ in
the last bits of each update, between 1e-16 and 4e-12 of a column over these runs (the largest the
single-beam PMF's variances). The discrete decisions (blurring, re-gridding, fixes, gates, divergence,
resampling) could flip only for a value within that of a threshold; on the runs below none does (the
integer outputs and the generator states are equal).

How far rounding can grow depends on the run, not only on the code: in a PMF run whose posterior is split
between two distant modes (a tide bias it does not model) the kernel itself, its beam offsets changed by
1e-15, moves by up to 2e-8 of a column, and so does the reference; such a run needs a wider tolerance,
and the cases below keep to runs where the kernel is not that sensitive.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
import pytest
from numba.core.dispatcher import Dispatcher

from filters_support import (assert_close_by_column, copy_of_rng, forbid_jitted_calls, same_rng_state,
                             short_scenario)
from tanbench.filters import ekf, mpf, pmf, resample, tercom
from tanbench.filters import estimator_reference as ref
from tanbench.filters.beams import nav_frame_offsets
from tanbench.filters.resample import MULTINOMIAL, RESIDUAL, STRATIFIED, SYSTEMATIC, Resampling
from tanbench.filters.rng import loop_rng, rng_state
from tanbench.methods import get, method_context
from tanbench.navigation.increments import D0E, D0N, SZ, nav_at_updates
from tanbench.options import REGULARISATION
from tanbench.runner.seeds import vehicle_seed
from tanbench.simulation import simulate_vehicle
from tanbench.terrain.grid import Map, MapArgs, node_grid_of

RTOL = 1e-9  # of each output column's largest magnitude (module docstring)
DROPOUTS = {"dropout_rate_per_ping": 0.05}  # bottom-lock dropouts: beams and whole updates without a range


def assert_outputs_close(got, want, rtol=RTOL):
    """Every output of a loop (a run's ``outputs``, ``finals`` and generators): each output field and final
    state (module docstring), then the generators' states (every draw the same). The outputs first: a
    decision taken otherwise shows as the first update that differs."""
    est_scale = np.abs(want.outputs.est).max(axis=0)
    for field in got.outputs._fields:
        floor = (rtol * est_scale) ** 2 if field == "var" else 0.0
        assert_close_by_column(field, getattr(got.outputs, field), getattr(want.outputs, field), rtol, floor)
    for name, a in got.finals.items():
        assert_close_by_column(name, a, want.finals[name], rtol)
    if got.rng is not None:
        assert same_rng_state(got.rng, want.rng), "the reference drew other random numbers"


# --------------------------------------------------------------------------------------
# the loops' inputs, as the methods build them, and the two runs
# --------------------------------------------------------------------------------------
# a run: the outputs a loop fills, its final states (arrays, a row per particle or one row), its generator
Run = namedtuple("Run", "outputs finals rng")


def _context(method, overrides):
    scenario = short_scenario(duration_s=120.0, particles=300, **overrides)
    vehicle = simulate_vehicle(scenario, vehicle_seed(11, scenario, 0))
    return method_context(scenario, method, vehicle, np.random.SeedSequence(5, spawn_key=(0, 1)), get(method))


def _sonar(ctx):
    """(nav at the updates, offsets (K, m, 3)) of the method's sensor, as its ``run_*`` projects them."""
    obs = ctx.obs
    sbe = ctx.name == "pmf-sbe"
    beams = obs.sbe_beams if sbe else obs.dvl_beams
    ranges = (obs.sbe_ranges if sbe else obs.dvl_ranges)[ctx.updates.rows]
    nav = nav_at_updates(ctx.nav, ctx.updates.imu)
    return nav, nav_frame_offsets(nav.pitch, nav.roll, nav.yaw, beams, ranges)


def _pmf_args(ctx):
    """``pmf_loop``'s arguments as ``filters.pmf.run_pmf`` builds them."""
    nav, offsets = _sonar(ctx)
    nav_en = np.ascontiguousarray(nav.en, dtype=float)
    track = pmf.PmfTrack(nav_en, np.ascontiguousarray(nav.up, dtype=float), np.ascontiguousarray(nav.yaw, dtype=float),
                         np.ascontiguousarray(np.diff(nav_en, axis=0)))
    return track, offsets, node_grid_of(*ctx.nmap.kernel_args()), pmf.pmf_settings(ctx.scenario, ctx.options)


def _pmf_jitted(args):
    k = args[0].en.shape[0]
    out = pmf.PmfOutputs(np.empty((k, 3)), np.empty((k, 3)), np.zeros(k, dtype=np.int64), np.zeros(k, dtype=np.int64))
    pmf.pmf_loop(*args, out)
    return Run(out, {}, None)


def _tercom_args(ctx):
    """``tercom_loop``'s arguments as ``filters.tercom.run_tercom`` builds them."""
    nav, offsets = _sonar(ctx)
    nav_en = np.asarray(nav.en, dtype=float)
    return (np.ascontiguousarray(np.diff(nav_en, axis=0)), offsets, np.ascontiguousarray(nav.up, dtype=float),
            nav_en[0, 0], nav_en[0, 1], MapArgs(*ctx.nmap.kernel_args()),
            tercom.tercom_settings(ctx.scenario, ctx.options))


def _tercom_jitted(args):
    k = args[1].shape[0]
    out = tercom.TercomOutputs(np.empty((k, 3)), np.empty((k, 3)), np.zeros(k, dtype=np.int64))
    tercom.tercom_loop(*args, out)
    return Run(out, {}, None)


def _ekf_args(ctx):
    """``ekf_loop``'s arguments as ``filters.ekf.run_ekf`` builds them (the initial state and covariance first)."""
    nav, offsets = _sonar(ctx)
    s = ekf.ekf_settings(ctx.scenario, ctx.options)
    inc = ctx.increments()
    x = np.array([nav.en[0, 0], nav.en[0, 1], 0.0, 0.0])
    p = np.diag([s.initial_area_m**2 / 12.0, s.initial_area_m**2 / 12.0, s.std_heading ** 2, s.std_bias ** 2])
    return (x, p, np.ascontiguousarray(inc[:, [D0E, D0N]]), np.ascontiguousarray(inc[:, SZ]), offsets,
            np.ascontiguousarray(nav.up, dtype=float), MapArgs(*ctx.nmap.kernel_args()), s)


def _ekf_jitted(args):
    x, p = args[0].copy(), args[1].copy()
    k = args[4].shape[0]
    out = ekf.EkfOutputs(np.empty((k, ekf.NX)), np.empty((k, ekf.NX)), np.zeros(k, dtype=np.int64))
    ekf.ekf_loop(x, p, *args[2:], out)
    return Run(out, {"x": x[None], "p": p}, None)


def _ekf_reference(args):
    out, x, p = ref.ekf_loop_numpy(*args)
    return Run(out, {"x": x[None], "p": p}, None)


def _mpf_args(ctx):
    """``mpf_loop``'s arguments as ``filters.mpf.run_mpf`` builds them: its initial cloud drawn from the
    run's Generator, then that Generator's state (for the two runs to start from)."""
    nav, offsets = _sonar(ctx)
    settings = mpf.mpf_settings(ctx.scenario, ctx.options)
    nav_en = np.asarray(nav.en, dtype=float)
    nav_yaw = np.ascontiguousarray(nav.yaw, dtype=float)
    x = np.empty((mpf.N_MPF, settings.particles))
    pr = settings.prior
    mpf.init_mpf(x, ctx.rng, nav_en[0, 0], nav_en[0, 1], nav_yaw[0], pr.half_side, pr.std_yaw, pr.var_b, pr.var_eps)
    track = mpf.MpfTrack(np.ascontiguousarray(ctx.increments()), nav_yaw, np.ascontiguousarray(nav.up, dtype=float))
    return x, rng_state(ctx.rng), track, offsets, MapArgs(*ctx.nmap.kernel_args()), settings


def _mpf_jitted(args):
    x, rng = args[0].copy(), _state_holder(args[1])
    k = args[3].shape[0]
    out = mpf.MpfOutputs(np.empty((k, mpf.N_MPF)), np.empty((k, mpf.N_MPF)), np.empty(k), np.zeros(k, dtype=np.int64))
    mpf.mpf_loop(x, rng, *args[2:], out)
    return Run(out, {"cloud": x.T}, rng)


def _mpf_reference(args):
    rng = _state_holder(args[1])
    out, x = ref.mpf_loop_numpy(args[0].copy(), rng, *args[2:])
    return Run(out, {"cloud": x.T}, rng)


def _state_holder(state):
    """A Generator in the PCG64 ``state`` (what ``copy_of_rng`` copies)."""
    g = np.random.Generator(np.random.PCG64())
    g.bit_generator.state = state
    return g


# a loop family: its arguments from a method context, the jitted run and the reference's run of them
Family = namedtuple("Family", "args jitted reference")
FAMILIES = {
    "pmf": Family(_pmf_args, _pmf_jitted, lambda a: Run(ref.pmf_loop_numpy(*a), {}, None)),
    "tercom": Family(_tercom_args, _tercom_jitted, lambda a: Run(ref.tercom_loop_numpy(*a), {}, None)),
    "ekf": Family(_ekf_args, _ekf_jitted, _ekf_reference),
    "mpf": Family(_mpf_args, _mpf_jitted, _mpf_reference),
}

# case: (family, method, scenario overrides); each a short default scenario with a few settings changed
CASES = {
    "pmf-dvl-defaults": ("pmf", "pmf-dvl", {}),
    "pmf-sbe-defaults": ("pmf", "pmf-sbe", {}),
    # the position-only PMF on an odd grid, with updates and beams without a range
    "pmf-position-only-dropouts": ("pmf", "pmf-dvl", {"method_options": {"pmf-dvl": {"headings": 1, "cells": 17}},
                                                      "faults": DROPOUTS}),
    # an 8 m tide bias the PMF does not model: the beams no longer fit, it diverges and re-initialises
    "pmf-tide-reinit": ("pmf", "pmf-dvl", {"faults": {"tide_bias_m": 8.0}}),
    "tercom-defaults": ("tercom", "tercom-dvl", {}),
    # the MAD metric, one heading, beams and whole updates without a range
    "tercom-mad-position-only-dropouts": ("tercom", "tercom-dvl", {
        "method_options": {"tercom-dvl": {"metric": "mad", "headings": 1}}, "faults": DROPOUTS}),
    "ekf-defaults": ("ekf", "ekf-dvl", {}),
    # one Gauss-Newton pass and no gate; updates without a usable beam are skipped
    "ekf-one-pass-dropouts": ("ekf", "ekf-dvl", {"method_options": {"ekf-dvl": {"iterations": 1, "gate": 1e9}},
                                                 "faults": DROPOUTS}),
    "mpf-defaults": ("mpf", "mpf-dvl", {}),
    # a 10 m tide bias against a depth-bias prior of 1 cm: the beams do not fit, the MPF re-initialises
    "mpf-tide-reinit": ("mpf", "mpf-dvl", {"faults": {"tide_bias_m": 10.0},
                                           "method_options": {"mpf-dvl": {"initial_std_depth_bias_m": 0.01}}}),
    # multinomial resampling, Gordon roughening, the re-spread of every resampled cloud below 50 m
    "mpf-multinomial-gordon-respread": ("mpf", "mpf-dvl", {"filter": {"resampling": "multinomial",
                                                                      "regularisation": "gordon",
                                                                      "min_spread_m": 50.0}}),
    # residual resampling, no regularisation, dropouts
    "mpf-residual-unregularised-dropouts": ("mpf", "mpf-dvl", {"filter": {"resampling": "residual",
                                                                          "regularisation": "none"},
                                                               "faults": DROPOUTS}),
}


@pytest.fixture(scope="module")
def runs():
    """case -> (the loop's arguments, the method context and its generator's initial state, the jitted run),
    each built once."""
    cache = {}

    def get_run(case):
        if case not in cache:
            family, method, overrides = CASES[case]
            ctx = _context(method, overrides)
            start = rng_state(ctx.rng)
            args = FAMILIES[family].args(ctx)
            cache[case] = (args, (ctx, start), FAMILIES[family].jitted(args))
        return cache[case]

    return get_run


def _reference_run(case, args):
    """The reference's run, with every jitted function of tanbench's modules replaced by one that fails."""
    with pytest.MonkeyPatch.context() as mp:
        forbid_jitted_calls(mp)
        return FAMILIES[CASES[case][0]].reference(args)


@pytest.mark.parametrize("case", list(CASES))
def test_the_loop_equals_its_reference(runs, case):
    args, (ctx, start), got = runs(case)
    want = _reference_run(case, args)
    assert_outputs_close(got, want)
    family = CASES[case][0]
    out = got.outputs
    # the inputs are the method's: its own run (from the generator's initial state) gives the loop's
    # estimates bit for bit
    ctx.rng.bit_generator.state = start
    np.testing.assert_array_equal(get(ctx.name).run(ctx).east, out.est[:, 0])
    # what each case is there for happened
    dropped = np.isnan(args[1 if family in ("pmf", "tercom") else 4 if family == "ekf" else 3][..., 2])
    if "dropouts" in case:
        assert dropped.any(axis=1).sum() > 5 and dropped.all(axis=1).any()
    if family in ("pmf", "mpf"):
        reinit = np.flatnonzero(out.reinit)
        assert (reinit.size > 0) == ("reinit" in case), reinit
    if family == "pmf":
        assert (out.live == 1).all() if "position-only" in case else (out.live.max() == 15 and out.live.min() < 15)
    elif family == "tercom":
        settings = args[-1]  # a match every ``interval`` updates once the profile is full
        matches = [k for k in range(out.fixes.size) if k >= settings.profile_len - 1 and k % settings.interval == 0]
        fixed = out.fixes[matches].sum()
        assert out.fixes.sum() == fixed > 0 and (fixed < len(matches)) == ("mad" in case)
        assert (out.est[:, 2] == 0.0).all() == ("position-only" in case)
    elif family == "ekf":
        assert (out.rejected.sum() > 10) == (case == "ekf-defaults")
    else:
        resampled = (out.ess < 150.0) & (out.reinit == 0)  # below the ESS threshold, 0.5 M
        assert resampled.any() and (resampled.all() == ("gordon" in case))
        if "respread" in case:  # a resampled cloud below min_spread_m (50 m) re-spread
            assert (resampled & (out.var[:, mpf.E] + out.var[:, mpf.N] < 50.0**2)).any()


def test_a_perturbed_reference_is_caught(runs, monkeypatch):
    """The comparison can fail for every loop, on its main path and on its re-initialisation: each reference
    with one of its kernels' numbers changed by 1e-6 (or a re-drawn grid or cloud moved by 1 mm) no
    longer agrees (the MPF's main-path mutation draws the same numbers; its cloud re-drawn 1 mm away, in a
    run that keeps diverging, changes a later decision, and the draws with it)."""
    mutations = [
        ("pmf-dvl-defaults", "blur_separable_numpy", lambda f: lambda p, sig: f(p, sig * (1.0 + 1e-6))),
        ("pmf-tide-reinit", "pmf_init_numpy", _after_the_first(lambda f: lambda shape, d, e, nn, sig: f(shape, d,
                                                                                                        e + 1e-3, nn,
                                                                                                        sig))),
        ("tercom-defaults", "surface_likelihood_moments_numpy",
         lambda f: lambda *a: tuple(v * (1.0 + 1e-6) for v in f(*a))),
        ("ekf-defaults", "ekf_predict_numpy", lambda f: lambda x, p, de, dn, sz, qp, qd, qb: f(x, p, de, dn, sz,
                                                                                          qp * (1.0 + 1e-6), qd, qb)),
        ("mpf-defaults", "mpf_propagate_numpy", lambda f: lambda x, inc, yaw, noise, sig, *a: f(x, inc, yaw, noise,
                                                                                              sig * (1.0 + 1e-6), *a)),
        ("mpf-tide-reinit", "init_mpf_numpy", lambda f: lambda x, rng, e, *a: f(x, rng, e + 1e-3, *a)),
    ]
    for case, name, mutate in mutations:
        args, _, got = runs(case)
        with monkeypatch.context() as mp:
            mp.setattr(ref, name, mutate(getattr(ref, name)))
            want = _reference_run(case, args)
        with pytest.raises(AssertionError, match="first difference"):
            assert_outputs_close(got, want)


def _after_the_first(mutation):
    """``mutation`` of a function from its second call on (the first draws the PMF's initial grid, the
    others re-initialise it)."""
    def mutate(f):
        changed, calls = mutation(f), []

        def call(*args):
            calls.append(1)
            return (changed if len(calls) > 1 else f)(*args)

        return call

    return mutate


def test_the_references_run_without_jitted_functions():
    """What the loop comparisons rely on: the reference's module holds no jitted function, and inside
    :func:`filters_support.forbid_jitted_calls` one called through its module fails (the kernels' modules lose theirs)."""
    assert not [name for name, value in vars(ref).items() if isinstance(value, Dispatcher)]
    with pytest.MonkeyPatch.context() as mp:
        assert forbid_jitted_calls(mp) > 100
        for call in (lambda: pmf.pmf_init(np.zeros((1, 2, 2)), np.zeros((1, 2)), np.zeros(1), 0.0, 0.0, 1.0),
                     lambda: tercom._best(np.zeros((1, 1, 1))),
                     lambda: resample.effective_sample_size(np.ones(4))):
            with pytest.raises(AssertionError, match="jitted function was called"):
                call()


def test_a_wound_yaw_is_refused():
    """The MPF's reference refuses a cloud whose yaw is wound beyond trig.WOUND / 2 from the navigation's."""
    scenario = short_scenario(duration_s=120.0, particles=4)
    settings = mpf.mpf_settings(scenario, get("mpf-dvl").parse_options(scenario))
    x = np.zeros((mpf.N_MPF, 4))
    x[mpf.PSI, 2] = 1e5
    track = mpf.MpfTrack(np.zeros((0, 12)), np.zeros(1), np.zeros(1))
    with pytest.raises(ValueError, match="wound"):
        ref.mpf_loop_numpy(x, np.random.default_rng(0), track, np.zeros((1, 4, 3)),
                           MapArgs(np.zeros((2, 2)), 0.0, 0.0, 1.0, 1.0), settings)


# --------------------------------------------------------------------------------------
# the kernels' references the loops' references added
# --------------------------------------------------------------------------------------
def test_a_blur_wider_than_the_grid_equals_its_reference():
    """``blur_separable`` against its reference with a kernel of more taps than the grid has nodes
    (``mode="same"`` gave the kernel's length there). (``pmf_init``'s: tests/test_kernel_references_more.py.)"""
    rng = np.random.default_rng(3)
    for shape, sigma in (((9, 9), 3.0), ((6, 11), 2.4), ((17, 17), 1.7)):
        p = rng.random(shape)
        got = p.copy()
        pmf.blur_separable(got, sigma, np.empty_like(got))
        assert 2 * int(np.ceil(3 * sigma)) + 1 > min(shape) or shape == (17, 17)
        np.testing.assert_allclose(got, pmf.blur_separable_numpy(p, sigma), rtol=1e-12, atol=1e-15)


def test_tercom_best_and_collect_equal_their_references():
    rng = np.random.default_rng(4)
    s = rng.random((3, 5, 5))
    s[1, 2, 3] = s[2, 0, 1] = -1.0  # a tie: the first in (d, i, j) order
    s[0, 0, 0] = np.nan
    for surface in (s, np.full((2, 3, 3), np.inf)):
        assert tercom._best(surface) == ref.best_numpy(surface)
    assert ref.best_numpy(s) == (-1.0, 1, 2, 3)
    buf = rng.random((3, 4, 5))
    buf[2, 1, 3] = buf[2, 3, :] = np.nan
    pe, pn, ph = np.empty(20), np.empty(20), np.empty(20)
    for count in (4, 2):
        npts = tercom._collect(buf[0], buf[1], buf[2], count, pe, pn, ph)
        want = tercom.collect_numpy(buf[0], buf[1], buf[2], count)
        for a, b in zip((pe, pn, ph), want):
            np.testing.assert_array_equal(a[:npts], b)


def test_iekf_update_counts_a_beam_on_level_map_as_the_kernel_does():
    """On a level map every usable beam has a Jacobian row of zeros: the kernel still counts it (and updates
    nothing); the reference used to return "no usable beam" there."""
    level = MapArgs(*Map(np.full((50, 50), -80.0), 0.0, 0.0, 10.0, 10.0).kernel_args())
    offs = np.array([[10.0, 10.0, -40.0], [-10.0, 10.0, -41.0], [10.0, -10.0, np.nan], [-10.0, -10.0, -39.0]])
    x = np.array([250.0, 250.0, 0.1, 1e-5])
    p = np.diag([100.0, 100.0, 0.01, 1e-10])
    for iterations in (1, 3):
        xk, pk = x.copy(), p.copy()
        nis, used = ekf.iekf_update(xk, pk, offs, -40.0, level, 10.0, 1.0, iterations, 1e9)
        xr, pr, nis_r, used_r = ekf.iekf_update_numpy(x, p, offs, -40.0, level, 10.0, 1.0, iterations, 1e9)
        assert used == used_r == 3 and nis == pytest.approx(nis_r, rel=1e-12)
        np.testing.assert_allclose(xk, xr, rtol=1e-12)
        np.testing.assert_allclose(pk, pr, rtol=1e-12)
