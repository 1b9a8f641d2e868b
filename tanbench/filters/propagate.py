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
from tanbench.filters.trig import sin_cos
from tanbench.navigation.increments import (D0E, D0N, DPITCH, DROLL, DUP, DYAW, JAXE, JAXN, JAZE,
                                            JAZN, SX, SZ)

from tanbench.options import DISTANCE_INNOVATION

DIST_NONE, DIST_PARTICLE, DIST_NAVIGATION = (DISTANCE_INNOVATION[k] for k in ("none", "particle", "navigation"))


@nb.njit(cache=True, fastmath=FASTMATH)
def propagate_tight(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov):
    """Move particles ``x`` (M, 8) over one interval; fill ``dist_innov`` (M, 2).

    ``sig_pos`` is the east/north noise per update (for ``DIST_PARTICLE`` the caller
    passes the combined q r / sqrt(q^2 + r^2), see :func:`position_noise`).

    ``inc`` is one row of the increments table, ``yaw_nav0`` the navigation yaw at the
    interval start, ``noise`` (M, 6) standard normals for E, N, U, pitch, roll, yaw.
    """
    for j in range(x.shape[0]):
        bx = x[j, BX]
        bz = x[j, BZ]
        s, c = sin_cos(x[j, YAW] - yaw_nav0)
        ue = inc[D0E] + bx * inc[JAXE] - bz * inc[JAZE]
        un = inc[D0N] + bx * inc[JAXN] - bz * inc[JAZN]
        de = c * ue - s * un
        dn = s * ue + c * un
        ee = sig_pos * noise[j, 0]
        en = sig_pos * noise[j, 1]
        x[j, E] += de + ee
        x[j, N] += dn + en
        x[j, U] += inc[DUP] + sig_up * noise[j, 2]
        x[j, PITCH] += inc[DPITCH] + sig_att * noise[j, 3]
        x[j, ROLL] += inc[DROLL] + sig_att * noise[j, 4]
        x[j, YAW] += inc[DYAW] + bx * inc[SX] - bz * inc[SZ] + sig_att * noise[j, 5]
        if dist_mode == DIST_NAVIGATION:
            dist_innov[j, 0] = inc[D0E] - (de + ee)
            dist_innov[j, 1] = inc[D0N] - (dn + en)
        else:
            dist_innov[j, 0] = 0.0
            dist_innov[j, 1] = 0.0


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


@nb.njit(cache=True, fastmath=FASTMATH)
def propagate_loose(x, d0e, d0n, noise, sig_pos, sig_heading):
    """Loose filter: move every particle by the navigation displacement plus noise.

    ``noise`` (M, 3): isotropic position noise ``sig_pos`` (columns 0, 1) and a
    cross-track term ``sig_heading * |D0|`` (column 2): the position error that the
    navigation system's heading uncertainty (rad) causes over the interval.
    """
    for j in range(x.shape[0]):
        h = sig_heading * noise[j, 2]
        x[j, 0] += d0e + sig_pos * noise[j, 0] - h * d0n
        x[j, 1] += d0n + sig_pos * noise[j, 1] + h * d0e


def propagate_loose_numpy(x, d0e, d0n, noise, sig_pos, sig_heading):
    """Plain-numpy reference of :func:`propagate_loose`."""
    h = sig_heading * noise[:, 2:3]
    return x + np.array([d0e, d0n]) + sig_pos * noise[:, :2] + h * np.array([-d0n, d0e])


def position_noise(q: float, r: float, dist_mode: int) -> float:
    """East/north noise per update: Table 2's q, or q combined with the distance noise r."""
    if dist_mode == DIST_PARTICLE:
        return q * r / math.sqrt(q * q + r * r)
    return q

