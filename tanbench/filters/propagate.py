"""Particle propagation (Eq. 1, Algorithm 1 line 4) between filter updates.

Tight: each particle moves by the navigation system's displacement rotated into its own
heading and corrected for its own gyro biases (see ``navigation/increments.py``); its
yaw integrates the gyro rate minus its biases; up, pitch and roll follow the pressure
sensor and the levelled accelerometers, each with its own random-walk noise.

The east/north "distance" innovations of Eqs. 14-18 have three readings (docs/model.md):

* ``DIST_PARTICLE`` (default): the DVL distance rotated through the particle's *own*
  attitude against the particle's predicted displacement. The innovation is then
  minus the particle's position process noise e ~ N(0, q^2), weighted by N(e; 0, r^2):
  exactly the same as drawing e from N(0, q^2 r^2 / (q^2 + r^2)) with no weight term,
  which is how it is implemented (same posterior, no extra weight variance). It never
  pulls the heading anywhere;
* ``DIST_NAVIGATION``: the navigation system's dead-reckoned distance against the
  particle's displacement; this pins every particle to the navigation heading;
* ``DIST_NONE``: no distance innovation (terrain altitude only, Table 2 process noise).

Only ``DIST_NAVIGATION`` leaves a per-particle innovation for the likelihood.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.state import BX, BZ, E, N, PITCH, ROLL, U, YAW
from tanbench.filters.trig import attitude_reference, particle_sin_cos, sin_cos_about
from tanbench.navigation.increments import (D0E, D0N, DPITCH, DROLL, DUP, DYAW, EU_VX, EU_VY, EU_WX, EU_WZ,
                                            JAXE, JAXN, JAZE, JAZN, SX, SZ)
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

from tanbench.options import DISTANCE_INNOVATION

DIST_NONE, DIST_PARTICLE, DIST_NAVIGATION = (DISTANCE_INNOVATION[k] for k in ("none", "particle", "navigation"))


@nb.njit(cache=True, inline="always")
def _move_particle(x, j, inc, de, dn, dyaw, n_e, n_n, n_u, n_pitch, n_roll, n_yaw, sig_pos, sig_up, sig_att,
                   dist_mode):
    """Move particle ``j`` by the displacement (de, dn) and heading change ``dyaw`` of either reading
    of Eq. 1, up, pitch and roll by the navigation's increments, each with its noise; returns the
    distance innovations (east, north)."""
    ee = sig_pos * n_e
    en = sig_pos * n_n
    x[j, E] += de + ee
    x[j, N] += dn + en
    x[j, U] += inc[DUP] + sig_up * n_u
    x[j, PITCH] += inc[DPITCH] + sig_att * n_pitch
    x[j, ROLL] += inc[DROLL] + sig_att * n_roll
    x[j, YAW] += dyaw + sig_att * n_yaw
    if dist_mode == DIST_NAVIGATION:
        return inc[D0E] - (de + ee), inc[D0N] - (dn + en)
    return 0.0, 0.0


@nb.njit(cache=True, inline="always")
def propagate_tight_particle(x, j, inc, yaw_nav0, yaw_off, s_off, c_off, n_e, n_n, n_u, n_pitch, n_roll, n_yaw,
                             sig_pos, sig_up, sig_att, dist_mode):
    """Move particle ``j`` of ``x`` as :func:`propagate_tight` does, with its six standard
    normals ``n_*``; returns its distance innovations (east, north).

    The particle's heading offset from the navigation, ``x[j, YAW] - yaw_nav0``, is rotated
    about ``yaw_off`` (the cloud's offset, with its sine ``s_off`` and cosine ``c_off``), so
    that its sine and cosine come from the short series of ``trig.sin_cos`` also when the
    navigation heading is far off (``yaw_off`` = 0, ``s_off`` = 0, ``c_off`` = 1: about the
    navigation heading itself, exactly).

    The ``*_particle`` functions are inlined into their callers and take the callers'
    floating-point flags: call them from ``fastmath=FASTMATH`` kernels only (the array
    kernels here and the filter loops' fused passes)."""
    bx = x[j, BX]
    bz = x[j, BZ]
    s, c = sin_cos_about(s_off, c_off, (x[j, YAW] - yaw_nav0) - yaw_off)
    ue = inc[D0E] + bx * inc[JAXE] - bz * inc[JAZE]
    un = inc[D0N] + bx * inc[JAXN] - bz * inc[JAZN]
    de = c * ue - s * un
    dn = s * ue + c * un
    return _move_particle(x, j, inc, de, dn, inc[DYAW] + bx * inc[SX] - bz * inc[SZ], n_e, n_n, n_u, n_pitch,
                          n_roll, n_yaw, sig_pos, sig_up, sig_att, dist_mode)


@nb.njit(cache=True, fastmath=FASTMATH)
def propagate_tight(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, yaw_off=0.0):
    """Move particles ``x`` (M, 8) over one interval; fill ``dist_innov`` (M, 2).

    ``sig_pos`` is the east/north noise per update (for ``DIST_PARTICLE`` the caller
    passes the combined q r / sqrt(q^2 + r^2), see :func:`position_noise`).

    ``inc`` is one row of the increments table, ``yaw_nav0`` the navigation yaw at the
    interval start, ``noise`` (M, 6) standard normals for E, N, U, pitch, roll, yaw.
    ``yaw_off`` (rad) is only where the trigonometry is centred (the cloud's heading offset
    from the navigation; :func:`propagate_tight_particle`): it does not change the motion.
    """
    s_off, c_off = math.sin(yaw_off), math.cos(yaw_off)
    for j in range(x.shape[0]):
        dist_innov[j, 0], dist_innov[j, 1] = propagate_tight_particle(
            x, j, inc, yaw_nav0, yaw_off, s_off, c_off, noise[j, 0], noise[j, 1], noise[j, 2], noise[j, 3],
            noise[j, 4], noise[j, 5], sig_pos, sig_up, sig_att, dist_mode)


def propagate_tight_numpy(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode):
    """Plain-numpy reference of :func:`propagate_tight`: returns (new x, dist_innov)."""
    x = x.copy()
    bx, bz = x[:, BX], x[:, BZ]
    delta = x[:, YAW] - yaw_nav0
    u = np.stack([inc[D0E] + bx * inc[JAXE] - bz * inc[JAZE], inc[D0N] + bx * inc[JAXN] - bz * inc[JAZN]], 1)
    rot = np.stack([np.stack([np.cos(delta), -np.sin(delta)], -1), np.stack([np.sin(delta), np.cos(delta)], -1)], -2)
    d = np.einsum("mij,mj->mi", rot, u)
    e = sig_pos * noise[:, :2]
    yaw_inc = inc[DYAW] + bx * inc[SX] - bz * inc[SZ]
    x[:, [E, N]] += d + e
    x[:, U] += inc[DUP] + sig_up * noise[:, 2]
    x[:, PITCH] += inc[DPITCH] + sig_att * noise[:, 3]
    x[:, ROLL] += inc[DROLL] + sig_att * noise[:, 4]
    x[:, YAW] += yaw_inc + sig_att * noise[:, 5]
    if dist_mode == DIST_NAVIGATION:
        innov = np.array([inc[D0E], inc[D0N]]) - (d + e)
    else:
        innov = np.zeros_like(e)
    return x, innov


@nb.njit(cache=True, inline="always")
def propagate_tight_euler_particle(x, j, u, dt, inc, att0, n_e, n_n, n_u, n_pitch, n_roll, n_yaw, sig_pos, sig_up,
                                   sig_att, dist_mode):
    """Move particle ``j`` as :func:`propagate_tight_euler` does, with its six standard normals;
    returns its distance innovations (east, north). Its attitude's sines and cosines are taken
    about the reference ``att0`` (``trig.attitude_reference``; only where the series is centred)."""
    vx = u[EU_VX]
    vy = u[EU_VY]
    wx = u[EU_WX]
    wz = u[EU_WZ]
    st, ct, sg, cg, sp, cp = particle_sin_cos(x, j, att0)
    de = ((cg * cp - st * sg * sp) * vx - ct * sp * vy) * dt
    dn = ((cg * sp + st * sg * cp) * vx + ct * cp * vy) * dt
    yaw_rate = (-sg * (wx - x[j, BX]) + cg * (wz - x[j, BZ])) / ct
    return _move_particle(x, j, inc, de, dn, yaw_rate * dt, n_e, n_n, n_u, n_pitch, n_roll, n_yaw, sig_pos, sig_up,
                          sig_att, dist_mode)


@nb.njit(cache=True, fastmath=FASTMATH)
def propagate_tight_euler(x, u, dt, inc, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, ref_pitch=0.0,
                          ref_roll=0.0, ref_yaw=0.0):
    """Eq. 1 read as one Euler step of length ``dt`` (the sampling time), Algorithm 1 line 4.

    ``u`` = (v_x, v_y, w_x, w_z): the DVL body velocity and body turn rates
    (``navigation.increments.euler_inputs``), held over the interval. Each particle moves
    by ``[1 0 0; 0 1 0] C_b^n(Theta_j) [v_x, v_y, 0] dt`` with its own attitude at the
    interval start, and its yaw by ``(-sin g_j (w_x - eps_x,j) + cos g_j (w_z - eps_z,j)) /
    cos th_j * dt``; up, pitch and roll follow the navigation system (``inc``: Eq. 1's 0_3,
    as in :func:`propagate_tight`). Noise and distance innovations as there; the
    navigation distance of ``DIST_NAVIGATION`` is the navigation system's displacement.
    ``ref_*`` (rad) only centre the trigonometry (``trig.particle_sin_cos``): the navigation
    attitude at the interval start, or the cloud's; they do not change the motion.
    """
    att0 = attitude_reference(ref_pitch, ref_roll, ref_yaw)
    for j in range(x.shape[0]):
        dist_innov[j, 0], dist_innov[j, 1] = propagate_tight_euler_particle(
            x, j, u, dt, inc, att0, noise[j, 0], noise[j, 1], noise[j, 2], noise[j, 3], noise[j, 4], noise[j, 5],
            sig_pos, sig_up, sig_att, dist_mode)


def propagate_tight_euler_numpy(x, u, dt, inc, noise, sig_pos, sig_up, sig_att, dist_mode):
    """Plain-numpy reference of :func:`propagate_tight_euler`: returns (new x, dist_innov)."""
    x = x.copy()
    c = dcm_body_to_nav_numpy(x[:, PITCH], x[:, ROLL], x[:, YAW])  # (M, 3, 3)
    d = (c @ np.array([u[EU_VX], u[EU_VY], 0.0]))[:, :2] * dt
    w = np.stack([u[EU_WX] - x[:, BX], np.zeros(len(x)), u[EU_WZ] - x[:, BZ]], 1)
    yaw_rate = (-np.sin(x[:, ROLL]) * w[:, 0] + np.cos(x[:, ROLL]) * w[:, 2]) / np.cos(x[:, PITCH])
    e = sig_pos * noise[:, :2]
    x[:, [E, N]] += d + e
    x[:, U] += inc[DUP] + sig_up * noise[:, 2]
    x[:, PITCH] += inc[DPITCH] + sig_att * noise[:, 3]
    x[:, ROLL] += inc[DROLL] + sig_att * noise[:, 4]
    x[:, YAW] += yaw_rate * dt + sig_att * noise[:, 5]
    innov = np.array([inc[D0E], inc[D0N]]) - (d + e) if dist_mode == DIST_NAVIGATION else np.zeros_like(e)
    return x, innov


@nb.njit(cache=True, inline="always")
def propagate_loose_particle(x, j, d0e, d0n, n_e, n_n, n_heading, sig_pos, sig_heading):
    """Move particle ``j`` as :func:`propagate_loose` does, with its three standard normals."""
    h = sig_heading * n_heading
    x[j, 0] += d0e + sig_pos * n_e - h * d0n
    x[j, 1] += d0n + sig_pos * n_n + h * d0e


@nb.njit(cache=True, fastmath=FASTMATH)
def propagate_loose(x, d0e, d0n, noise, sig_pos, sig_heading):
    """Loose filter: move every particle by the navigation displacement plus noise.

    ``noise`` (M, 3): isotropic position noise ``sig_pos`` (columns 0, 1) and a
    cross-track term ``sig_heading * |D0|`` (column 2): the position error that the
    navigation system's heading uncertainty (rad) causes over the interval.
    """
    for j in range(x.shape[0]):
        propagate_loose_particle(x, j, d0e, d0n, noise[j, 0], noise[j, 1], noise[j, 2], sig_pos, sig_heading)


def propagate_loose_numpy(x, d0e, d0n, noise, sig_pos, sig_heading):
    """Plain-numpy reference of :func:`propagate_loose`."""
    h = sig_heading * noise[:, 2:3]
    return x + np.array([d0e, d0n]) + sig_pos * noise[:, :2] + h * np.array([-d0n, d0e])


def position_noise(q: float, r: float, dist_mode: int) -> float:
    """East/north noise per update: Table 2's q, or q combined with the distance noise r."""
    if dist_mode == DIST_PARTICLE:
        return q * r / math.sqrt(q * q + r * r)
    return q

