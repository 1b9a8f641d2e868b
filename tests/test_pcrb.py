"""The posterior Cramér-Rao bound: closed forms on a tilted plane and on a flat seafloor."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tanbench.bounds.pcrb import (BoundModel, TrueTrack, bound, range_sensitivities, track_information,
                                  transition)
from tanbench.navigation.increments import compute_increments
from tanbench.sensors.sonar import altimeter_beam_vectors, dvl_beam_vectors, true_ranges
from tanbench.terrain.grid import Map
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

GRAD = (0.06, -0.025)  # dz/de, dz/dn of the tilted plane
Z0 = -70.0
SPEED, T_UPDATE, UPDATES = 2.0, 1.0, 400


def plane_map(grad=GRAD, res=10.0) -> Map:
    e = np.arange(0.0, 2001.0, res)
    n = np.arange(0.0, 2001.0, res)
    ee, nn = np.meshgrid(e, n)
    return Map(z=Z0 + grad[0] * ee + grad[1] * nn, e0=0.0, n0=0.0, res_e=res, res_n=res, name="plane")


def straight_track(grid: Map, beams: np.ndarray, yaw: float = -math.pi / 2, rate_hz: float = 100.0) -> TrueTrack:
    """A level straight run at 20 m depth from (400, 1000) with constant yaw (-pi/2 = east)."""
    n_samples = int(round(UPDATES * T_UPDATE * rate_hz))
    t = np.arange(n_samples) / rate_hz
    fwd = np.array([-math.sin(yaw), math.cos(yaw)])
    pos = np.column_stack([400.0 + SPEED * t * fwd[0], 1000.0 + SPEED * t * fwd[1], np.full(t.size, -20.0)])
    zeros = np.zeros(t.size)
    yaws = np.full(t.size, yaw)
    upd = np.arange(0, n_samples, int(round(T_UPDATE * rate_hz)))
    inc = compute_increments(1.0 / rate_hz, pos, zeros, zeros, yaws, upd)
    ranges = true_ranges(grid, pos[upd], zeros[upd], zeros[upd], yaws[upd], beams)
    return TrueTrack(t=t[upd], pos=pos[upd], pitch=zeros[upd], roll=zeros[upd], yaw=yaws[upd], ranges=ranges,
                     increments=inc)


def model(states="position", area=150.0, q=0.07, heading_noise=0.0, bias_std=0.0, range_std=0.8,
          heading_std=math.radians(30.0)) -> BoundModel:
    return BoundModel(states=states, initial_area_m=area, initial_std_heading_rad=heading_std,
                      initial_std_bias_rad_s=bias_std, position_noise_m=q, heading_noise_rad=heading_noise,
                      cross_track_heading_rad=0.0, range_std_m=range_std)


def riccati_closed_form(p0: float, q2: float, a: float, k: np.ndarray) -> np.ndarray:
    """p_k of p -> (p + q2) / (a (p + q2) + 1) after a first update p0 -> p0 / (a p0 + 1), closed form.

    The map is the Moebius transformation of M = [[1, q2], [a, 1 + a q2]] (det 1), so
    M^k = s_k M - s_{k-1} I with s_k = (l+^k - l-^k) / (l+ - l-) (Cayley-Hamilton).
    """
    p_first = p0 / (a * p0 + 1.0)
    tau = 2.0 + a * q2
    lp, lm = (tau + math.sqrt(tau * tau - 4)) / 2, (tau - math.sqrt(tau * tau - 4)) / 2

    def s(j):
        return (lp ** j - lm ** j) / (lp - lm)

    m11, m12, m21, m22 = 1.0, q2, a, 1.0 + a * q2
    sk, sk1 = s(k.astype(float)), s(k.astype(float) - 1)
    A, B = sk * m11 - sk1, sk * m12
    C, D = sk * m21, sk * m22 - sk1
    return (A * p_first + B) / (C * p_first + D)


@pytest.mark.parametrize("sensor", ["dvl", "sbe"])
def test_tilted_plane_matches_closed_form(sensor):
    """Every beam sees the same gradient: information along it only, a scalar Riccati recursion."""
    grid = plane_map()
    beams = dvl_beam_vectors(30.0, (0, 90, 180, 270)) if sensor == "dvl" else altimeter_beam_vectors()
    track = straight_track(grid, beams)
    m = model()
    P = bound([track], beams, grid, m)
    g = np.array(GRAD)
    u = g / np.linalg.norm(g)
    v = np.array([-u[1], u[0]])
    # per ping: sum_i |g|^2 / (sigma^2 D_i^2), D_i = b_u - g . b_h (level, constant yaw)
    b_nav = beams @ dcm_body_to_nav_numpy(np.zeros(1), np.zeros(1), np.array([track.yaw[0]]))[0].T
    a = float(np.sum(g @ g / (m.range_std_m**2 * (b_nav[:, 2] - b_nav[:, :2] @ g) ** 2)))
    k = np.arange(UPDATES)
    p0 = m.initial_area_m**2 / 12.0
    along = riccati_closed_form(p0, m.position_noise_m**2, a, k)
    across = p0 + k * m.position_noise_m**2
    got_along = np.einsum("i,kij,j->k", u, P, u)
    got_across = np.einsum("i,kij,j->k", v, P, v)
    np.testing.assert_allclose(got_along, along, rtol=0.01)
    np.testing.assert_allclose(got_across, across, rtol=0.01)
    horizontal = np.sqrt(P[:, 0, 0] + P[:, 1, 1])
    np.testing.assert_allclose(horizontal, np.sqrt(along + across), rtol=0.01)
    assert along[-1] < 0.05 * across[-1]  # the plane pins one direction and leaves the other free


def test_flat_world_is_dead_reckoning_growth():
    """No slope, no information: the bound is the filter model's dead-reckoning covariance."""
    grid = plane_map(grad=(0.0, 0.0))
    beams = dvl_beam_vectors(30.0, (0, 90, 180, 270))
    track = straight_track(grid, beams)  # east at 2 m/s: heading errors move the vehicle north
    q, sig_a, sig0 = 0.07, math.radians(2.0) / 60.0, math.radians(30.0)
    m = model(states="full", q=q, heading_noise=sig_a, heading_std=sig0)
    assert m.state_names == ("E", "N", "psi")  # zero bias prior: the biases are known, not states
    P = bound([track], beams, grid, m)
    k = np.arange(UPDATES)
    p0 = m.initial_area_m**2 / 12.0
    d = SPEED * T_UPDATE
    # N_k = N_0 + sum_{i<k} (d delta_i + q w_i), delta_i = delta_0 + sum_{j<i} sig_a v_j
    ii, jj = np.meshgrid(k, k, indexing="ij")
    cov_delta = sig0**2 + np.minimum(ii, jj) * sig_a**2
    north = np.array([p0 + kk * q**2 + d**2 * cov_delta[:kk, :kk].sum() for kk in k])
    np.testing.assert_allclose(P[:, 0, 0], p0 + k * q**2, rtol=1e-6)
    np.testing.assert_allclose(P[:, 1, 1], north, rtol=1e-6)
    np.testing.assert_allclose(P[:, 2, 2], sig0**2 + k * sig_a**2, rtol=1e-6)


