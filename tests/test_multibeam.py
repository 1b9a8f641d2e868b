"""The multibeam (issue 28): the fan's geometry against flat and sloped seafloors (analytic
ranges), the kernels against their numpy twins, the sensor's data (common random numbers,
ping rate, faults), the swath thinning and the bound's swath information."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tanbench.config import Scenario
from tanbench.filters.beams import nav_frame_offsets
from tanbench.filters.likelihood import Likelihood, loglik_tight, loglik_tight_numpy
from tanbench.filters.trig import attitude_reference
from tanbench.filters.swath import beam_information, beam_information_numpy, every_kth, most_informative
from tanbench.sensors.multibeam import (fan_angles_deg, fan_directions, fan_directions_numpy, fan_vectors,
                                        swath_ranges)
from tanbench.simulation import simulate_vehicle
from tanbench.terrain.grid import Map, node_grid_of

H = 40.0  # altitude of the vehicle above the test seafloors, m


def plane(slope_e: float = 0.0, slope_n: float = 0.0, res: float = 5.0) -> Map:
    """A plane seafloor z = -H + slope_e e + slope_n n over -500..500 m (the vehicle at the origin, up 0)."""
    c = np.arange(-500.0, 500.0 + res, res)
    ee, nn = np.meshgrid(c, c)
    return Map(z=-H + slope_e * ee + slope_n * nn, e0=-500.0, n0=-500.0, res_e=res, res_n=res)


def cast(tmap, angles_deg, pitch=0.0, roll=0.0, yaw=0.0):
    a = np.radians(np.asarray(angles_deg, dtype=float))[None, :]
    return swath_ranges(tmap, np.zeros((1, 3)), np.array([pitch]), np.array([roll]), np.array([yaw]), a, 1000.0)[0]


# ---- the fan -----------------------------------------------------------------------------------
def test_fan_patterns_span_the_swath_symmetrically():
    eq = fan_angles_deg(5, 120.0, "equiangular")
    np.testing.assert_allclose(eq, [-60, -30, 0, 30, 60])
    ed = fan_angles_deg(5, 120.0, "equidistant")
    np.testing.assert_allclose(np.diff(np.tan(np.radians(ed))), math.tan(math.radians(60)) / 2)  # equal across-track steps
    assert ed[0] == pytest.approx(-60) and ed[-1] == pytest.approx(60)
    assert list(fan_angles_deg(1, 120.0)) == [0.0]
    v = fan_vectors([-30.0, 0.0, 30.0])
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0)
    assert v[2, 0] > 0 and v[1, 2] == -1.0 and (v[:, 1] == 0).all()  # starboard positive, across track only


@pytest.mark.parametrize("angle", [-65.0, -30.0, 0.0, 12.5, 45.0, 70.0])
def test_flat_seafloor_ranges_and_footprints_are_analytic(angle):
    """Level vehicle H above a flat floor: r = H / cos a, footprint H tan a across track (starboard = east
    when heading north)."""
    r = cast(plane(), [angle])[0]
    assert r == pytest.approx(H / math.cos(math.radians(angle)), rel=1e-9)
    d = np.empty((1, 1, 3))
    fan_directions(np.zeros(1), np.zeros(1), np.zeros(1), np.radians([[angle]]), d)
    foot = r * d[0, 0]
    assert foot[0] == pytest.approx(H * math.tan(math.radians(angle)), abs=1e-6)
    assert foot[1] == pytest.approx(0.0, abs=1e-9) and foot[2] == pytest.approx(-H, abs=1e-6)


@pytest.mark.parametrize("slope", [-0.3, 0.1, 0.5])
def test_sloped_seafloor_ranges_are_analytic(slope):
    """A floor rising across track (z = -H + g e): r = H / (cos a + g sin a); along track (z = -H + g n)
    the across-track fan's ranges are the flat ones."""
    angles = np.array([-60.0, -20.0, 0.0, 35.0, 60.0])
    a = np.radians(angles)
    expected = H / (np.cos(a) + slope * np.sin(a))
    ok = (expected > 0) & (expected * np.abs(np.sin(a)) < 450)  # footprints on the 1 km map
    np.testing.assert_allclose(cast(plane(slope_e=slope), angles)[ok], expected[ok], rtol=1e-9)
    np.testing.assert_allclose(cast(plane(slope_n=slope), angles), H / np.cos(a), rtol=1e-9)


