"""Vehicle: Eq. 5 attitude, the paper's and the vehicle-run trajectories, error-free INS, simulation.

The simulation tests (``simulate_vehicle``) live here too: reproducibility from the seed
alone, common random numbers across noise levels, and the off-map refusal.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tanbench.config import Scenario
from tanbench.errors import TanbenchError
from tanbench.navigation.ins import run_strapdown
from tanbench.simulation import motion_plan, simulate_vehicle
from tanbench.terrain import navigation_map, truth_map
from tanbench.vehicle.attitude import dcm_body_to_nav, dcm_body_to_nav_numpy, wrap_pi
from tanbench.vehicle.trajectory import simulate_truth


def _segment_ends(facts) -> np.ndarray:
    """End times (s) of the paper's trajectory segments."""
    return np.cumsum([seg["duration_s"] for seg in facts["trajectory"]["segments"]])


# ---- attitude (Eq. 5) --------------------------------------------------------------

def test_dcm_jit_matches_numpy_and_is_a_rotation():
    """Jitted C_b^n equals the numpy Rz Rx Ry product to 1e-12 and is orthonormal with det 1."""
    rng = np.random.default_rng(3)
    pitch = rng.uniform(-1.5, 1.5, 500)
    roll = rng.uniform(-math.pi, math.pi, 500)
    yaw = rng.uniform(-2 * math.pi, 2 * math.pi, 500)
    ref = dcm_body_to_nav_numpy(pitch, roll, yaw)
    out = np.empty((3, 3))
    for k in range(500):
        dcm_body_to_nav(pitch[k], roll[k], yaw[k], out)
        np.testing.assert_allclose(out, ref[k], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ref @ np.swapaxes(ref, -1, -2), np.broadcast_to(np.eye(3), ref.shape),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(ref), 1.0, rtol=0, atol=1e-12)


def test_dcm_conventions():
    """Eq. 5 conventions: yaw +90 deg points forward west, pitch up raises the nose, roll lowers starboard."""
    fwd = np.array([0.0, 1.0, 0.0])
    stbd = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(dcm_body_to_nav_numpy(0, 0, math.pi / 2) @ fwd, [-1, 0, 0], atol=1e-15)
    assert (dcm_body_to_nav_numpy(0.1, 0, 0) @ fwd)[2] > 0
    assert (dcm_body_to_nav_numpy(0, 0.1, 0) @ stbd)[2] < 0


# ---- trajectories -------------------------------------------------------------------

def test_paper_trajectory_shape(paper_run, facts, scenario):
    """Area A run: 1190 s from the paper's start, pitch 0 -> -5 deg -> 0, depth -20 -> -37.5 -> -20, 2 m/s."""
    tr = paper_run.truth
    ends = _segment_ends(facts)
    assert tr.t[-1] == pytest.approx(facts["trajectory"]["total_s"]) == pytest.approx(ends[-1])
    assert tr.dt == pytest.approx(facts["sensors"]["ins_update_period_s"])
    np.testing.assert_allclose(tr.pos[0], facts["areas"]["A"]["start_enu_m"], atol=1e-12)

    def at(t):
        return int(round(t / tr.dt))

    pitch = np.degrees(tr.pitch)
    # first 25 s straight and level to the north
    assert np.all(pitch[: at(ends[0]) + 1] == 0) and np.all(tr.yaw[: at(ends[2]) + 1] == 0)
    np.testing.assert_allclose(tr.pos[: at(ends[2]) + 1, 0], tr.pos[0, 0], atol=1e-9)
    # dive to about -5 deg, hold, level off; mirrored at the end
    assert pitch.min() == pytest.approx(-5.0, abs=0.01)
    np.testing.assert_allclose(pitch[at(ends[1]):at(ends[2]) + 1], pitch.min(), atol=1e-9)
    assert abs(pitch[at(ends[3])]) < 1e-9 and abs(pitch[-1]) < 1e-9
    assert np.all(np.abs(pitch[at(ends[3]):at(ends[4]) + 1]) < 1e-9)  # level during the cruise
    # depth: -20 -> closed-form bottom -> -20
    rate = math.radians(scenario.trajectory.dive_pitch_rate_deg_s)
    th = math.radians(5.0)
    dz = -tr.vel_body[0, 1] * (2 * (1 - math.cos(th)) / rate + (ends[2] - ends[1]) * math.sin(th))
    start_up = facts["areas"]["A"]["start_enu_m"][2]
    assert tr.pos[at(ends[3]), 2] == pytest.approx(start_up + dz, abs=1e-3)
    assert tr.pos[at(ends[3]), 2] == pytest.approx(-37.5, abs=0.5)
    assert tr.pos[:, 2].min() == pytest.approx(start_up + dz, abs=1e-3)
    assert tr.pos[-1, 2] == pytest.approx(start_up, abs=1e-6)
    # constant speed along the path and in the body frame
    speed = np.linalg.norm(np.diff(tr.pos, axis=0), axis=1) / tr.dt
    np.testing.assert_allclose(speed, facts["trajectory"]["speed_mps"], rtol=1e-6)
    forward = np.broadcast_to([0.0, facts["trajectory"]["speed_mps"], 0.0], tr.vel_body.shape)
    np.testing.assert_array_equal(tr.vel_body, forward)


