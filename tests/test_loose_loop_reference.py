"""The loose TAN's loops against their plain-numpy references.

``filters/loose_reference.py`` writes each jitted loop again from the numpy references of its kernels and of
the generator's fills (``rng.fill_numpy``): ``loose.loose_filter_loop`` (fix-only), ``loose.loose_kalman_loop``
(Kalman feedback) and ``loose_turned.loose_turned_loop`` (Kalman feedback with heading-offset particles, the
recommended default). The loops' inputs are the method's own: ``loose-dvl`` runs on a short scenario (160 s,
300 particles) with the loop it selects replaced by a recorder that keeps copies of the loop's arguments (its
initial cloud, generator state and KF covariance) before calling it, and its outputs and final arrays after.
The reference then runs from the same cloud and generator state, with every jitted function of tanbench's
modules replaced by one that fails, and must end with the generator in the same state (checked exactly).

Every output agrees within ``RTOL`` = 1e-9 of each output column's largest magnitude (the normwise error of a
column; integers exactly), the final cloud and KF covariance as well: the kernels compute sines and cosines
with their own polynomials, fastmath reciprocals, sums over four accumulators, moments about the first
particle and 2x2 inverses in closed form, where the references call numpy and LAPACK; they differ in the last
bits of each update, between 1e-14 and 1.4e-11 of a column on these runs (the largest the Kalman-feedback loop's
z-gyro bias estimate, after its KF was reopened). The discrete decisions (convergence and fit counts, fixes
accepted, rejected or refused, the KF reopened, divergence, keep-on-map, resampling) could flip only for a value
within that rounding of a threshold; on the runs below none does (the integer outputs and the generator states are
equal). Two runs, off the map, are the jitted loop's own from the method's arguments with the initial cloud and the
navigation's start moved 400 m east of the map.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
import pytest
from numba.core.dispatcher import Dispatcher

from filters_support import (assert_close_by_column, copy_of_rng, forbid_jitted_calls, same_rng_state,
                             short_scenario)
from tanbench.filters import loose, loose_turned
from tanbench.filters import loose_reference as ref
from tanbench.filters.loose import FixOnlyOutputs, KalmanOutputs
from tanbench.filters.likelihood import Likelihood, beam_constants, new_likelihood_work
from tanbench.filters.state import N_TIGHT, YAW
from tanbench.filters.tight_reference import grid_maps
from tanbench.filters.trig import attitude_reference
from tanbench.methods import get, method_context
from tanbench.methods import loose as loose_method
from tanbench.runner.seeds import vehicle_seed
from tanbench.simulation import simulate_vehicle
from tanbench.terrain.grid import Map, node_grid

RTOL = 1e-9  # of each output column's largest magnitude (module docstring)

# the loose TAN without heading offsets: the options that only the turned loop reads at their neutral values
NO_OFFSETS = {"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
              "loose_fix_fit_one_wild_beam": False, "loose_reopen_heading": "navigation",
              "loose_reopen_position": "prior", "loose_fix_correlation_s": 0.0}
FIX_ONLY = {**NO_OFFSETS, "loose_architecture": "fix-only"}

# case: (the loop, scenario overrides, vehicle run, start); each a short default scenario (160 s, 300 particles)
# with a few settings changed; start "off-map" moves the initial cloud and the navigation's start 400 m east of the
# map (then the jitted loop runs again from the recorded arguments so moved)
Case = namedtuple("Case", "loop overrides run start", defaults=("nav",))
GATE = {"loose_fix_interval_s": 3.0}  # a fix attempt every 3 updates: more fixes, more rejections
CASES = {
    # converged: the navigation corrected by the filter's fixes
    "fix-only": Case("fix-only", {"filter": FIX_ONLY}, 11),
    # an 8 m tide bias: the beams do not fit, the filter diverges and is re-drawn as a Gaussian cloud; multinomial
    # resampling, numpy's stream
    "fix-only-tide-gaussian": Case("fix-only", {"filter": {**FIX_ONLY, "initial_cloud": "gaussian",
                                                           "resampling": "multinomial", "random_numbers": "numpy"},
                                                "faults": {"tide_bias_m": 8.0}}, 11),
    # collapsed clouds redrawn whole (filter.collapse_reinit: initial), residual resampling, Gordon roughening
    "fix-only-collapse": Case("fix-only", {"filter": {**FIX_ONLY, "collapse_reinit": "initial", "min_spread_m": 20.0,
                                                      "resampling": "residual", "regularisation": "gordon"}}, 12),
    # a 1.0 chi-square gate: fixes accepted and rejected, the locked-out KF reopened
    "kalman-gate": Case("kalman", {"filter": {**NO_OFFSETS, **GATE, "loose_fix_gate": 1.0}}, 11),
    # an 8 m tide bias: the filter diverges, is re-initialised, and its next fix resets the KF's position again;
    # numpy's stream
    "kalman-tide-reinit": Case("kalman", {"filter": {**NO_OFFSETS, "random_numbers": "numpy"},
                                          "faults": {"tide_bias_m": 8.0}}, 12),
    "kalman-off-map": Case("kalman", {"filter": NO_OFFSETS}, 11, "off-map"),
    # the recommended defaults
    "turned": Case("turned", {}, 11),
    # a tide bias: divergence and re-initialisation; updates that fail the fit by one wild beam keep the count
    "turned-tide": Case("turned", {"faults": {"tide_bias_m": 8.0}}, 11),
    # a 0.2 chi-square gate on independent fixes: rejected fixes, the KF reopened with the cloud's heading, and the
    # fix the reopened KF still rejects setting its position
    "turned-gate": Case("turned", {"filter": {**GATE, "loose_fix_gate": 0.2, "loose_fix_correlation_s": 0.0}}, 11),
    # the fix-prior gate refusing fixes; beams with wild ranges and without bottom lock; numpy's stream
    "turned-prior-refused": Case("turned", {"filter": {**GATE, "loose_fix_prior_gate": 1.0, "random_numbers": "numpy"},
                                            "faults": {"outlier_fraction": 0.05, "dropout_rate_per_ping": 0.05}},
                                 12),
    # the fix-prior gate's fallback, the posterior first fix, a tight bias gate, no fit test and no shape gate
    "turned-fallback": Case("turned", {"filter": {**GATE, "loose_fix_prior_gate": 1.0,
                                                  "loose_fix_prior_fallback": "posterior",
                                                  "loose_first_fix": "posterior",
                                                  "loose_bias_gate_sigma": 0.05, "loose_fix_fit_test": False,
                                                  "loose_fix_fit_one_wild_beam": False, "loose_fix_shape": None}}, 11),
    "turned-off-map": Case("turned", {}, 11, "off-map"),
}


# --------------------------------------------------------------------------------------
# the loops' arguments, recorded from the method's run
# --------------------------------------------------------------------------------------
# a run: the loop's arguments (the initial cloud, the generator's initial state and the rest, as the reference
# takes them), its outputs, its final arrays (the cloud, a row per particle; the KF's covariance) and its generator
# after the run
Run = namedtuple("Run", "args outputs finals rng")
LOOPS = {"fix-only": "loose_filter_loop", "kalman": "loose_kalman_loop", "turned": "loose_turned_loop"}
REFERENCES = {"fix-only": ref.loose_filter_loop_numpy, "kalman": ref.loose_kalman_loop_numpy,
              "turned": ref.loose_turned_loop_numpy}


def _finals(x, p_kf):
    return {"cloud": x.T.copy()} if p_kf is None else {"cloud": x.T.copy(), "p_kf": p_kf.copy()}


def _record_loop(case):
    """Run loose-dvl on the case's scenario with its loop recorded (module docstring): the jitted run."""
    loop, overrides, run, _ = CASES[case]
    scenario = short_scenario(duration_s=160.0, particles=300, **overrides)
    vehicle = simulate_vehicle(scenario, vehicle_seed(run, scenario, 0))
    ctx = method_context(scenario, "loose-dvl", vehicle, np.random.SeedSequence(5, spawn_key=(0, 3)), get("loose-dvl"))
    assert loose_method.loop_kind(scenario.filter) == loop
    jitted = getattr(loose_method, LOOPS[loop])
    seen = []

    def recorder(x, rng, *rest):
        *args, out = rest
        p_kf, start = (None, None) if loop == "fix-only" else (args.pop(), out.en[0].copy())
        x0, state, p0 = x.copy(), copy_of_rng(rng), None if p_kf is None else p_kf.copy()
        jitted(x, rng, *rest)
        seen.append(Run((x0, state, *args) if p_kf is None else (x0, state, *args, p0, start), out,
                        _finals(x, p_kf), rng))

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(loose_method, LOOPS[loop], recorder)
        get("loose-dvl").run(ctx)
    assert len(seen) == 1
    return seen[0]


