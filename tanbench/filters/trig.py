"""Sine and cosine of the small angles the particle kernels meet most of the time.

Particles differ from the navigation system by small attitude offsets once a filter has
converged. ``sin_cos(d)`` evaluates a Taylor polynomial for |d| <= 0.2 rad (error below
2e-12, far below anything that matters here) and falls back to ``math.sin``/``math.cos``
otherwise; ``sin_cos_about(s_ref, c_ref, d)`` gives sin/cos of (ref + d) from the
reference angle's sine and cosine. This removes most trigonometric calls from the
per-particle loops.
"""

from __future__ import annotations

import math

import numba as nb

from tanbench.filters.state import PITCH, ROLL, YAW

SMALL = 0.2


@nb.njit(cache=True, inline="always")
def sin_cos(d):
    """(sin d, cos d)."""
    if -SMALL <= d <= SMALL:
        d2 = d * d
        s = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0 * (1.0 - d2 / 72.0))))
        c = 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0 * (1.0 - d2 / 56.0 * (1.0 - d2 / 90.0))))
        return s, c
    return math.sin(d), math.cos(d)


@nb.njit(cache=True, inline="always")
def sin_cos_about(s_ref, c_ref, d):
    """(sin(ref + d), cos(ref + d)) from sin/cos of the reference angle."""
    s, c = sin_cos(d)
    return s_ref * c + c_ref * s, c_ref * c - s_ref * s


@nb.njit(cache=True, inline="always")
def attitude_reference(ref_pitch, ref_roll, ref_yaw):
    """A reference attitude and its sines and cosines, as :func:`particle_sin_cos` takes it."""
    return (ref_pitch, math.sin(ref_pitch), math.cos(ref_pitch), ref_roll, math.sin(ref_roll), math.cos(ref_roll),
            ref_yaw, math.sin(ref_yaw), math.cos(ref_yaw))


@nb.njit(cache=True, inline="always")
def particle_sin_cos(x, j, att):
    """(sin, cos) of particle ``j``'s pitch, roll and yaw, each as the reference ``att``
    (:func:`attitude_reference`) plus an offset: the short series when the particle is near it."""
    ref_pitch, s_pitch, c_pitch, ref_roll, s_roll, c_roll, ref_yaw, s_yaw, c_yaw = att
    st, ct = sin_cos_about(s_pitch, c_pitch, x[j, PITCH] - ref_pitch)
    sg, cg = sin_cos_about(s_roll, c_roll, x[j, ROLL] - ref_roll)
    sp, cp = sin_cos_about(s_yaw, c_yaw, x[j, YAW] - ref_yaw)
    return st, ct, sg, cg, sp, cp