@pytest.mark.parametrize("area", ["A", "B"])
def test_track_uncertainty_and_footprints_inside_map(area, facts):
    """Beam footprints +- (150 m square + 100 m initial error)/2 stay inside the truth and 30 m maps."""
    s = Scenario(area=area, noise_m=0.0)  # noise-free ranges: exact footprints
    np.testing.assert_allclose(s.trajectory.start_enu_m, facts["areas"][area]["start_enu_m"])
    run = simulate_vehicle(s, np.random.SeedSequence(0))
    tr, k = run.truth, run.obs.ping_idx
    assert tr.t[k][-1] == facts["trajectory"]["total_s"]
    margin = (facts["filter"]["initial_uniform_area_m"][0]
              + facts["trajectory"]["initial_horizontal_error_area_m"][0]) / 2.0
    c_bn = dcm_body_to_nav_numpy(tr.pitch[k], tr.roll[k], tr.yaw[k])
    beams = np.vstack([run.obs.dvl_beams, run.obs.sbe_beams])
    ranges = np.hstack([run.obs.dvl_ranges, run.obs.sbe_ranges])
    assert np.isfinite(ranges).all()  # every beam finds the bottom on the whole run
    foot = tr.pos[k][:, None, :] + ranges[..., None] * np.einsum("nij,mj->nmi", c_bn, beams)
    tmap = truth_map(s.terrain)
    # footprints sit on the seafloor, and with the margin inside every map the filters may use
    np.testing.assert_allclose(tmap.elevation(foot[..., 0], foot[..., 1]), foot[..., 2], atol=1e-6)
    for m in (tmap, navigation_map(s.terrain, 10), navigation_map(s.terrain, 30)):
        assert m.contains(foot[..., 0], foot[..., 1], margin=margin).all(), m.name
        assert m.contains(tr.pos[:, 0], tr.pos[:, 1], margin=margin).all(), m.name


def test_vehicle_run_trajectory(facts):
    """The vehicle-run analog lasts 750 s, starts at (1000, 3500) at the surface, heads east, fits its map."""
    v = facts["vehicle_test"]
    s = Scenario(area="vehicle")
    plan = motion_plan(s)
    assert plan.duration == pytest.approx(v["duration_s"])
    tr = simulate_truth(plan, s.sensors.imu_rate_hz, s.sensors.latitude_deg)
    assert tr.t[-1] == pytest.approx(v["duration_s"])
    np.testing.assert_allclose(tr.pos[0, :2], v["start_enu_m"], atol=1e-12)
    np.testing.assert_allclose(tr.pos[:, 2], 0.0, atol=1e-9)
    vel = np.diff(tr.pos[:200, :2], axis=0) / tr.dt
    np.testing.assert_allclose(vel, np.broadcast_to([2.0, 0.0], vel.shape), atol=1e-6)
    # the run fits its own synthetic map and every beam finds the bottom
    run = simulate_vehicle(s, np.random.SeedSequence(0))
    assert run.truth.t[-1] == pytest.approx(v["duration_s"])
    assert np.isfinite(run.obs.dvl_ranges).all() and np.isfinite(run.obs.sbe_ranges).all()


def test_duration_cut_is_a_prefix_of_the_full_run(paper_run):
    """Scenario(duration_s=60) gives exactly the first 60 s of the full-length truth."""
    short = simulate_truth(motion_plan(Scenario(duration_s=60.0)))
    n = short.t.size
    assert short.t[-1] == pytest.approx(60.0)
    np.testing.assert_allclose(short.pos, paper_run.truth.pos[:n], rtol=0, atol=1e-9)
    np.testing.assert_allclose(short.pitch, paper_run.truth.pitch[:n], rtol=0, atol=1e-12)
    np.testing.assert_allclose(short.omega_ib[:-1], paper_run.truth.omega_ib[: n - 1], rtol=0, atol=1e-12)


def test_duration_longer_than_the_plan_is_refused():
    """duration_s beyond the 1190 s plan is refused with a TanbenchError naming duration_s."""
    # Known bug (simulation._cut): it indexes past the last segment and raises IndexError.
    with pytest.raises(TanbenchError, match="duration_s"):
        motion_plan(Scenario(duration_s=5000.0))


