"""Issue 24's tight-filter mechanisms (docs/filters.md sections 5-6): kernels against their
numpy twins, neutral settings reproducing the filter from before the options bit for bit
(against the prototype plug-in, which drives the unchanged kernels from Python), and the
bound following the gyro-bias random walk."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from tanbench.config import Scenario
from tanbench.filters import bias_walk, posterior, recovery
from tanbench.filters.rng import loop_rng
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, YAW

PROTOTYPES = Path(__file__).resolve().parents[1] / "examples" / "prototypes"

NEUTRAL = {"gyro_bias_noise": "none", "tight_regularisation": "shared", "recovery": "estimate"}


def _cloud(m=257, seed=3):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(N_TIGHT, m))
    x[E] = 5.0e5 + 30.0 * x[E]
    x[N] = 4.1e6 + 20.0 * x[N] + 0.5 * (x[E] - 5.0e5)  # correlated with east
    x[YAW] = math.pi - 0.05 + 0.2 * x[YAW]  # straddles +-pi once wrapped
    x[BX] *= 1e-4
    x[BZ] *= 1e-4
    w = rng.random(m)
    return x, w / w.sum()


def test_weighted_covariance_matches_numpy():
    x, w = _cloud()
    rows = np.array([E, N, YAW, BX, BZ], dtype=np.int64)
    mean, cov = np.empty(5), np.empty((5, 5))
    posterior.weighted_covariance(x, rows, w, YAW, math.pi, mean, cov)
    mu_ref, cov_ref = posterior.weighted_covariance_numpy(x, rows, w, YAW, math.pi)
    np.testing.assert_allclose(mean, mu_ref, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(cov, cov_ref, rtol=1e-9, atol=1e-15)
    assert cov[0, 1] > 0.3 * math.sqrt(cov[0, 0] * cov[1, 1])  # the correlation is kept


def test_cholesky_small_matches_numpy_and_falls_back():
    a = np.array([[4.0, 1.0, 0.2], [1.0, 3.0, 0.1], [0.2, 0.1, 2.0]])
    out = np.empty((3, 3))
    assert posterior.cholesky_small(a, out)
    np.testing.assert_allclose(out, posterior.cholesky_small_numpy(a)[0], rtol=1e-13)
    singular = np.array([[1.0, 1.0], [1.0, 1.0]])
    out2 = np.empty((2, 2))
    assert not posterior.cholesky_small(singular, out2)
    np.testing.assert_allclose(out2, np.eye(2))
    ref, ok = posterior.cholesky_small_numpy(singular - np.diag([0.0, 1e-12]))
    assert not ok and np.allclose(ref, np.diag([1.0, math.sqrt(1.0 - 1e-12)]))


def test_shrink_jitter_full_matches_numpy_and_keeps_moments():
    x, _ = _cloud(m=20000, seed=5)
    w = np.full(x.shape[1], 1.0 / x.shape[1])
    rows = np.array([E, N, YAW, BX, BZ], dtype=np.int64)
    mean, cov, chol = np.empty(5), np.empty((5, 5)), np.empty((5, 5))
    posterior.weighted_covariance(x, rows, w, YAW, math.pi, mean, cov)
    posterior.cholesky_small(cov, chol)
    noise = np.random.default_rng(7).normal(size=(5, x.shape[1]))
    y = x.copy()
    posterior.shrink_jitter_full(y, rows, YAW, mean, chol, 0.3, noise)
    ref = posterior.shrink_jitter_full_numpy(x, rows, YAW, mean, chol, 0.3, noise)
    np.testing.assert_allclose(y, ref, rtol=1e-13, atol=1e-12)
    mean2, cov2 = np.empty(5), np.empty((5, 5))
    posterior.weighted_covariance(y, rows, w, YAW, math.pi, mean2, cov2)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(mean2 - mean) < 0.05 * sd)  # mean kept (Monte Carlo)
    assert np.allclose(np.diag(cov2), np.diag(cov), rtol=0.05)  # variance kept
    assert abs(cov2[0, 1] / (sd[0] * sd[1]) - cov[0, 1] / (sd[0] * sd[1])) < 0.03  # correlation kept
    assert np.all(np.abs(np.diff(np.vstack([x[YAW], y[YAW]]), axis=0)) < 1.0)  # no 2 pi jumps


def test_bandwidth():
    assert posterior.posterior_bandwidth(5, 2000, 1.0) == pytest.approx(0.40, abs=0.01)
    assert posterior.posterior_bandwidth(5, 2000, 0.5) == pytest.approx(0.20, abs=0.01)
    assert posterior.posterior_bandwidth_jit(5, 3000, 0.5) == posterior.posterior_bandwidth(5, 3000, 0.5)


def test_walk_biases_matches_numpy():
    x, _ = _cloud(m=100)
    nx, nz = np.random.default_rng(2).normal(size=(2, 60))
    y = x.copy()
    bias_walk.walk_biases(y, nx, nz, 1e-6, 40)
    ref = x.copy()
    ref[:, 40:] = bias_walk.walk_biases_numpy(x[:, 40:], nx, nz, 1e-6)
    np.testing.assert_array_equal(y, ref)
    assert bias_walk.gauss_markov_walk_std(25.0, 300.0, 1.0) == pytest.approx(25.0 * math.sqrt(2.0 / 300.0))


@pytest.mark.parametrize("mode", [recovery.RECOVER_AT_ESTIMATE, recovery.RECOVER_LAST_HEALTHY])
@pytest.mark.parametrize("healthy_e", [np.nan, 100.0])
def test_recovery_square_matches_python(mode, healthy_e):
    args = (mode, 10.0, 20.0, healthy_e, 50.0, 7.0, -3.0, 400.0, 75.0, 0.5, 300.0)
    assert recovery.recovery_square(*args) == pytest.approx(recovery.recovery_square_numpy(*args), nan_ok=True)
    ce, cn, half = recovery.recovery_square(*args)
    if mode == recovery.RECOVER_LAST_HEALTHY and not math.isnan(healthy_e):
        assert (ce, cn, half) == (107.0, 47.0, 275.0)
    else:
        assert (ce, cn, half) == (10.0, 20.0, 75.0)


def _run(name, scenario, run=0):
    from tanbench.methods import get, method_context
    from tanbench.runner.seeds import vehicle_seed
    from tanbench.simulation import simulate_vehicle

    vehicle = simulate_vehicle(scenario, vehicle_seed(11, scenario, run))
    fseed = np.random.SeedSequence(5, spawn_key=(run, 2))
    return get(name).run(method_context(scenario, name, vehicle, fseed, get(name))), (vehicle, fseed)


@pytest.mark.parametrize("name,sensor", [("tight-dvl", "dvl"), ("tight-sbe", "sbe")])
def test_neutral_options_reproduce_the_filter_before_them(name, sensor):
    """The built-in loop at the options' neutral values equals the prototype with its options off,
    which drives the kernels of the filter from before the options (unchanged) from Python."""
    sys.path.insert(0, str(PROTOTYPES))
    from tan_proto import tight
    from tanbench.methods import get, method_context

    scenario = Scenario(duration_s=150.0, particles=500, filter=NEUTRAL)
    a, (vehicle, fseed) = _run(name, scenario)
    b = tight.run_tight(method_context(scenario, name, vehicle, fseed, get(name)), sensor)
    for k in ("east", "north", "yaw", "var_e", "var_n", "ess"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)
    np.testing.assert_array_equal(a.reinit, b.reinit)


def test_neutral_values_leave_the_cell_key():
    """Setting the new options to their neutral values is the scenario from before them."""
    base = Scenario(filter={**NEUTRAL})
    assert base.cell_key() == Scenario(filter={**NEUTRAL, "regularisation_bandwidth": 0.5,
                                               "tight_min_spread_m": 0.0}).cell_key()
    assert base.cell_key() != Scenario().cell_key()  # the recommended defaults differ from it


def test_recommended_options_run_and_differ():
    scenario = Scenario(duration_s=150.0, particles=500)
    a, _ = _run("tight-dvl", scenario)
    b, _ = _run("tight-dvl", Scenario(duration_s=150.0, particles=500, filter=NEUTRAL))
    assert np.all(np.isfinite(a.east)) and not np.array_equal(a.east, b.east)
    assert np.all(a.extra["var_bias_z"][-20:] > 0.0)


def test_bound_follows_the_bias_walk():
    from tanbench.bounds.pcrb import model_for, transition

    walk = model_for(Scenario(), "full")
    none = model_for(Scenario(filter={"gyro_bias_noise": "none"}), "full")
    assert none.bias_noise_rad_s == 0.0 and walk.bias_noise_rad_s > 0.0
    inc = np.zeros((3, 12))
    _, q = transition(inc, walk)
    assert q[0, 3, 3] == q[0, 4, 4] == pytest.approx(walk.bias_noise_rad_s ** 2)
    assert transition(inc, none)[1][0, 3, 3] == 0.0
    assert model_for(Scenario(), "position").bias_noise_rad_s == 0.0


def test_literal_profile_keeps_the_paper_reading():
    from tanbench.profiles import profile_settings

    s = profile_settings("zhou2017-literal")
    assert s["filter.gyro_bias_noise"] == "none" and s["filter.tight_regularisation"] == "shared"


# ---- the loose TAN with heading-offset particles (docs/filters.md section 5 items 6-8) ----------------------
LOOSE_NEUTRAL = {"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
                 "loose_fix_prior_gate": None, "loose_fix_fit_one_wild_beam": False,
                 "loose_reopen_heading": "navigation", "loose_reopen_position": "prior", "loose_fix_floor_m": 5.0,
                 "loose_fix_correlation_s": 0.0}


def test_propagate_loose_turned_matches_numpy():
    from tanbench.filters.loose_turned import propagate_loose_turned, propagate_loose_turned_numpy

    x, _ = _cloud(m=300)
    noise = np.random.default_rng(4).normal(size=(3, 100))
    y = x.copy()
    propagate_loose_turned(y, 1.5, -0.7, 3.0, 0.01, noise, 0.1, 0.002, 200)
    ref = x.copy()
    ref[:, 200:] = propagate_loose_turned_numpy(x[:, 200:], 1.5, -0.7, 3.0, 0.01, noise, 0.1, 0.002)
    np.testing.assert_allclose(y, ref, rtol=1e-14, atol=1e-9)


def test_unimodal_fraction_matches_numpy():
    from tanbench.filters.loose_turned import unimodal_fraction, unimodal_fraction_numpy

    rng = np.random.default_rng(9)
    one = rng.normal(size=(2, 4000))
    two = one.copy()
    two[0, :480] += 100.0  # 12 % of the weight in a far mode
    w = np.full(4000, 1.0 / 4000)
    for x in (one, two):
        mean = x @ w
        d = x - mean[:, None]
        cov = (d * w) @ d.T
        assert unimodal_fraction(x, w, mean, cov) == pytest.approx(unimodal_fraction_numpy(x, w, mean, cov))
    assert unimodal_fraction(one, w, one @ w, np.cov(one)) == pytest.approx(0.95, abs=0.015)
    assert unimodal_fraction(two, w, two @ w, np.cov(two)) < 0.9  # a split cloud gives no fix at 0.9
    assert unimodal_fraction(one, w, one @ w, np.zeros((2, 2))) == 0.0


def test_loose_neutral_options_reproduce_the_filter_before_them():
    sys.path.insert(0, str(PROTOTYPES))
    from tan_proto import loose
    from tanbench.methods import get, method_context

    scenario = Scenario(duration_s=150.0, particles=500, filter=LOOSE_NEUTRAL)
    a, (vehicle, fseed) = _run("loose-dvl", scenario)
    b = loose.run_loose(method_context(scenario, "loose-dvl", vehicle, fseed, get("loose-dvl")))
    for k in ("east", "north", "yaw", "var_e", "var_n", "ess"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)


def test_loose_heading_offsets_run():
    a, _ = _run("loose-dvl", Scenario(duration_s=150.0, particles=500))
    assert np.all(np.isfinite(a.east)) and np.all(a.var_e > 0)


def test_gates_need_heading_offsets():
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="need filter.loose_heading_offsets"):
        Scenario(filter={"loose_heading_offsets": False})


def test_regularisation_none_switches_the_posterior_kernel_off_too():
    """``filter.regularisation: none`` means no jitter for the tight filters as well, whichever
    kernel ``filter.tight_regularisation`` chooses (it used to be silently replaced by the
    posterior kernel)."""
    from tanbench.filters.resample import REG_NONE
    from tanbench.filters.tight import tight_resampling_of

    on = Scenario().filter
    off = on.model_copy(update={"regularisation": "none"})
    assert tight_resampling_of(on).kind == posterior.REG_POSTERIOR
    assert tight_resampling_of(off).kind == REG_NONE


def test_single_beam_bandwidth_is_the_single_beam_filters_only():
    """``filter.single_beam_regularisation_bandwidth`` and ``single_beam_ess_threshold``
    (docs/filters.md 8) size the posterior kernel and the resampling threshold of a tight PF
    weighted by one beam; a filter with more beams keeps ``regularisation_bandwidth`` and
    ``ess_threshold``, and None (the neutral value) keeps them for every filter."""
    from tanbench.filters.tight import tight_resampling_of

    base = Scenario().filter
    set_ = base.model_copy(update={"single_beam_regularisation_bandwidth": 0.25, "single_beam_ess_threshold": 0.2})
    assert tight_resampling_of(set_, 1).size == 0.25
    assert tight_resampling_of(set_, 1).ess_threshold == 0.2
    assert tight_resampling_of(set_, 4).size == base.regularisation_bandwidth
    assert tight_resampling_of(set_, 4).ess_threshold == base.ess_threshold
    assert tight_resampling_of(base, 1).size == base.regularisation_bandwidth
    assert tight_resampling_of(base, 1) == tight_resampling_of(base, 4)


def test_single_beam_bandwidth_reaches_tight_sbe_and_leaves_tight_dvl_alone():
    """A run: tight-sbe's numbers move with the single-beam settings, tight-dvl's stay the same bits."""
    from filters_support import short_scenario
    from tanbench.methods import run_method
    from tanbench.simulation import simulate_vehicle

    runs = {}
    for value in (None, 0.25):
        sc = short_scenario(duration_s=60.0, particles=300, filter={"single_beam_regularisation_bandwidth": value,
                                                                     "single_beam_ess_threshold": value})
        v = simulate_vehicle(sc, np.random.SeedSequence(2424, spawn_key=(0,)))
        for method, seed in (("tight-sbe", 1), ("tight-dvl", 2)):
            r = run_method(sc, method, v, np.random.SeedSequence(2425, spawn_key=(0, seed)))
            runs[method, value] = np.asarray(r.series["est_e"])
    assert np.array_equal(runs["tight-dvl", None], runs["tight-dvl", 0.25])
    assert not np.array_equal(runs["tight-sbe", None], runs["tight-sbe", 0.25])


# ---- the likelihood's width (docs/filters.md section 7) -------------------------------------------------------
WIDTH_NEUTRAL = {"range_noise": "table-2", "map_representation": "slope"}


def test_interpolation_variance_matches_numpy_and_holes():
    from tanbench.terrain.representation import interpolation_variance, interpolation_variance_numpy

    z = np.random.default_rng(1).normal(size=(7, 9))
    z[3, 4] = np.nan
    out = np.empty_like(z)
    interpolation_variance(z, 0.4, out)
    np.testing.assert_allclose(out, interpolation_variance_numpy(z, 0.4), rtol=1e-13, equal_nan=True)
    assert np.isnan(out[3, 4]) and out[3, 5] >= 0.16


def test_interpolation_variance_is_bilinear_interpolations_mean_square_error():
    """On a quadratic surface sampled at the nodes, the formula is the mean square error of
    bilinear interpolation over uniformly placed points; a plane costs nothing."""
    from tanbench.terrain.grid import Map
    from tanbench.terrain.representation import interpolation_variance_numpy

    res = 10.0
    ee, nn = np.meshgrid(np.arange(12) * res, np.arange(10) * res)

    def surface(e, n):
        return 0.004 * e**2 - 0.003 * n**2 + 0.002 * e * n + 0.3 * e

    grid = Map(surface(ee, nn), 0.0, 0.0, res, res)
    rng = np.random.default_rng(0)
    e, n = rng.uniform(20, 90, 400000), rng.uniform(20, 70, 400000)
    mse = np.mean((grid.elevation(e, n) - surface(e, n)) ** 2)
    assert interpolation_variance_numpy(grid.z, 0.0)[5, 5] == pytest.approx(mse, rel=0.01)
    plane = Map(0.3 * ee - 0.1 * nn, 0.0, 0.0, res, res)
    assert np.allclose(interpolation_variance_numpy(plane.z, 0.0), 0.0, atol=1e-20)


def test_width_options_neutral_and_every_method_takes_the_data_sheet_noise():
    from tanbench.filters.ekf import ekf_settings
    from tanbench.filters.mpf import mpf_settings
    from tanbench.filters.pmf import pmf_settings
    from tanbench.filters.tercom import tercom_settings
    from tanbench.filters.tight import tight_model_of
    from tanbench.methods.ekf import EkfOptions
    from tanbench.methods.mpf import MpfOptions
    from tanbench.methods.pmf import PmfOptions
    from tanbench.methods.tercom import TercomOptions

    assert Scenario().cell_key() == Scenario(filter=WIDTH_NEUTRAL).cell_key()
    sheet = Scenario(noise_m=2.0, filter={"range_noise": "data-sheet"})
    sigma = 2.0 / math.sqrt(3.0)
    assert sheet.range_sigma_m == pytest.approx(sigma) and Scenario(noise_m=2.0).range_sigma_m == 1.0
    assert tight_model_of(sheet).sig_u == pytest.approx(sigma)
    for settings, options in ((pmf_settings, PmfOptions()), (ekf_settings, EkfOptions()),
                              (tercom_settings, TercomOptions())):
        assert settings(sheet, options).sig_u == pytest.approx(sigma)
    assert mpf_settings(sheet, MpfOptions()).model.sig_u == pytest.approx(sigma)
    from pydantic import ValidationError

    with pytest.raises(ValidationError, match="range_noise: data-sheet"):
        Scenario(noise_m=0.0, filter={"range_noise": "data-sheet"})


def test_bilinear_map_term_reaches_the_likelihood_grid():
    from tanbench.filters.likelihood import likelihood_grid
    from tanbench.terrain import navigation_map

    sc = Scenario()
    nmap = navigation_map(sc.terrain, sc.map_resolution_m)
    slope = likelihood_grid(sc.filter, nmap)
    bil = likelihood_grid(Scenario(filter={"map_representation": "bilinear"}).filter, nmap)
    assert slope.grids == bil.grids == 2
    assert not np.array_equal(slope.nodes, bil.nodes)


def test_width_options_at_neutral_run_the_same_filter():
    a, _ = _run("tight-dvl", Scenario(duration_s=60.0, particles=300))
    b, _ = _run("tight-dvl", Scenario(duration_s=60.0, particles=300, filter=WIDTH_NEUTRAL))
    np.testing.assert_array_equal(a.east, b.east)
    c, _ = _run("tight-dvl", Scenario(duration_s=60.0, particles=300,
                                      filter={"range_noise": "data-sheet", "map_representation": "bilinear"}))
    assert np.all(np.isfinite(c.east)) and not np.array_equal(a.east, c.east)