def _jitted_run(loop, args):
    """The jitted loop's run of the reference's arguments ``args`` (from a copy of the generator's state)."""
    x0, state, *rest = args
    x, rng = x0.copy(), copy_of_rng(state)
    if loop == "fix-only":
        k = rest[1].shape[0]
        out = FixOnlyOutputs(np.empty((k, 2)), np.empty((k, 2)), np.empty(k), np.empty(k),
                             np.zeros(k, dtype=np.int64), np.zeros(k, dtype=np.int64))
        loose.loose_filter_loop(x, rng, *rest, out)
        return Run(args, out, _finals(x, None), rng)
    *middle, p0, start = rest
    k = middle[0].yaw.shape[0]
    out = KalmanOutputs(np.empty((k, 2)), np.empty(k), np.empty(k), np.empty((k, 2)), np.empty(k), np.empty(k),
                        *(np.zeros(k, dtype=np.int64) for _ in range(4)))
    out.en[0] = start
    p = p0.copy()
    (loose.loose_kalman_loop if loop == "kalman" else loose_turned.loose_turned_loop)(x, rng, *middle, p, out)
    return Run(args, out, _finals(x, p), rng)


def _moved_off_the_map(args):
    """``args`` with the initial cloud and the navigation's start moved 400 m east of the map (its guard's east
    bound)."""
    x0, state, *middle, p0, start = args
    settings = next(a for a in middle if hasattr(a, "guard"))
    shift = settings.guard.bounds[1] + 400.0 - start[0]
    x0 = x0.copy()
    x0[0] += shift
    return (x0, state, *middle, p0, start + np.array([shift, 0.0]))