def test_error_free_imu_reproduces_truth(paper_run):
    """The strapdown INS on the error-free IMU, DVL and depth tracks the 1190 s truth to centimetres."""
    tr = paper_run.truth
    pos, pitch, roll, yaw = run_strapdown(tr.dt, tr.omega_ib, tr.f_body, tr.vel_body, -tr.pos[:, 2],
                                          tr.pos[0, :2], tr.yaw[0], tr.latitude_rad)
    assert tr.t[-1] == pytest.approx(1190.0)
    assert np.linalg.norm(pos[:, :2] - tr.pos[:, :2], axis=1).max() < 0.05
    assert np.degrees(np.abs(wrap_pi(yaw - tr.yaw))).max() < 0.01
    np.testing.assert_allclose(pos[:, 2], tr.pos[:, 2], atol=1e-9)
    # levelling lags by half its 1 s window during the 0.1 deg/s pitch ramps
    assert np.degrees(np.abs(pitch - tr.pitch)).max() < 0.06
    assert np.degrees(np.abs(roll)).max() < 0.01


# ---- simulate_vehicle ---------------------------------------------------------------

def _random_arrays(run) -> dict:
    return {
        "gyro": run.obs.gyro, "accel": run.obs.accel, "gyro_bias": run.imu_errors.gyro_bias,
        "accel_bias": run.imu_errors.accel_bias, "dvl_velocity": run.obs.dvl_velocity,
        "depth": run.obs.depth, "dvl_ranges": run.obs.dvl_ranges, "sbe_ranges": run.obs.sbe_ranges,
        "nav_pos": run.obs.nav.pos, "nav_yaw": run.obs.nav.yaw, "nav_pitch": run.obs.nav.pitch,
        "initial_position_error": run.initial_position_error,
        "dvl_scale_error": np.array(run.dvl_scale_error),
    }


def test_simulation_reproducible_from_seed(paper_run, run_seed):
    """simulate_vehicle called again with an equal seed (and scenario) gives identical arrays."""
    again = simulate_vehicle(Scenario(), np.random.SeedSequence(run_seed))
    a, b = _random_arrays(paper_run), _random_arrays(again)
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=True), key
    assert np.array_equal(again.truth.pos, paper_run.truth.pos)


def test_simulation_different_seeds_differ(paper_run, scenario, run_seed):
    """Another seed changes every random quantity of the run (the truth stays)."""
    other = simulate_vehicle(scenario, np.random.SeedSequence(run_seed + 1))
    a, b = _random_arrays(paper_run), _random_arrays(other)
    for key in a:
        assert not np.array_equal(a[key], b[key], equal_nan=True), key
    assert np.array_equal(other.truth.pos, paper_run.truth.pos)


def test_simulation_noise_levels_share_random_numbers(paper_run, scenario, run_seed):
    """noise_m 0 / 1 / 2 with one seed: everything equal except the range noise, which scales exactly."""
    assert scenario.noise_m == 1.0
    runs = {nm: simulate_vehicle(Scenario(noise_m=nm), np.random.SeedSequence(run_seed)) for nm in (0.0, 2.0)}
    runs[1.0] = paper_run
    base = _random_arrays(paper_run)
    for nm in (0.0, 2.0):
        other = _random_arrays(runs[nm])
        for key in base:
            if key not in ("dvl_ranges", "sbe_ranges"):
                assert np.array_equal(base[key], other[key]), (nm, key)
    for key in ("dvl_ranges", "sbe_ranges"):
        r0, r1, r2 = (getattr(runs[nm].obs, key) for nm in (0.0, 1.0, 2.0))
        assert np.isfinite(r0).all()
        unit = r1 - r0
        assert np.abs(unit).max() <= 1.0 + 1e-9 and np.abs(unit).max() > 0.99
        np.testing.assert_allclose(r2 - r0, 2.0 * unit, rtol=0, atol=1e-9)
    # the DVL and altimeter ranges have independent noise
    assert abs(np.corrcoef((runs[1.0].obs.dvl_ranges - runs[0.0].obs.dvl_ranges)[:, 0],
                           (runs[1.0].obs.sbe_ranges - runs[0.0].obs.sbe_ranges)[:, 0])[0, 1]) < 0.1


def test_track_leaving_the_map_raises():
    """A start near the eastern edge makes the lawn-mower leave the map: a clear TanbenchError."""
    s = Scenario(trajectory={"start_enu_m": [2950, 400, -20]})
    with pytest.raises(TanbenchError, match=r"leaves the map at t=\d+ s") as err:
        simulate_vehicle(s, np.random.SeedSequence(0))
    assert "the map spans E 0..3000, N 0..1200 m" in str(err.value)
    assert "\n" not in str(err.value)