def test_roll_turns_the_fan_and_heading_turns_its_footprints():
    """Roll (starboard down positive) moves every beam's angle from the vertical by -roll on a flat
    floor; heading east puts the starboard footprints to the south."""
    angles = np.array([-40.0, -10.0, 0.0, 25.0, 50.0])
    roll = math.radians(8.0)
    np.testing.assert_allclose(cast(plane(), angles, roll=roll), cast(plane(), angles - 8.0), rtol=1e-9)
    d = np.empty((1, 1, 3))
    fan_directions(np.zeros(1), np.zeros(1), np.array([-math.pi / 2]), np.radians([[30.0]]), d)  # heading 90 deg
    assert d[0, 0, 1] == pytest.approx(-0.5) and d[0, 0, 0] == pytest.approx(0.0, abs=1e-12)


def test_fan_directions_kernel_matches_numpy():
    rng = np.random.default_rng(4)
    n, m = 7, 33
    pitch, roll, yaw = rng.normal(0, 0.1, n), rng.normal(0, 0.1, n), rng.uniform(-3, 3, n)
    angles = rng.uniform(-1.2, 1.2, (n, m))
    out = np.empty((n, m, 3))
    fan_directions(pitch, roll, yaw, angles, out)
    np.testing.assert_allclose(out, fan_directions_numpy(pitch, roll, yaw, angles), rtol=0, atol=1e-14)


# ---- the swath in the filters ------------------------------------------------------------------
def rough_map(seed=2, res=10.0) -> Map:
    rng = np.random.default_rng(seed)
    z = -60.0 + np.cumsum(np.cumsum(rng.normal(0, 0.3, (120, 120)), axis=0), axis=1) * 0.05
    return Map(z=z, e0=0.0, n0=0.0, res_e=res, res_n=res)


def test_beam_information_kernel_matches_numpy_and_thinning_keeps_the_informative_beams():
    tmap = rough_map()
    rng = np.random.default_rng(1)
    k, beams = 6, fan_vectors(fan_angles_deg(64, 120.0))
    ranges = rng.uniform(30, 90, (k, 64))
    ranges[0, 5] = np.nan
    offsets = nav_frame_offsets(rng.normal(0, .05, k), rng.normal(0, .05, k), rng.uniform(-3, 3, k), beams, ranges)
    nav_en = rng.uniform(400, 800, (k, 2))
    info = np.empty((k, 64))
    beam_information(offsets, nav_en, *tmap.kernel_args(), info)
    np.testing.assert_allclose(info, beam_information_numpy(offsets, nav_en, *tmap.kernel_args()), rtol=1e-10,
                               atol=1e-14)
    assert info[0, 5] == -1.0 and (info[np.isfinite(ranges)] >= 0).all()
    kept = most_informative(info, ranges, 8)
    assert (np.isfinite(kept).sum(axis=1) == 8).all()
    for row in range(k):  # every kept beam is at least as informative as every dropped one
        on = np.isfinite(kept[row])
        assert info[row, on].min() >= info[row, ~on & np.isfinite(ranges[row])].max()
    assert list(every_kth(256, 16)) == list(range(0, 256, 16)) and every_kth(64, 0).size == 64


@pytest.mark.parametrize("mapaware, kind", [(False, 0), (True, 1)])
def test_the_likelihood_kernel_weighs_a_64_beam_swath_as_its_numpy_twin(mapaware, kind):
    """The tight PF's likelihood loops over any number of beams: a 64-beam fan, some without a range."""
    tmap = rough_map(res=10.0)
    rng = np.random.default_rng(7)
    m = 500
    x = np.empty((8, m))
    x[0], x[1], x[2] = rng.uniform(500, 700, m), rng.uniform(500, 700, m), rng.normal(-10, 0.1, m)
    x[3], x[4], x[5] = rng.normal(0, 0.01, m), rng.normal(0, 0.01, m), rng.normal(0.3, 0.2, m)
    x[6:] = 0.0
    beams = fan_vectors(fan_angles_deg(64, 120.0))
    ranges = rng.uniform(40, 90, 64)
    ranges[[3, 40]] = np.nan
    mvar = np.full(tmap.z.shape, 0.2)
    grid = node_grid_of(*tmap.kernel_args(), mvar if mapaware else None)
    out = np.empty(m)
    best = loglik_tight(x, beams, ranges, grid, Likelihood(mapaware, kind, 4.0), 1.0, 5.0, np.zeros((2, m)), 0.1,
                        False, attitude_reference(0.0, 0.0, 0.3), out)
    ref, ref_best = loglik_tight_numpy(x, beams, ranges, tmap.kernel_args(), mvar, Likelihood(mapaware, kind, 4.0),
                                       1.0, 5.0, None, 0.1)
    np.testing.assert_allclose(out, ref, rtol=1e-9, atol=1e-7)
    assert best == pytest.approx(ref_best, rel=1e-9)