def plane_range(point, b_nav, grad):
    """Exact range from ``point`` along ``b_nav`` to the plane z = Z0 + g . (e, n)."""
    g = np.asarray(grad)
    return (Z0 + g @ point[:2] - point[2]) / (b_nav[2] - g @ b_nav[:2])


def test_range_sensitivities_match_finite_differences():
    grad = (0.08, 0.05)
    beams = dvl_beam_vectors(30.0, (0, 90, 180, 270))
    pitch, roll, yaw = 0.03, -0.02, 0.7
    x = np.array([500.0, 600.0, -25.0])

    def ranges(point, yaw_):
        c = dcm_body_to_nav_numpy(np.array([pitch]), np.array([roll]), np.array([yaw_]))[0]
        return np.array([plane_range(point, c @ b, grad) for b in beams]), beams @ c.T

    r, b_nav = ranges(x, yaw)
    sens = range_sensitivities(np.full(4, grad[0]), np.full(4, grad[1]), b_nav, r)
    h = 1e-4
    fd_e = (ranges(x + [h, 0, 0], yaw)[0] - ranges(x - [h, 0, 0], yaw)[0]) / (2 * h)
    fd_n = (ranges(x + [0, h, 0], yaw)[0] - ranges(x - [0, h, 0], yaw)[0]) / (2 * h)
    fd_psi = (ranges(x, yaw + h)[0] - ranges(x, yaw - h)[0]) / (2 * h)
    np.testing.assert_allclose(sens[:, 0], fd_e, rtol=1e-6)
    np.testing.assert_allclose(sens[:, 1], fd_n, rtol=1e-6)
    np.testing.assert_allclose(sens[:, 2], fd_psi, rtol=1e-6)


def test_transition_matches_brute_force_propagation():
    """F's heading and bias columns: finite differences of the particle propagation kernel."""
    from tanbench.filters.propagate import DIST_NONE, propagate_tight_numpy
    from tanbench.filters.state import N_TIGHT

    rate = 100.0
    n_samples = 1001
    t = np.arange(n_samples) / rate
    yaw = -math.pi / 2 + 0.02 * t  # turning
    roll = 0.1 * np.sin(0.3 * t)
    pitch = np.full(t.size, 0.05)
    fwd = np.column_stack([-np.sin(yaw) * np.cos(pitch), np.cos(yaw) * np.cos(pitch)])
    pos = np.column_stack([400 + np.cumsum(fwd[:, 0]) * 2 / rate, 1000 + np.cumsum(fwd[:, 1]) * 2 / rate,
                           np.full(t.size, -20.0)])
    upd = np.array([0, 1000])
    inc = compute_increments(1 / rate, pos, pitch, roll, yaw, upd)
    F, _ = transition(inc, model(states="full", bias_std=1e-4))
    x0 = np.zeros((N_TIGHT, 1))  # one particle (a column)
    x0[5, 0] = yaw[0]
    cols = {2: 5, 3: 6, 4: 7}  # bound state -> filter state (psi, eps_x, eps_z)
    h = 1e-6
    for s, c in cols.items():
        xp, xm = x0.copy(), x0.copy()
        xp[c, 0] += h
        xm[c, 0] -= h
        yp, _ = propagate_tight_numpy(xp, inc[0], yaw[0], np.zeros((6, 1)), 0, 0, 0, DIST_NONE)
        ym, _ = propagate_tight_numpy(xm, inc[0], yaw[0], np.zeros((6, 1)), 0, 0, 0, DIST_NONE)
        fd = (yp[[0, 1, 5], 0] - ym[[0, 1, 5], 0]) / (2 * h)
        np.testing.assert_allclose(F[0, :3, s], fd, rtol=1e-5, atol=1e-9)


def test_off_map_footprints_carry_no_information():
    grid = plane_map()
    beams = altimeter_beam_vectors()
    track = straight_track(grid, beams)
    far = TrueTrack(t=track.t, pos=track.pos + [5000.0, 0, 0], pitch=track.pitch, roll=track.roll,
                    yaw=track.yaw, ranges=track.ranges, increments=track.increments)
    assert np.all(track_information(far, beams, grid, model()) == 0.0)
    assert np.all(track_information(track, beams, grid, model())[:, 0, 0] > 0.0)