def _reference_run(case, args):
    """The reference's run of ``args`` (from a copy of the generator's state: a case can run again), with every
    jitted function of tanbench's modules replaced by one that fails."""
    x0, state, *rest = args
    rng = copy_of_rng(state)
    with pytest.MonkeyPatch.context() as mp:
        forbid_jitted_calls(mp)
        out, x, *p = REFERENCES[CASES[case].loop](x0.copy(), rng, *rest)
    return Run(args, out, _finals(x, p[0] if p else None), rng)


def assert_runs_close(got, want, rtol=RTOL):
    """Every output of a loop, then its final arrays, then the generators' states (every draw the same). The
    outputs first: a decision taken otherwise shows as the first update that differs."""
    for field in got.outputs._fields:
        assert_close_by_column(field, getattr(got.outputs, field), getattr(want.outputs, field), rtol)
    for name, a in got.finals.items():
        assert_close_by_column(name, a, want.finals[name], rtol)
    assert same_rng_state(got.rng, want.rng), "the reference drew other random numbers"


@pytest.fixture(scope="module")
def runs():
    """case -> the jitted run: recorded from the method's, or, off the map, run again from its moved arguments."""
    cache = {}

    def get_run(case):
        if case not in cache:
            run = _record_loop(case)
            if CASES[case].start == "off-map":
                again = _jitted_run(CASES[case].loop, run.args)  # the recorded arguments run again: the same run
                for field in run.outputs._fields:
                    np.testing.assert_array_equal(getattr(again.outputs, field), getattr(run.outputs, field))
                assert same_rng_state(again.rng, run.rng)
                run = _jitted_run(CASES[case].loop, _moved_off_the_map(run.args))
            cache[case] = run
        return cache[case]

    return get_run


# --------------------------------------------------------------------------------------
# the loops
# --------------------------------------------------------------------------------------
# the reference's kernels whose calls (and results) tell what happened in a run (its decisions are the loop's)
EVENTS = ("reopen_kf_numpy", "position_reset_numpy", "cloud_heading_offset_numpy", "fix_prior_chi2_numpy",
          "best_particle_fit_numpy", "gaussian_horizontal_numpy", "eskf_update_numpy")