# ---- the sensor in a run -----------------------------------------------------------------------
@pytest.fixture(scope="module")
def runs():
    base = dict(area="A", duration_s=40, particles=200)
    seed = np.random.SeedSequence(9)
    plain = simulate_vehicle(Scenario(**base), seed)
    swath = simulate_vehicle(Scenario(**base, sensors={"multibeam_beams": 32, "multibeam_rate_hz": 0.5}), seed)
    faulty = simulate_vehicle(Scenario(**base, sensors={"multibeam_beams": 32},
                                       faults={"outlier_fraction": 0.2, "dropout_rate_per_ping": 0.2}), seed)
    return plain, swath, faulty


def test_switching_the_multibeam_on_changes_no_other_number(runs):
    plain, swath, _ = runs
    assert plain.obs.mbe_ranges is None and plain.obs.mbe_beams is None
    for name in ("gyro", "accel", "dvl_velocity", "depth", "dvl_ranges", "sbe_ranges"):
        assert np.array_equal(getattr(plain.obs, name), getattr(swath.obs, name), equal_nan=True), name
    assert np.array_equal(plain.obs.nav.pos, swath.obs.nav.pos)
    assert Scenario(sensors={"multibeam_beams": 32}).pairing_key() == Scenario().pairing_key()
    assert Scenario(sensors={"multibeam_beams": 32}).world_key() != Scenario().world_key()


def test_pings_at_every_kth_dvl_ping_with_the_fans_ranges(runs):
    _, swath, _ = runs
    r = swath.obs.mbe_ranges
    assert r.shape == (swath.obs.ping_idx.size, 32) and swath.obs.mbe_beams.shape == (32, 3)
    assert np.isnan(r[1::2]).all() and np.isfinite(r[::2]).mean() > 0.9
    # the nadir-most beams see about the altitude the altimeter sees (pointing and range noise aside)
    nadir = r[::2, 15:17].mean(axis=1)
    alt = swath.obs.sbe_ranges[::2, 0]
    assert np.nanmedian(np.abs(nadir - alt)) < 3.0


def test_faults_reach_the_swath(runs):
    _, swath, faulty = runs
    lost = np.isnan(faulty.obs.dvl_ranges).all(axis=1)
    assert lost.any() and np.isnan(faulty.obs.mbe_ranges[lost]).all()
    both = ~lost
    clean = simulate_vehicle(Scenario(area="A", duration_s=40, particles=200, sensors={"multibeam_beams": 32}),
                             np.random.SeedSequence(9)).obs.mbe_ranges
    wild = np.abs(faulty.obs.mbe_ranges[both] - clean[both]) > 1e-9
    assert 0.15 < wild[np.isfinite(clean[both])].mean() < 0.25  # outlier_fraction 0.2 of the measured ranges


def test_the_bound_falls_as_the_fan_gains_beams():
    """J adds over beams: the 61-beam fan holds the 16-beam fan's beams (8 deg = 4 x 2 deg), so its PCRB
    is no larger at any update."""
    from tanbench.bounds.pcrb import method_bound
    from tanbench.methods import get

    base = dict(area="A", duration_s=60, particles=200)
    bound = get("tight-mbe").bound
    assert bound == ("mbe", "full")
    few = method_bound(Scenario(**base, sensors={"multibeam_beams": 16}), bound)["pcrb_horizontal_m"]
    many = method_bound(Scenario(**base, sensors={"multibeam_beams": 61}), bound)["pcrb_horizontal_m"]
    assert (many.to_numpy() <= few.to_numpy() * (1 + 1e-9)).all() and many.iloc[-1] < few.iloc[-1]
