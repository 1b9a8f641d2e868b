"""Navigation: strapdown INS against its numpy reference, free-running drift, interval increments.

The increments tests integrate a particle's heading
psi_nav + delta + eps_x Sx(t) - eps_z Sz(t) by brute force at 100 Hz (the trapezoidal dead
reckoning of navigation/ins.py with the particle's heading) and compare the displacement
with the first-order formula d = Rz(delta) [D0 + eps_x J Ax - eps_z J Az].
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from tanbench.navigation import increments as inc
from tanbench.navigation.increments import compute_increments, increments_numpy
from tanbench.navigation.ins import run_strapdown, strapdown_numpy
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy, wrap_pi

DEG_H = math.radians(1.0) / 3600.0  # rad/s


def rz(delta) -> np.ndarray:
    """2-D rotation by the Eq. 5 yaw ``delta`` (counter-clockwise, east/north)."""
    c, s = math.cos(delta), math.sin(delta)
    return np.array([[c, -s], [s, c]])


def brute_force_displacement(dt, pitch, roll, yaw, vel_body, k0, k1, delta=0.0, eps_x=0.0, eps_z=0.0):
    """Horizontal displacement over samples k0..k1 of a particle with heading offset and gyro biases."""
    sl = slice(k0, k1 + 1)
    p, r = pitch[sl], roll[sl]
    sx = cumulative_trapezoid(np.sin(r) / np.cos(p), dx=dt, initial=0.0)
    sz = cumulative_trapezoid(np.cos(r) / np.cos(p), dx=dt, initial=0.0)
    psi = yaw[sl] + delta + eps_x * sx - eps_z * sz
    vb = np.column_stack([vel_body[sl, 0], vel_body[sl, 1], np.zeros(k1 - k0 + 1)])
    v = np.einsum("kij,kj->ki", dcm_body_to_nav_numpy(p, r, psi), vb)[:, :2]
    return 0.5 * dt * np.sum(v[:-1] + v[1:], axis=0)


def first_order_displacement(row, delta, eps_x, eps_z) -> np.ndarray:
    """d = Rz(delta) [D0 + eps_x J Ax - eps_z J Az] from one row of the increments table."""
    d0 = row[[inc.D0E, inc.D0N]]
    jax = row[[inc.JAXE, inc.JAXN]]
    jaz = row[[inc.JAZE, inc.JAZN]]
    return rz(delta) @ (d0 + eps_x * jax - eps_z * jaz)


@pytest.fixture(scope="module")
def synthetic_nav():
    """20 s of a rolling, pitching, turning navigation solution with its trapezoid-integrated track."""
    dt = 0.01
    t = np.arange(0.0, 20.0 + dt / 2, dt)
    pitch = np.radians(-5.0 + 2.0 * np.sin(0.3 * t))
    roll = np.radians(15.0 * np.sin(0.5 * t))
    yaw = 0.3 + 0.08 * t + 0.2 * np.sin(0.4 * t)  # turning
    vel = np.column_stack([0.1 * np.cos(t), 2.0 + 0.05 * np.sin(t), 0.02 * np.ones_like(t)])
    vb = vel.copy()
    vb[:, 2] = 0.0
    v = np.einsum("kij,kj->ki", dcm_body_to_nav_numpy(pitch, roll, yaw), vb)
    pos = np.zeros((t.size, 3))
    pos[0] = [500.0, 700.0, -30.0]
    pos[1:, :2] = pos[0, :2] + np.cumsum(0.5 * dt * (v[:-1, :2] + v[1:, :2]), axis=0)
    pos[1:, 2] = pos[0, 2]
    return dt, pos, pitch, roll, yaw, vel


# ---- strapdown -----------------------------------------------------------------------

@pytest.mark.parametrize("compensate", [True, False])
def test_strapdown_jit_matches_numpy_reference(paper_run, compensate):
    """Jitted strapdown equals strapdown_numpy to 1e-9 on 40 s of a noisy run (dive end and a turn)."""
    k0, k1 = 16_000, 20_000  # 160-200 s: the pitch ramp ends at 175 s, the first turn starts there
    r = paper_run
    args = (r.truth.dt, r.obs.gyro[k0:k1], r.obs.accel[k0:k1], r.obs.dvl_velocity[k0:k1], r.obs.depth[k0:k1],
            r.obs.nav.pos[k0, :2], r.obs.nav.yaw[k0], r.truth.latitude_rad, 1.0, compensate)
    jit = run_strapdown(*args)
    ref = strapdown_numpy(*args)
    for name, a, b in zip(("pos", "pitch", "roll", "yaw"), jit, ref):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9, err_msg=name)
    assert np.ptp(r.truth.yaw[k0:k1]) > 0.5  # the slice does contain a turn


def test_free_running_ins_drifts_hundreds_of_metres(paper_run, scenario, facts):
    """Table 1 sensors and a 30 deg initial heading error: dead reckoning ends > 100 m off after 1190 s."""
    r = paper_run
    assert scenario.sensors.grade == "table1"
    assert scenario.navigation.initial_heading_error_deg == facts["sensors"]["initial_heading_error_deg"]
    heading_err0 = -math.degrees(r.obs.nav.yaw[0] - r.truth.yaw[0])  # heading is -yaw
    assert heading_err0 == pytest.approx(facts["sensors"]["initial_heading_error_deg"], abs=1e-9)
    half = facts["trajectory"]["initial_horizontal_error_area_m"][0] / 2
    np.testing.assert_allclose(r.obs.nav.pos[0, :2] - r.truth.pos[0, :2], r.initial_position_error, atol=1e-9)
    assert np.all(np.abs(r.initial_position_error) <= half)
    err = np.linalg.norm(r.obs.nav.pos[:, :2] - r.truth.pos[:, :2], axis=1)
    assert r.truth.t[-1] == pytest.approx(facts["trajectory"]["total_s"])
    assert err[-1] > 100.0
    assert err.max() > 200.0
    np.testing.assert_allclose(r.obs.nav.pos[:, 2], -r.obs.depth, atol=0)  # up is the pressure depth
    # heading error stays near the initial 30 deg (gyro drift adds at most ~(30 + 3 x 25) deg/h)
    drift = np.degrees(np.abs(wrap_pi(r.obs.nav.yaw - r.truth.yaw) - (r.obs.nav.yaw[0] - r.truth.yaw[0])))
    assert drift.max() < 105.0 * r.truth.t[-1] / 3600.0


# ---- increments ----------------------------------------------------------------------

def test_increments_jit_matches_numpy_reference(paper_run, synthetic_nav):
    """compute_increments equals increments_numpy to 1e-9 (1 s, 5 s and irregular intervals)."""
    nav = paper_run.obs.nav
    dt = paper_run.truth.dt
    n = nav.yaw.size
    cases = [(dt, nav.pos, nav.pitch, nav.roll, nav.yaw, np.arange(0, n, 100)),
             (dt, nav.pos, nav.pitch, nav.roll, nav.yaw, np.arange(0, n, 500)),
             (dt, nav.pos, nav.pitch, nav.roll, nav.yaw, np.array([0, 1, 7, 250, 2000, 17_500, n - 1]))]
    d, pos, pitch, roll, yaw, _ = synthetic_nav
    cases.append((d, pos, pitch, roll, yaw, np.arange(0, yaw.size, 333)))
    for args in cases:
        jit = compute_increments(*args)
        ref = increments_numpy(*args)
        assert jit.shape == (args[-1].size - 1, inc.N_INCREMENTS)
        # 1e-9 absolute; relative 1e-12 for the ~1e5 m*s sums of the 1000 s irregular interval
        np.testing.assert_allclose(jit, ref, rtol=1e-12, atol=1e-9)
    # the displacements of consecutive intervals add up to the whole track
    table = compute_increments(dt, nav.pos, nav.pitch, nav.roll, nav.yaw, np.arange(0, n, 100))
    np.testing.assert_allclose(table[:, [inc.D0E, inc.D0N]].sum(axis=0), nav.pos[-1, :2] - nav.pos[0, :2],
                               atol=1e-6)
    assert compute_increments(dt, nav.pos, nav.pitch, nav.roll, nav.yaw, np.array([5])).shape == (0, 12)


def test_increments_computed_once_for_a_runs_methods(paper_run, monkeypatch):
    """The methods of a run (each with its own read-only copy of the run's observations) get the
    table computed once, through their contexts, as a copy of their own; writeable arrays, other
    updates, another dt or another navigation solution are computed again, with the same numbers."""
    import dataclasses

    from tanbench.methods.api import MethodContext, method_inputs
    from tanbench.terrain.grid import Map

    calls = []
    kernel = inc.interval_increments
    monkeypatch.setattr(inc, "interval_increments", lambda *a: calls.append(1) or kernel(*a))
    run_obs = dataclasses.replace(paper_run.obs, shared_increments=inc.SharedIncrements())  # none computed yet
    nav, dt = run_obs.nav, run_obs.dt
    assert not any(a.flags.writeable for a in (nav.pos, nav.pitch, nav.roll, nav.yaw))
    upd = np.arange(0, nav.yaw.size, 100)
    nmap = Map(z=np.zeros((2, 2)), e0=0.0, n0=0.0, res_e=1.0, res_n=1.0)
    tables = []
    for _ in range(3):  # three methods' contexts on the same run
        obs, own_map = method_inputs(run_obs, nmap)
        updates = type("Updates", (), {"imu": upd.copy()})()
        ctx = MethodContext(name="m", scenario=None, obs=obs, nmap=own_map, updates=updates, rng=None)
        tables.append(ctx.increments())
        tables[-1][:] = -1.0  # a method's copy is its own
    assert len(calls) == 1
    shared = run_obs.shared_increments
    first = shared.table(dt, nav, upd)
    assert len(calls) == 1
    writeable = dataclasses.replace(nav, **{k: np.array(getattr(nav, k)) for k in ("pos", "pitch", "roll", "yaw")})
    again = shared.table(dt, writeable, upd)
    other_upd = shared.table(dt, nav, upd[:-1])
    other_dt = shared.table(dt * 2, nav, upd)
    assert len(calls) == 4
    assert first.tobytes() == again.tobytes() == other_upd.tobytes() + first[-1].tobytes()
    assert first.tobytes() == compute_increments(dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd).tobytes()
    assert other_dt.tobytes() != first.tobytes()
    np.testing.assert_allclose(first, increments_numpy(dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd),
                               rtol=1e-12, atol=1e-9)


def test_increments_zero_bias_is_a_rotation(synthetic_nav):
    """With zero biases a particle's displacement is Rz(delta) D0: the nav displacement rotated."""
    dt, pos, pitch, roll, yaw, vel = synthetic_nav
    idx = np.arange(0, yaw.size, 500)
    table = compute_increments(dt, pos, pitch, roll, yaw, idx)
    for m, (k0, k1) in enumerate(zip(idx[:-1], idx[1:])):
        nav_d = brute_force_displacement(dt, pitch, roll, yaw, vel, k0, k1)
        np.testing.assert_allclose(nav_d, pos[k1, :2] - pos[k0, :2], atol=1e-9)  # the nav's own track
        for delta in (-2.5, -0.3, 0.0, 0.7, math.pi):
            want = brute_force_displacement(dt, pitch, roll, yaw, vel, k0, k1, delta)
            np.testing.assert_allclose(first_order_displacement(table[m], delta, 0.0, 0.0), want,
                                       rtol=0, atol=1e-9)
            np.testing.assert_allclose(rz(delta) @ (pos[k1, :2] - pos[k0, :2]), want, rtol=0, atol=1e-9)


def _check_first_order(dt, pos, pitch, roll, yaw, vel, k0, k1):
    table = compute_increments(dt, pos, pitch, roll, yaw, np.array([k0, k1]))
    row = table[0]
    sx = cumulative_trapezoid(np.sin(roll[k0:k1 + 1]) / np.cos(pitch[k0:k1 + 1]), dx=dt)[-1]
    sz = cumulative_trapezoid(np.cos(roll[k0:k1 + 1]) / np.cos(pitch[k0:k1 + 1]), dx=dt)[-1]
    assert row[inc.SX] == pytest.approx(sx, abs=1e-12) and row[inc.SZ] == pytest.approx(sz, abs=1e-12)
    assert row[inc.DYAW] == pytest.approx(yaw[k1] - yaw[k0], abs=1e-12)
    worst, effect = 0.0, 0.0
    for delta in (-1.2, 0.0, 0.6, 2.9):
        for eps_x, eps_z in ((55.0, 0.0), (0.0, 55.0), (55.0, -55.0), (-40.0, 25.0)):
            ex, ez = eps_x * DEG_H, eps_z * DEG_H
            want = brute_force_displacement(dt, pitch, roll, yaw, vel, k0, k1, delta, ex, ez)
            got = first_order_displacement(row, delta, ex, ez)
            worst = max(worst, float(np.linalg.norm(got - want)))
            effect = max(effect, float(np.linalg.norm(want - rz(delta) @ row[[inc.D0E, inc.D0N]])))
    assert worst < 1e-3, f"first-order formula off by {worst * 1e3:.3f} mm"
    assert effect > 5e-3  # the bias terms matter: the check is not vacuous
    return worst


@pytest.mark.parametrize("t0", [170.0, 180.0, 200.0])
def test_increments_first_order_matches_brute_force_in_a_turn(paper_run, t0):
    """On the noisy run's navigation solution, 10 s intervals in the first turn: formula vs 100 Hz < 1 mm."""
    r, nav = paper_run, paper_run.obs.nav
    k0 = int(round(t0 / r.truth.dt))
    k1 = k0 + int(round(10.0 / r.truth.dt))
    assert np.ptp(r.truth.yaw[k0:k1 + 1]) > 0.1  # a turn happens inside the interval
    _check_first_order(r.truth.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, r.obs.dvl_velocity, k0, k1)


def test_increments_first_order_matches_brute_force_with_roll(synthetic_nav):
    """With +-15 deg roll and varying pitch (Sx matters), 10 s intervals: formula vs 100 Hz < 1 mm."""
    dt, pos, pitch, roll, yaw, vel = synthetic_nav
    for k0 in (0, 500, 1000):
        _check_first_order(dt, pos, pitch, roll, yaw, vel, k0, k0 + 1000)
