"""The paper-as-written options (docs/model.md section 10): kernels against numpy references,
reference-free properties, neutrality of the options at today's values, and profiles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from filters_support import KERNEL_SEED
from tanbench.config import Scenario
from tanbench.errors import TanbenchError
from tanbench.filters import propagate as prop
from tanbench.filters.cloud import gaussian_horizontal, gaussian_horizontal_numpy

from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.navigation import increments as incmod
from tanbench.navigation.increments import compute_euler_inputs, compute_increments, euler_inputs_numpy
from tanbench.profiles import PROFILES, describe_profile, profile_settings
from tanbench.sweep import parse_sweep
from tanbench.terrain.layouts import layout
from tanbench.terrain.synthetic import with_roughness

TOL = dict(rtol=1e-9, atol=1e-9)


@pytest.fixture(scope="module")
def run_inputs(paper_run):
    """(observations, update samples every 1 s) of the default full-length run."""
    return paper_run.obs, paper_run.obs.ping_idx


@pytest.mark.parametrize("window", [1, 100, 250])
def test_euler_inputs_match_numpy(run_inputs, window):
    v, upd = run_inputs
    nav = v.nav
    for idx in (upd, upd[::10], np.array([0, 3, 150, 7000, upd[-1]])):
        jit = compute_euler_inputs(v.gyro, v.dvl_velocity, nav.pitch, nav.roll, nav.yaw, math.radians(30.0),
                                   idx, window)
        ref = euler_inputs_numpy(v.gyro, v.dvl_velocity, nav.pitch, nav.roll, nav.yaw, math.radians(30.0),
                                 idx, window)
        assert jit.shape == (idx.size - 1, incmod.N_EULER)
        np.testing.assert_allclose(jit, ref, rtol=1e-12, atol=1e-12)


def test_euler_inputs_follow_the_vehicle(run_inputs):
    """Reference-free: the 1 s mean inputs are the DVL's forward speed and the navigation yaw rate."""
    v, upd = run_inputs
    nav = v.nav
    u = compute_euler_inputs(v.gyro, v.dvl_velocity, nav.pitch, nav.roll, nav.yaw, math.radians(30.0), upd, 100)
    assert np.allclose(u[:, incmod.EU_VY], 2.0, atol=0.02)  # 2 m/s forward, 0.4 % scale error
    yaw_rate = (-np.sin(nav.roll[upd[1:]]) * u[:, incmod.EU_WX]
                + np.cos(nav.roll[upd[1:]]) * u[:, incmod.EU_WZ]) / np.cos(nav.pitch[upd[1:]])
    nav_rate = np.diff(nav.yaw[upd])  # rad per 1 s interval
    assert np.abs(yaw_rate - nav_rate).max() < math.radians(0.05)


@pytest.mark.parametrize("dist_mode", [prop.DIST_PARTICLE, prop.DIST_NAVIGATION], ids=["particle", "navigation"])
@pytest.mark.parametrize("dt", [1.0, 10.0])
def test_propagate_tight_euler_matches_numpy(run_inputs, dist_mode, dt):
    v, upd = run_inputs
    nav = v.nav
    step = int(dt)
    idx = upd[::step]
    inc = compute_increments(v.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, idx)
    u = compute_euler_inputs(v.gyro, v.dvl_velocity, nav.pitch, nav.roll, nav.yaw, math.radians(30.0), idx, 100)
    rng = np.random.default_rng([KERNEL_SEED, 13, step, dist_mode])
    m = 211
    for row in sorted({0, int(np.argmax(np.abs(inc[:, incmod.DYAW]))), inc.shape[0] - 1,
                       *rng.integers(0, inc.shape[0], 3).tolist()}):
        k0 = idx[row]
        x0 = np.empty((N_TIGHT, m))  # a column per particle
        x0[E] = nav.pos[k0, 0] + rng.uniform(-100, 100, m)
        x0[N] = nav.pos[k0, 1] + rng.uniform(-100, 100, m)
        x0[U] = nav.pos[k0, 2] + rng.normal(0, 0.3, m)
        x0[PITCH] = nav.pitch[k0] + rng.normal(0, 0.05, m)
        x0[ROLL] = nav.roll[k0] + rng.normal(0, 0.05, m)
        x0[YAW] = nav.yaw[k0] + rng.uniform(-4, 4, m)
        x0[[BX, BZ]] = rng.normal(0, 1e-3, (2, m))
        noise = rng.standard_normal((6, m))
        x = x0.copy()
        innov = np.full((2, m), np.nan)
        prop.propagate_tight_euler(x, u[row], dt, inc[row], noise, 0.3, 0.01, 3e-4, dist_mode, innov)
        x_ref, innov_ref = prop.propagate_tight_euler_numpy(x0, u[row], dt, inc[row], noise, 0.3, 0.01, 3e-4,
                                                            dist_mode)
        np.testing.assert_allclose(x, x_ref, **TOL, err_msg=f"row {row}")
        if dist_mode == prop.DIST_NAVIGATION:
            np.testing.assert_allclose(innov, innov_ref, **TOL, err_msg=f"row {row}")