@pytest.mark.parametrize("case", list(CASES))
def test_the_loop_equals_its_reference(runs, case):
    got = runs(case)
    results = {name: [] for name in EVENTS}
    with pytest.MonkeyPatch.context() as mp:  # the reference's calls recorded
        for name in EVENTS:
            def recorded(*a, _f=getattr(ref, name), _name=name):
                result = _f(*a)
                results[_name].append(result)
                return result
            mp.setattr(ref, name, recorded)
        want = _reference_run(case, got.args)
    calls = {name: len(r) for name, r in results.items()}
    assert_runs_close(got, want)
    # what each case is there for happened
    out = got.outputs
    loop = CASES[case].loop
    reinit = np.flatnonzero(out.reinit)
    assert (reinit.size > 0) == (case.endswith(("reinit", "tide", "tide-gaussian", "collapse", "off-map"))), reinit
    if loop == "fix-only":
        assert out.fixed.sum() > 0 and (calls["gaussian_horizontal_numpy"] > 0) == ("gaussian" in case)
        if case == "fix-only-collapse":
            assert reinit.size > 10
        return
    accepted, rejected = out.fixed.sum(), out.rejected.sum()
    assert not np.isnan(out.en).any()
    if case.endswith("off-map"):  # clamped to the map's edge and re-drawn there, again and again: never a fix
        east_bound = next(a for a in got.args if hasattr(a, "guard")).guard.bounds[1]
        assert reinit[0] == 0 and out.en[0, 0] == east_bound and reinit.size > 10 and accepted == 0
    else:
        assert accepted > 0
    gated = case in ("kalman-gate", "turned-gate")
    assert (rejected > 5) == (gated or case in ("turned-prior-refused", "turned-fallback"))
    assert (calls["reopen_kf_numpy"] > 0) == gated
    # KF updates the chi-square gate passed, less the accepted fixes that were not resets: undone by the bias gate
    passed = sum(chi2 < 13.8 for chi2, _, _ in results["eskf_update_numpy"]) if not gated else None
    if not gated:
        assert (passed > accepted - calls["position_reset_numpy"]) == (case == "turned-fallback")
    if case in ("turned-prior-refused", "turned-fallback"):  # fixes failed the fix-prior gate: refused, or replaced
        assert sum(chi2 >= 1.0 for chi2 in results["fix_prior_chi2_numpy"]) > 3
    if case == "turned-gate":  # the reopened KF took the cloud's heading, and a fix it still refused set its position
        assert calls["cloud_heading_offset_numpy"] == calls["reopen_kf_numpy"]
        assert calls["position_reset_numpy"] > 1 + reinit.size  # more resets than first fixes
    if loop == "turned":
        assert (calls["fix_prior_chi2_numpy"] > 0) == (case in ("turned-prior-refused", "turned-fallback"))
        # updates that failed the fit test: the one wild beam judged
        assert (calls["best_particle_fit_numpy"] > 0) == (case in ("turned-tide", "turned-prior-refused"))
        if case == "turned-tide":  # some fitted without it: the count kept
            assert 0 < sum(fit < 4.0 for fit in results["best_particle_fit_numpy"]) < calls["best_particle_fit_numpy"]


def test_a_perturbed_reference_is_caught(runs, monkeypatch):
    """The comparison can fail for every loop: each reference with one of its kernels' numbers changed by 1e-6
    (the fix-only particles' position noise, the Kalman-feedback loop's KF process noise, the heading-offset
    particles' heading noise; and, on the reopened KF's path, the cloud's heading 1e-6 rad off) no longer agrees."""
    mutations = [
        ("fix-only", "propagate_loose_numpy", lambda f: lambda x, de, dn, noise, sig, sh: f(x, de, dn, noise,
                                                                                         sig * (1.0 + 1e-6), sh)),
        ("kalman-gate", "eskf_predict_numpy", lambda f: lambda p, de, dn, be, bn, sz, qp, qy, qb: f(
            p, de, dn, be, bn, sz, qp * (1.0 + 1e-6), qy, qb)),
        ("turned", "propagate_loose_turned_numpy", lambda f: lambda x, de, dn, ref_yaw, dyaw, noise, sig, q: f(
            x, de, dn, ref_yaw, dyaw, noise, sig, q * (1.0 + 1e-6))),
        ("turned-gate", "cloud_heading_offset_numpy", lambda f: lambda *a: f(*a) + 1e-6),
    ]
    for case, name, mutate in mutations:
        got = runs(case)
        with monkeypatch.context() as mp:
            mp.setattr(ref, name, mutate(getattr(ref, name)))
            want = _reference_run(case, got.args)
        with pytest.raises(AssertionError):
            assert_runs_close(got, want)


