"""Conformance suite: what every TAN method (``tanbench.filters.METHODS``) must do.

Deterministic edge cases on short area-A runs (60-120 s, 300-500 particles), each
parametrised over the methods: reproducibility and seed sensitivity, common random
numbers, the output contract (metric and series keys, lengths, finiteness), every
option value runs (distance innovation, resampling, regularisation, sampling time), a
start at the truth with near-perfect sensors stays there, zero range noise is no worse,
a flat seafloor (only depth observable) leaves the horizontal cloud wide, stretches
without bottom lock are not taken for divergence, degenerate clouds (1-3 particles,
all weight on one particle) produce no NaN, and bad input is refused with
``TanbenchError``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from filters_support import series_keys, short_scenario, snapshot
from tanbench.options import REGULARISATION, RESAMPLING
from tanbench.errors import TanbenchError
from tanbench.methods.registry import builtin_names, get, particle_steps
from tanbench.filters import resample as rs
from tanbench.filters.estimate import weighted_estimate
from tanbench.methods import run_method
from tanbench.schema import METRIC_COLUMNS
from tanbench.filters.state import N_TIGHT, YAW
from tanbench.filters.tight import REGULARISED_STATES
from tanbench.simulation import simulate_vehicle
from tanbench.terrain.grid import Map
from tanbench.testing import assert_same_tree

METHODS = builtin_names()
# the randomised methods, whose budget is the particle count (grid, Kalman and batch methods are
# deterministic: their seed cannot matter and they have no cloud to shrink)
PARTICLE_METHODS = tuple(m for m in METHODS if get(m).cost_units is particle_steps)

SEED = 90210
PERFECT_SENSORS = dict(gyro_turn_on_bias_deg_h=0.0, gyro_bias_instability_deg_h=0.0, gyro_arw_deg_sqrt_h=0.0,
                       accel_turn_on_bias_mg=0.0, accel_bias_instability_mg=0.0, accel_noise_mg_sqrt_hz=0.0,
                       dvl_scale_error=0.0, dvl_noise_mps=0.0)


def vseed(k: int = 0) -> np.random.SeedSequence:
    return np.random.SeedSequence(SEED, spawn_key=(k,))


def fseed(k: int = 0, method: str = "tight-dvl") -> np.random.SeedSequence:
    return np.random.SeedSequence(SEED + 1, spawn_key=(k, METHODS.index(method)))


def plane_like(template: Map, height: float) -> Map:
    """A flat seafloor at ``height`` m (up) with ``template``'s extent and spacing."""
    return Map(np.full(template.z.shape, float(height)), template.e0, template.n0, template.res_e,
               template.res_n, name="plane")


@pytest.fixture
def plane_world(monkeypatch):
    """Replace the truth and navigation seafloors by a flat plane at -90 m (deeper than the track).

    The simulation's world cache and the bound's cache are cleared before and after, so no
    other test sees the plane.
    """
    import tanbench.terrain as run_mod
    import tanbench.simulation as sim_mod
    from tanbench.terrain import navigation_map, truth_map

    real_truth = truth_map
    real_nav = navigation_map
    height = -90.0

    def fake_truth(spec):
        return plane_like(real_truth(spec), height)

    def fake_nav(spec, resolution_m):
        return plane_like(real_nav(spec, resolution_m), height)

    import tanbench.bounds.pcrb as pcrb_mod

    def clear_caches():
        sim_mod.noise_free_world.cache_clear()
        pcrb_mod._bound_cached.cache_clear()

    clear_caches()
    monkeypatch.setattr(sim_mod, "truth_map", fake_truth)
    monkeypatch.setattr(run_mod, "navigation_map", fake_nav)
    # the modules that imported it at their top (methods hand it to the filters, the bound)
    import tanbench.methods as methods_mod

    monkeypatch.setattr(methods_mod, "navigation_map", fake_nav)
    monkeypatch.setattr(pcrb_mod, "navigation_map", fake_nav)
    yield height
    monkeypatch.undo()
    clear_caches()


@pytest.fixture(scope="module")
def base():
    """The default short scenario (120 s, 400 particles) and one of its vehicle runs."""
    sc = short_scenario()
    return sc, simulate_vehicle(sc, vseed())


@pytest.fixture(scope="module")
def base_results(base):
    sc, v = base
    return {m: run_method(sc, m, v, fseed(0, m)) for m in METHODS}


# series that are NaN by definition somewhere: NEES where a collapsed cloud reports a singular
# covariance; the PCRB without range noise (undefined) and, for the loose state, its heading
MAY_BE_NAN = {m: {"nees", "pcrb_horizontal_m", "pcrb_heading_deg"} for m in METHODS}