def test_propagate_tight_euler_geometry():
    """Reference-free: level, yaw 0 (north), forward 2 m/s for 5 s moves 10 m north; yaw +90 deg
    (counter-clockwise, west) moves 10 m west; the yaw integrates (w_z - eps_z) dt."""
    x = np.zeros((N_TIGHT, 3))
    x[YAW, 1] = math.pi / 2
    x[BZ, 2] = 0.01
    u = np.array([0.0, 2.0, 0.0, 0.02])
    inc = np.zeros(incmod.N_INCREMENTS)
    inc[incmod.DUP] = -1.5
    innov = np.empty((2, 3))
    prop.propagate_tight_euler(x, u, 5.0, inc, np.zeros((6, 3)), 1.0, 1.0, 1.0, prop.DIST_NONE, innov)
    np.testing.assert_allclose(x[[E, N], 0], [0.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(x[[E, N], 1], [-10.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(x[YAW], [0.1, math.pi / 2 + 0.1, 0.05], atol=1e-12)
    np.testing.assert_allclose(x[U], -1.5, atol=1e-12)


def test_euler_step_error_grows_with_the_sampling_time(run_inputs):
    """Reference-free: one Euler step on held inputs departs from the exact displacement of the
    navigation system by much more over 10 s than over 1 s in the lawn-mower's turns."""
    v, upd = run_inputs
    nav = v.nav
    worst = {}
    for step in (1, 10):
        idx = upd[::step]
        inc = compute_increments(v.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, idx)
        u = compute_euler_inputs(v.gyro, v.dvl_velocity, nav.pitch, nav.roll, nav.yaw, math.radians(30.0),
                                 idx, 100)
        x = np.zeros((N_TIGHT, idx.size - 1))
        x[PITCH], x[ROLL], x[YAW] = nav.pitch[idx[:-1]], nav.roll[idx[:-1]], nav.yaw[idx[:-1]]
        moved = np.empty((idx.size - 1, 2))
        for r in range(idx.size - 1):
            one = np.ascontiguousarray(x[:, r:r + 1])
            prop.propagate_tight_euler(one, u[r], float(step), inc[r], np.zeros((6, 1)), 0.0, 0.0, 0.0,
                                       prop.DIST_NONE, np.empty((2, 1)))
            moved[r] = one[[E, N], 0]
        worst[step] = np.hypot(*(moved - inc[:, [incmod.D0E, incmod.D0N]]).T).max()
    assert worst[1] < 0.1  # metres: 1 s steps are nearly exact
    assert worst[10] > 10 * worst[1] and worst[10] > 1.0


def test_gaussian_horizontal_matches_numpy():
    x0 = np.random.default_rng(KERNEL_SEED).normal(size=(N_TIGHT, 500))
    x = x0.copy()
    gaussian_horizontal(x, np.random.default_rng(7), 100.0, 200.0, 150.0)
    normals = np.random.default_rng(7).standard_normal((2, 500))  # the east row, then the north row
    np.testing.assert_allclose(x, gaussian_horizontal_numpy(x0, normals, 100.0, 200.0, 150.0), **TOL)
    assert (x[2:] == x0[2:]).all()
    assert abs(x[0].std() - 150.0) < 15.0


@pytest.mark.parametrize("reading, expect", [("per-component", (0.1, 1.0)), ("scalar-norm", (1.0, 1.0)),
                                             ("scalar-determinant", (0.01, 0.01))])
def test_measurement_sigmas(reading, expect):
    f = Scenario(filter={"likelihood_r": reading}).filter
    assert f.measurement_sigmas_m == pytest.approx(expect)


def test_new_options_at_neutral_change_no_key():
    """Every new option at its neutral value leaves the cell and world keys as they were."""
    base = Scenario()
    same = Scenario(filter={"propagation": "exact", "likelihood_r": "per-component", "initial_cloud": "uniform",
                            "divergence_reinit": True, "collapse_reinit": "respread"},
                    terrain={"region_hurst": None})
    assert same.cell_key() == base.cell_key() and same.world_key() == base.world_key()
    assert "propagation" not in base.identity()["filter"]
    euler = Scenario(filter={"propagation": "euler-last-second"})
    assert euler.cell_key() != base.cell_key() and euler.world_key() == base.world_key()
    rough = Scenario(terrain={"region_hurst": {"A": 0.8}})
    assert rough.world_key() != base.world_key()


def test_roughness_override_keeps_calibration():
    paper = layout("paper")
    rough = with_roughness(paper, {"A": 0.8}, {"B": 350.0})
    a = {r.name: r for r in rough.regions}
    assert a["A"].hurst == 0.8 and a["A"].corner_m == {r.name: r for r in paper.regions}["A"].corner_m
    assert a["B"].corner_m == 350.0 and a["A"].calibration is not None
    with pytest.raises(ValueError, match="no region 'C'"):
        with_roughness(paper, {"C": 1.0})


def test_profile_in_a_sweep():
    text = "name: p\nseed: 1\nruns: 1\nprofile: zhou2017-literal\nscenario: {filter: {resampling: systematic}}\n" \
           "tables:\n  a: {}\n  b: {filter.regularisation: [liu-west]}\n"
    sweep = parse_sweep(text)
    a, b = (c.scenario.filter for c in sweep.cells)
    assert a.propagation == "euler-last-second" and a.ess_threshold == 1.0 and a.likelihood_r == "scalar-norm"
    assert a.resampling == "systematic"  # the sweep's scenario overrides the profile
    assert a.regularisation == "none" and b.regularisation == "liu-west"  # a table switches one back
    assert profile_settings("recommended") == {}
    assert "filter.propagation = 'euler-last-second'" in "\n".join(describe_profile("zhou2017-literal"))
    with pytest.raises(TanbenchError, match="unknown profile 'nope'"):
        parse_sweep(text.replace("zhou2017-literal", "nope"))


def test_literal_profile_values_are_valid_options():
    """Each literal setting is a value its option accepts, and not the recommended one unless documented so."""
    sc = parse_sweep("name: p\nseed: 1\nruns: 1\nprofile: zhou2017-literal\n").cells[0].scenario
    flat = {f"filter.{k}": v for k, v in sc.filter.model_dump().items()}
    for key, (value, source) in PROFILES["zhou2017-literal"].items():
        assert flat[key] == value and source


# ---- the options inside the filter loops ------------------------------------------------
from filters_support import filter_seed, short_scenario, vehicle_seed  # noqa: E402
from tanbench.methods import run_method  # noqa: E402
from tanbench.simulation import simulate_vehicle  # noqa: E402


@pytest.fixture(scope="module")
def short_run():
    sc = short_scenario(duration_s=60.0, particles=300)
    return sc, simulate_vehicle(sc, vehicle_seed(0))


@pytest.mark.parametrize("method", ["tight-dvl", "loose-dvl"])
def test_divergence_reinit_off_never_reinitialises(short_run, method):
    """A divergence threshold no particle meets: with divergence_reinit the filter restarts, without it never."""
    sc, v = short_run
    # the paper readings apply to the tight filters and to the paper's (fix-only) loose filter
    strict = {"divergence_sigma": 1e-3, "divergence_steps": 2, "loose_architecture": "fix-only"}
    on = run_method(sc.model_copy(update={"filter": sc.filter.model_copy(update=strict)}), method, v,
                    filter_seed(0, 0))
    off = run_method(sc.model_copy(update={"filter": sc.filter.model_copy(
        update={**strict, "divergence_reinit": False})}), method, v, filter_seed(0, 0))
    assert on.metrics["reinitialisations"] > 10 and off.metrics["reinitialisations"] == 0


@pytest.mark.parametrize("method", ["tight-sbe", "loose-dvl"])
def test_collapse_initial_redraws_the_cloud(short_run, method):
    """A collapse threshold above any cloud: 'initial' redraws the cloud at every resampling,
    'respread' never reinitialises (it jitters the positions instead)."""
    sc, v = short_run
    f = sc.filter.model_copy(update={"min_spread_m": 1000.0, "ess_threshold": 1.0, "divergence_reinit": False,
                                     "loose_architecture": "fix-only"})
    initial = run_method(sc.model_copy(update={"filter": f.model_copy(update={"collapse_reinit": "initial"})}),
                         method, v, filter_seed(0, 1))
    respread = run_method(sc.model_copy(update={"filter": f}), method, v, filter_seed(0, 1))
    k = initial.series["t"].size
    assert initial.metrics["reinitialisations"] >= k - 2 and respread.metrics["reinitialisations"] == 0


def test_gaussian_initial_cloud_in_a_run(short_run):
    """The first update's weighted spread is wider with a 150 m-std Gaussian cloud than the uniform square."""
    sc, v = short_run
    flat = sc.filter.model_copy(update={"measurement_noise_altitude_m": 1e3,  # weights ~ uniform
                                        "loose_architecture": "fix-only"})  # var_e is then the cloud's
    uni = run_method(sc.model_copy(update={"filter": flat}), "loose-dvl", v, filter_seed(0, 2))
    gau = run_method(sc.model_copy(update={"filter": flat.model_copy(update={"initial_cloud": "gaussian"})}),
                     "loose-dvl", v, filter_seed(0, 2))
    s_uni = math.sqrt(uni.series["var_e"][0])
    s_gau = math.sqrt(gau.series["var_e"][0])
    assert abs(s_uni - 150 / math.sqrt(12)) < 5 and abs(s_gau - 150.0) < 12


def test_validate_shows_what_the_literal_profile_sets():
    """`tanbench validate configs/zhou2017-literal.yaml` lists every setting of the profile with its source."""
    from sweep_support import ROOT, cli

    proc = cli("validate", ROOT / "configs" / "zhou2017-literal.yaml")
    assert proc.returncode == 0, proc.stderr
    assert "profile zhou2017-literal sets:" in proc.stdout
    for key, (value, _) in PROFILES["zhou2017-literal"].items():
        assert f"{key} = {value!r}" in proc.stdout


def test_literal_family_options_neutral_and_acting():
    """Issue 23's readings: at their neutral values no key moves; otherwise they change the cell, not the world."""
    base = Scenario()
    same = Scenario(filter={"position_noise_growth": "linear"})
    assert same.cell_key() == base.cell_key() and "position_noise_growth" not in base.identity()["filter"]
    for f in ({"position_noise_growth": "sqrt"}, {"propagation": "euler-interval-start"}):
        s = Scenario(filter=f)
        assert s.cell_key() != base.cell_key() and s.world_key() == base.world_key()


def test_position_step_grows_with_t_or_its_root():
    lin, root = (Scenario(sampling_time_s=10.0, filter={"position_noise_growth": g}) for g in ("linear", "sqrt"))
    assert lin.position_step_m == pytest.approx(1.0)
    assert root.position_step_m == pytest.approx(0.1 * math.sqrt(10.0))
    one = [Scenario(filter={"position_noise_growth": g}).position_step_m for g in ("linear", "sqrt")]
    assert one[0] == one[1]


def test_euler_inputs_at_the_interval_start(run_inputs):
    """euler-interval-start: interval m's inputs are the one sample at its start (update m)."""
    v, upd = run_inputs
    nav = v.nav
    start = np.concatenate([upd[:1], upd[:-1] + 1])
    u = compute_euler_inputs(v.gyro, v.dvl_velocity, nav.pitch, nav.roll, nav.yaw, math.radians(30.0), start, 1)
    ref = euler_inputs_numpy(v.gyro, v.dvl_velocity, nav.pitch, nav.roll, nav.yaw, math.radians(30.0), upd, 1)
    np.testing.assert_allclose(u[:, incmod.EU_VX], v.dvl_velocity[upd[:-1], 0], rtol=1e-12)
    # the start sample of interval m is the update sample of interval m-1's end: shifted by one interval
    np.testing.assert_allclose(u[1:, incmod.EU_VY], v.dvl_velocity[upd[1:-1], 1], rtol=1e-12)
    assert u.shape == ref.shape