def test_the_references_run_without_jitted_functions():
    """What the loop comparisons rely on: the reference's module holds no jitted function, and inside
    :func:`filters_support.forbid_jitted_calls` one called through its module fails (the kernels' modules lose
    theirs)."""
    assert not [name for name, value in vars(ref).items() if isinstance(value, Dispatcher)]
    with pytest.MonkeyPatch.context() as mp:
        assert forbid_jitted_calls(mp) > 100
        for call in (lambda: loose.reopen_kf(np.eye(4), 1.0, 1.0),
                     lambda: loose_turned.unimodal_fraction(np.zeros((2, 3)), np.ones(3) / 3, np.zeros(2), np.eye(2))):
            with pytest.raises(AssertionError, match="jitted function was called"):
                call()


def test_a_wound_yaw_is_refused():
    """The loop references refuse a cloud whose yaw is wound beyond trig.WOUND / 2 from the heading
    (``tight_reference.check_not_wound``, which the turned loop's reference calls)."""
    with pytest.raises(ValueError, match="wound"):
        ref.check_not_wound(3, (np.array([0.1, 1e5]), 0.0))
    with pytest.raises(ValueError, match="wound"):
        ref.check_not_wound(3, (np.array([0.1, np.nan]), 0.0))
    ref.check_not_wound(3, (np.array([0.1, -4e4]), 0.0))


# --------------------------------------------------------------------------------------
# the kernel reference the turned loop's reference added
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("lik", [Likelihood(False, 0, 4.0), Likelihood(True, 1, 4.0)])
def test_the_fit_without_the_worst_beam_equals_its_reference(lik):
    """``loose_turned.fit_without_worst_beam`` against ``best_particle_fit_numpy``: the best particle's beams one
    by one through the likelihood, the worst left out from 3 beams on; 4, 3 (one without a range), 2 and 1 beams,
    footprints off the map included, and with the map-aware Student-t density."""
    rng = np.random.default_rng(8)
    heights = -60.0 - 10.0 * np.sin(np.arange(40)[:, None] / 5.0) * np.cos(np.arange(40)[None, :] / 7.0)
    nmap = Map(heights, 0.0, 0.0, 10.0, 10.0)
    mvar = rng.uniform(0.0, 2.0, heights.shape)
    grid = node_grid(nmap, mvar) if lik.mapaware else node_grid(nmap)
    zmap, mvar_ref = grid_maps(grid)
    m = 50
    x = np.zeros((N_TIGHT, m))
    x[0] = rng.uniform(-30.0, 420.0, m)  # some footprints off the map's east and west edges
    x[1] = rng.uniform(50.0, 350.0, m)
    x[2] = -20.0
    x[3:5] = rng.normal(0.0, 0.02, (2, m))
    x[YAW] = 0.7 + rng.normal(0.0, 0.3, m)
    beams = np.array([[0.3, 0.3, -0.9], [-0.3, 0.3, -0.9], [0.3, -0.3, -0.9], [-0.3, -0.3, -0.9]])
    beams /= np.linalg.norm(beams, axis=1)[:, None]
    ll = rng.normal(0.0, 1.0, m)
    consts = beam_constants(1.0, 1.0, 5.0)
    att = attitude_reference(0.0, 0.0, 0.7)
    for ranges in ([45.0, 41.0, 52.0, 38.0], [45.0, np.nan, 52.0, 38.0], [np.nan, 41.0, np.nan, 38.0],
                   [np.nan, np.nan, 52.0, np.nan]):
        ranges = np.array(ranges)
        one = loose_turned.OneParticle(np.zeros((N_TIGHT, 1)), np.empty((1, 3)),
                                       new_likelihood_work(np.int64(1), 4 * grid.grids), np.zeros((2, 1)), np.empty(1))
        vec = loose_turned.beam_vectors(beams, ranges)
        got = loose_turned.fit_without_worst_beam(x, ll, vec, grid, lik, consts, att, False, one)
        want = loose_turned.best_particle_fit_numpy(x, ll, beams, ranges, zmap, mvar_ref, lik, 1.0, 5.0)
        assert got == pytest.approx(want, rel=1e-12), ranges
        assert np.isfinite(want)