def check_finite(result, method):
    for k, a in result.series.items():
        a = np.asarray(a)
        if k in ("ess", "cov_en") and np.isnan(a).all():
            continue  # optional outputs a method does not report (no particles, no cross-covariance)
        if a.dtype.kind == "f" and k not in MAY_BE_NAN.get(method, set()):
            assert np.isfinite(a).all(), f"{method}: series {k} has NaN/inf"
    for k in ("final_horizontal_error_m", "mean_horizontal_error_m", "final_heading_error_deg"):
        assert math.isfinite(result.metrics[k]), f"{method}: {k}"


# --------------------------------------------------------------------------------------
# output contract
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_metrics_keys(base_results, method):
    m = base_results[method].metrics
    assert list(m) == list(METRIC_COLUMNS)
    assert isinstance(m["diverged"], bool) and isinstance(m["reinitialisations"], int)
    assert m["final_horizontal_error_m"] == pytest.approx(math.hypot(m["final_east_error_m"],
                                                                     m["final_north_error_m"]), rel=1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_series_keys_and_lengths(base, base_results, method):
    from tanbench.runner.tasks import SERIES_COLUMNS

    sc, v = base
    s = base_results[method].series
    assert set(s) == series_keys(method)
    assert set(SERIES_COLUMNS) <= set(s)  # what the sweep engine stores
    k = int(round(sc.duration_s / sc.sampling_time_s)) + 1
    assert {len(a) for a in s.values()} == {k}
    np.testing.assert_allclose(s["t"], np.arange(k) * sc.sampling_time_s, atol=1e-9)
    check_finite(base_results[method], method)
    # the error series are what they say
    np.testing.assert_allclose(s["east_error_m"], s["est_e"] - s["truth_e"], atol=1e-9)
    np.testing.assert_allclose(s["horizontal_error_m"], np.hypot(s["east_error_m"], s["north_error_m"]), atol=1e-9)
    if np.isfinite(s["ess"]).any():
        assert ((s["ess"] >= 1 - 1e-9) & (s["ess"] <= sc.particles + 1e-6)).all()
    assert (s["var_e"] >= 0).all() and (s["var_n"] >= 0).all()
    assert ((s["est_heading_deg"] >= 0) & (s["est_heading_deg"] < 360)).all()


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("sampling", [2.0, 5.0])
def test_sampling_time(method, sampling):
    sc = short_scenario(sampling_time_s=sampling)
    r = run_method(sc, method, simulate_vehicle(sc, vseed()), fseed(0, method))
    k = int(round(sc.duration_s / sampling)) + 1
    assert len(r.series["t"]) == k
    np.testing.assert_allclose(np.diff(r.series["t"]), sampling, atol=1e-9)
    check_finite(r, method)


# --------------------------------------------------------------------------------------
# seeds and common random numbers
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_reproducible(base, base_results, method):
    sc, v = base
    again = run_method(sc, method, v, fseed(0, method))
    first = base_results[method]
    for k in METRIC_COLUMNS:
        if k == "filter_wall_s":
            continue
        a, b = first.metrics[k], again.metrics[k]
        assert (a == b) or (isinstance(a, float) and math.isnan(a) and math.isnan(b)), k
    for k in first.series:
        np.testing.assert_array_equal(first.series[k], again.series[k], err_msg=k)
    # also from a freshly simulated, identically seeded vehicle
    third = run_method(sc, method, simulate_vehicle(sc, vseed()), fseed(0, method))
    for k in first.series:
        np.testing.assert_array_equal(first.series[k], third.series[k], err_msg=k)


@pytest.mark.parametrize("method", PARTICLE_METHODS)
def test_filter_seed_matters(base, base_results, method):
    sc, v = base
    other = run_method(sc, method, v, fseed(1, method))
    first = base_results[method]
    assert not np.array_equal(first.series["est_e"], other.series["est_e"])
    # ... but not the world: same truth and navigation
    for k in ("truth_e", "truth_n", "truth_u", "nav_e", "nav_n", "nav_heading_deg"):
        np.testing.assert_array_equal(first.series[k], other.series[k])


def test_common_random_numbers(base, base_results):
    """The three methods of a run see the same truth and navigation, and no run alters the vehicle data."""
    sc, v = base
    ref = base_results[METHODS[0]].series
    for m in METHODS[1:]:
        s = base_results[m].series
        for k in ("t", "truth_e", "truth_n", "truth_u", "truth_heading_deg", "nav_e", "nav_n", "nav_heading_deg",
                  "nav_horizontal_error_m"):
            np.testing.assert_array_equal(ref[k], s[k], err_msg=f"{m}: {k}")
    before = snapshot(v)
    for m in METHODS:
        run_method(sc, m, v, fseed(3, m))
    assert_same_tree(before, v)
    # different vehicle seeds are different runs
    v2 = simulate_vehicle(sc, vseed(1))
    assert not np.array_equal(v.obs.nav.pos, v2.obs.nav.pos)
    assert not np.array_equal(v.obs.dvl_ranges, v2.obs.dvl_ranges)


# --------------------------------------------------------------------------------------
# every option value runs
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("mode", ["particle", "navigation", "none"])
def test_distance_innovation_modes_run(base, method, mode):
    sc, v = base
    sc = sc.model_copy(update={"filter": sc.filter.model_copy(update={"distance_innovation": mode})})
    r = run_method(sc, method, v, fseed(0, method))
    check_finite(r, method)
    assert r.metrics["final_horizontal_error_m"] < 200.0


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("scheme", sorted(RESAMPLING))
def test_resampling_schemes_run(base, method, scheme):
    _, v = base  # same world: only filter settings differ
    sc = short_scenario(filter=dict(resampling=scheme, ess_threshold=1.0))  # resample at every update
    r = run_method(sc, method, v, fseed(0, method))
    check_finite(r, method)
    assert r.metrics["final_horizontal_error_m"] < 100.0


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("reg", sorted(REGULARISATION))
@pytest.mark.parametrize("states", sorted(REGULARISED_STATES))
def test_regularisations_run(base, method, reg, states):
    _, v = base
    sc = short_scenario(filter=dict(regularisation=reg, regularised_states=states))
    r = run_method(sc, method, v, fseed(0, method))
    check_finite(r, method)


# --------------------------------------------------------------------------------------
# easy and degenerate worlds
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_start_at_truth_stays(method):
    """No initial error, near-perfect sensors, a 2 m initial square: the error stays within 5 m."""
    sc = short_scenario(noise_m=0.05, sensors=PERFECT_SENSORS,
                        navigation=dict(initial_heading_error_deg=0.0, initial_position_error_m=0.0),
                        filter=dict(initial_area_m=2.0, initial_std_heading_deg=0.5,
                                    initial_std_gyro_bias_deg_h=1.0))
    for k in range(2):
        r = run_method(sc, method, simulate_vehicle(sc, vseed(k)), fseed(k, method))
        check_finite(r, method)
        err = r.series["horizontal_error_m"]
        assert err.max() < 5.0, err.max()
        assert np.abs(r.series["heading_error_deg"]).max() < 3.0
        assert r.metrics["reinitialisations"] == 0 and not r.metrics["diverged"]
        assert r.metrics["convergence_time_s"] == 0.0


# the paper's plain reading of the likelihood and loose TAN (docs/realism.md); the recommended
# settings are the defaults
PAPER_READING = dict(map_aware_likelihood=False, likelihood="gaussian", loose_architecture="fix-only",
                     keep_on_map=False, divergence_spread_m=None)
# runs per noise level. The test was set with 6 runs (ORIGINAL_RUNS); that version is kept and
# counted: before issue 17 the recommended tight-sbe and loose-dvl failed it (expected failures
# then); on the vectorised code every method passes it. A few lost runs decide a 6-run mean, so
# the same statistic and threshold are also reported on 48 runs (NOISE_FREE_RUNS; their first 6
# are the original runs), which pass for every method, with the code before the vectorised
# passes and with it.
ORIGINAL_RUNS = 6
NOISE_FREE_RUNS = 48
_NOISE_FREE_ERRORS: dict = {}


def _noise_free_errors(settings, method, runs):
    """Final horizontal errors over the first ``runs`` paired runs at noise 0 and 1 m: each run
    computed once per process, and only up to the count asked (xdist may put the 6- and 48-run
    cases in different processes)."""
    f = PAPER_READING if settings == "paper" else {}
    noisy, clean = short_scenario(noise_m=1.0, filter=f), short_scenario(noise_m=0.0, filter=f)
    errs = _NOISE_FREE_ERRORS.setdefault((settings, method), {0.0: [], 1.0: []})
    if not errs[0.0]:  # the world and the noise are checked once
        assert noisy.world_key() == clean.world_key()
        v0 = simulate_vehicle(clean, vseed(0))
        v1 = simulate_vehicle(noisy, vseed(0))
        assert not np.array_equal(v0.obs.dvl_ranges, v1.obs.dvl_ranges)
    for k in range(len(errs[0.0]), runs):
        final = {}
        for sc in (noisy, clean):
            v = simulate_vehicle(sc, vseed(k))
            r = run_method(sc, method, v, fseed(k, method))
            check_finite(r, method)
            final[sc.noise_m] = r.metrics["final_horizontal_error_m"]
        for n, e in final.items():  # both of run k, or neither
            errs[n].append(e)
    return {n: np.array(e[:runs]) for n, e in errs.items()}


# The original 6-run statistic, counted as it was set, fails again for the recommended tight-sbe
# since issue 24's defaults (posterior regularisation, bias random walk): 3.74 m at noise 0 against
# 1.70 m at noise 1 over runs 0-5, two runs near 7 m deciding the mean. Its 48-run version passes
# (2.87 against 3.86 m). Kept visible as an expected failure, not dropped.
ORIGINAL_FAILS = {("recommended", "tight-sbe"): "6-run mean decided by two runs near 7 m since issue 24; "
                                                  "the 48-run version passes"}


def _noise_free_param(settings, method, runs):
    reason = ORIGINAL_FAILS.get((settings, method)) if runs == ORIGINAL_RUNS else None
    marks = [pytest.mark.xfail(reason=reason, strict=True)] if reason else []
    return pytest.param(settings, method, runs, id=f"{settings}-{method}-{runs}runs", marks=marks)


@pytest.mark.parametrize("settings, method, runs", [
    _noise_free_param(s, m, n) for n in (ORIGINAL_RUNS, NOISE_FREE_RUNS)
    for s in ("paper", "recommended") for m in METHODS])
def test_zero_range_noise_no_worse(settings, method, runs):
    """noise_m = 0 runs (no zero-variance trouble) and is not worse than 1 m noise on the same
    vehicle runs (common random numbers: noise_m is not part of the world), over the first
    ``runs`` runs."""
    errs = _noise_free_errors(settings, method, runs)
    assert np.mean(errs[0.0]) <= 1.25 * np.mean(errs[1.0]) + 1.0, errs


@pytest.mark.parametrize("method", METHODS)
def test_flat_seafloor_leaves_position_unobservable(plane_world, method):
    """On a flat seafloor only depth is observable: the horizontal cloud keeps (at least) its initial
    spread (a 150 m square: std ~61 m), no method claims to have converged, and the loose method
    never issues a position fix (its output is the navigation system's)."""
    sc = short_scenario(particles=500)
    for k in range(2):
        v = simulate_vehicle(sc, vseed(k))
        altitude = v.truth.pos[v.obs.ping_idx, 2] - plane_world
        np.testing.assert_allclose(v.obs.sbe_ranges[:, 0], altitude, rtol=0.05, atol=sc.noise_m)  # really a plane
        r = run_method(sc, method, v, fseed(k, method))
        check_finite(r, method)
        s = r.series
        std = np.sqrt(s["var_e"] + s["var_n"])
        initial = sc.filter.initial_area_m / math.sqrt(6.0)  # horizontal std of the uniform square
        assert std[0] == pytest.approx(initial, rel=0.15)
        assert std.min() > initial / 4, std.min()
        assert std[-1] > initial / 4
        assert r.metrics["reinitialisations"] == 0
        if "up" in get(method).states:
            # depth is observable (and sensed): the vertical estimate stays on the truth
            assert np.abs(s["est_u"] - s["truth_u"]).max() < 2.0
        if "position_fix" in s:
            assert not s["position_fix"].any()
            np.testing.assert_array_equal(s["est_e"], s["nav_e"])
            np.testing.assert_array_equal(s["est_n"], s["nav_n"])


@pytest.mark.parametrize("method", METHODS)
def test_flat_seafloor_error_follows_navigation_and_no_fix_is_claimed(plane_world, method):
    """Where TAN has no information (a plane), every method's error follows the navigation system's
    and its reported covariance admits it: at every update the estimate lies within 3 reported
    sigmas (sqrt(var_e + var_n)) of the truth and of the navigation solution, and over two runs the
    mean final error is at least half the navigation system's (no method beats dead reckoning
    without information). Thresholds fixed before the runs were looked at."""
    sc = short_scenario(duration_s=300.0, particles=500)
    final, nav_final = [], []
    for k in range(2):
        r = run_method(sc, method, simulate_vehicle(sc, vseed(k)), fseed(k, method))
        check_finite(r, method)
        s = r.series
        sigma = np.sqrt(s["var_e"] + s["var_n"])
        assert (s["horizontal_error_m"] <= 3.0 * sigma).all(), \
            f"{method}: error {s['horizontal_error_m'].max():.1f} m beyond 3 sigma (min sigma {sigma.min():.1f} m)"
        off_nav = np.hypot(s["est_e"] - s["nav_e"], s["est_n"] - s["nav_n"])
        assert (off_nav <= 3.0 * sigma).all(), f"{method}: {off_nav.max():.1f} m off the navigation solution"
        final.append(s["horizontal_error_m"][-1])
        nav_final.append(s["nav_horizontal_error_m"][-1])
    assert np.mean(final) >= 0.5 * np.mean(nav_final), (final, nav_final)


@pytest.mark.parametrize("method", METHODS)
def test_no_bottom_lock_is_not_divergence(method):
    """With a 45 m maximum range the sonar loses the bottom for ~60 s of the first 120 s (all DVL
    beams and the altimeter return NaN). An update without any range carries no evidence: the
    filter must not count it towards divergence, so no reinitialisation may follow a stretch
    of ``divergence_steps`` updates without a single range (each one throws the converged cloud
    away and re-spreads it over the initial 150 m square)."""
    sc = short_scenario(sensors=dict(max_range_m=45.0))
    v = simulate_vehicle(sc, vseed(0))
    sensor = v.obs.sbe_ranges if method == "tight-sbe" else v.obs.dvl_ranges
    no_lock = np.isnan(sensor).all(axis=1)
    steps = sc.filter.divergence_steps
    assert no_lock.sum() > 3 * steps  # the scenario does what it says
    r = run_method(sc, method, v, fseed(0, method))
    check_finite(r, method)
    reinit = np.nonzero(r.series["reinit"])[0]
    blind = [k for k in reinit if no_lock[max(0, k - steps + 1):k + 1].all()]
    assert not blind, f"reinitialised after {steps} updates without any range at updates {blind}"


@pytest.mark.parametrize("method", PARTICLE_METHODS)
@pytest.mark.parametrize("particles", [1, 2, 3])
def test_tiny_clouds(method, particles):
    """One to three particles: degenerate but must run without NaN (ESS 1, resampling one particle)."""
    sc = short_scenario(duration_s=60.0, particles=particles)
    r = run_method(sc, method, simulate_vehicle(sc, vseed()), fseed(0, method))
    check_finite(r, method)
    assert (r.series["ess"] <= particles + 1e-9).all()


@pytest.mark.parametrize("scheme", sorted(RESAMPLING))
def test_all_weight_on_one_particle(scheme):
    """The loop's weight pipeline on a one-hot posterior: log-weights [0, -inf, ...] normalise without
    NaN, ESS is 1, every scheme resamples only that particle, the estimate is that particle with
    zero variance, and regularising the collapsed cloud stays finite."""
    rng = np.random.default_rng(5)
    m = 300
    x = rng.normal(size=(N_TIGHT, m))  # a column per particle
    logw = np.full(m, -np.inf)
    logw[42] = 0.0
    w = np.empty(m)
    rs.normalize_log_weights(logw, w)
    assert not np.isnan(w).any() and w[42] == 1.0
    assert rs.effective_sample_size(w) == 1.0
    idx = np.empty(m, dtype=np.int64)
    rs.resample_indices(RESAMPLING[scheme], w, rng.random(m), idx)
    assert (idx == 42).all()
    target = x[:, 42].copy()
    rs.apply_resample(x, idx, np.empty_like(x))
    mean, var, cov = np.empty(N_TIGHT), np.empty(N_TIGHT), np.empty((2, 2))
    weighted_estimate(x, np.full(m, 1.0 / m), YAW, target[YAW], mean, var, cov)
    np.testing.assert_allclose(mean, target, atol=1e-9)
    assert (np.abs(var) < 1e-18).all()
    for kind in REGULARISATION.values():
        y = x.copy()
        rs.regularise(y, np.random.default_rng(1), kind, REGULARISED_STATES["position-heading-biases"], 0.2, N_TIGHT)
        assert np.isfinite(y).all()


# --------------------------------------------------------------------------------------
# refused input
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["tight", "TIGHT-DVL", "loose-sbe", "", "tight-dvl "])
def test_bad_method_name(base, name):
    sc, v = base
    with pytest.raises(TanbenchError, match="unknown method"):
        run_method(sc, name, v, fseed())


@pytest.mark.parametrize("method", METHODS)
def test_initial_cloud_off_the_map_is_refused(base, method):
    _, v = base
    huge = short_scenario(filter=dict(initial_area_m=5000.0))
    with pytest.raises(TanbenchError, match="leaves the navigation map"):
        run_method(huge, method, v, fseed(0, method))
