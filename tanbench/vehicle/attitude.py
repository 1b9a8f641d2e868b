"""Attitude conventions of Zhou et al. 2017 (Eq. 5) and their kinematics.

Frames: navigation frame n = east/north/up (ENU); body frame b = x starboard,
y forward, z up. Attitude is (pitch theta, roll gamma, yaw psi) with

    C_b^n = Rz(psi) Rx(theta) Ry(gamma)                                  (Eq. 5)

so psi is measured counter-clockwise from north (psi = +90 deg points west);
the compass heading (clockwise from north) is -psi. Pitch is positive nose up,
roll positive with the starboard side down, as Eq. 5 implies (see docs/model.md).

The Euler-angle rates follow from omega_nb^b = Ry^T [theta_dot,0,0] + [0,gamma_dot,0]
+ Ry^T Rx^T [0,0,psi_dot]; their inverse for the yaw rate is the row used in Eq. 1:
psi_dot = (-sin(gamma) wx + cos(gamma) wz) / cos(theta).
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def dcm_body_to_nav(pitch, roll, yaw, out):
    """Fill the 3x3 ``out`` with C_b^n of Eq. 5."""
    st = np.sin(pitch)
    ct = np.cos(pitch)
    sg = np.sin(roll)
    cg = np.cos(roll)
    sp = np.sin(yaw)
    cp = np.cos(yaw)
    out[0, 0] = cg * cp - st * sg * sp
    out[0, 1] = -ct * sp
    out[0, 2] = sg * cp + st * cg * sp
    out[1, 0] = cg * sp + st * sg * cp
    out[1, 1] = ct * cp
    out[1, 2] = sg * sp - st * cg * cp
    out[2, 0] = -ct * sg
    out[2, 1] = st
    out[2, 2] = ct * cg


def dcm_body_to_nav_numpy(pitch, roll, yaw):
    """Plain-numpy C_b^n (Eq. 5) for scalars or arrays of angles: shape (..., 3, 3).

    Built as the product Rz(yaw) Rx(pitch) Ry(roll), independently of the jitted
    kernel's closed form, so that each checks the other.
    """
    pitch, roll, yaw = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (pitch, roll, yaw)))
    ct, st = np.cos(pitch), np.sin(pitch)
    cg, sg = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(yaw), np.sin(yaw)
    one, zero = np.ones_like(ct), np.zeros_like(ct)
    rz = np.stack([np.stack([cp, -sp, zero], -1), np.stack([sp, cp, zero], -1), np.stack([zero, zero, one], -1)], -2)
    rx = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, ct, -st], -1), np.stack([zero, st, ct], -1)], -2)
    ry = np.stack([np.stack([cg, zero, sg], -1), np.stack([zero, one, zero], -1), np.stack([-sg, zero, cg], -1)], -2)
    return rz @ rx @ ry


def body_rates_from_euler_rates(pitch, roll, pitch_rate, roll_rate, yaw_rate):
    """omega_nb^b (wx, wy, wz) from Euler-angle rates, for the Eq. 5 convention (arrays ok)."""
    cg, sg = np.cos(roll), np.sin(roll)
    ct, st = np.cos(pitch), np.sin(pitch)
    wx = cg * pitch_rate - sg * ct * yaw_rate
    wy = roll_rate + st * yaw_rate
    wz = sg * pitch_rate + cg * ct * yaw_rate
    return wx, wy, wz


def yaw_to_heading_deg(yaw_rad):
    """Compass heading (degrees clockwise from north, in [0, 360)) from Eq. 5 yaw."""
    return np.mod(-np.degrees(yaw_rad), 360.0)


def wrap_pi(angle):
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi
