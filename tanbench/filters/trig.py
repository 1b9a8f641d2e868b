"""Sine and cosine for the particle loops, branch free so that the loops vectorise.

``sin_cos(d)`` reduces d by multiples of pi/2 (Cody-Waite, two-part pi/2: accurate for
|d| up to ``WOUND`` = 1e5 rad, far beyond any angle offset of a working filter; a wound-up
angle beyond it is replaced by a pseudo-random one, :func:`wound_angle`) and evaluates fdlibm's minimax
polynomials for sine and cosine on [-pi/4, pi/4] (k_sin.c, k_cos.c); the quadrant is
applied by selects, not branches. Accurate to about 1 ulp (the tests compare with numpy's
``sin`` and ``cos``, its plain-numpy reference). A loop over particles that calls it has
no call and no branch left, and compiles to SIMD instructions.

The particles' angles are taken as a reference plus an offset: ``sin_cos_about`` rotates
the reference's sine and cosine (computed once per update) by the offset's, which is
exact up to rounding, and keeps the argument of ``sin_cos`` small.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.vecmath import exact_float_53, float_bits

TWO_OVER_PI = 6.36619772367581382433e-01
PIO2_HI = 1.57079632673412561417e+00  # the first 33 bits of pi/2
PIO2_LO = 6.07710050650619224932e-11  # pi/2 - PIO2_HI
ROUND = 6755399441055744.0  # 1.5 * 2^52: adding and subtracting it rounds to the nearest integer
WOUND = 1.0e5  # rad: beyond, sin_cos takes the angle as wound (wound_angle)
HASH_MULTIPLIER = np.int64(-7046029254386353131)  # 0x9E3779B97F4A7C15, 2^64 / golden ratio, as int64
FRACTION_MASK = np.int64((1 << 53) - 1)
TURN_PER_2_53 = 2.0 * math.pi / 9007199254740992.0
S1, S2, S3 = -1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04
S4, S5, S6 = 2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10
C1, C2, C3 = 4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05
C4, C5, C6 = -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11


@nb.njit(cache=True, inline="always")
def wound_angle(d):
    """An angle in [-pi, pi) standing for an angle ``d`` wound beyond ``WOUND``: the top 53 bits
    of d's bits times a 64-bit odd constant (Fibonacci hashing), as a fraction of a turn.

    Such an angle has lost every bit below its units in the last place (ulp(1e5) is 1.5e-11
    rad, ulp(1e9) 1.2e-7 rad, ulp(1e16) 2 rad): its value modulo 2 pi is no longer a
    measurement but a function of rounding, as arbitrary as any other. The C library's exact
    reduction and this hash both give an angle that the rest of the cloud does not predict;
    this one costs a multiply and keeps the loop vectorised. It only appears in filters that
    have lost the heading (range-scaled roughening lets the heading spread grow without bound).
    """
    h = float_bits(d) * HASH_MULTIPLIER
    return exact_float_53((h >> 11) & FRACTION_MASK) * TURN_PER_2_53 - math.pi


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def sin_cos(d):
    """(sin d, cos d), branch free: to about 1 ulp for |d| <= ``WOUND``; beyond, the sine
    and cosine of a pseudo-random angle fixed by d's bits (:func:`wound_angle`); NaN for
    NaN or infinite d."""
    nonfinite = d - d  # 0, or NaN for NaN and +-inf
    return _sin_cos_reduced(d if abs(d) <= WOUND else wound_angle(d), nonfinite)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def sin_cos_near(d):
    """:func:`sin_cos` of an angle known to be within ``WOUND`` (the same bits): the loops call it
    when :func:`wound_count` found no wound angle in their block, and spare the wound angle's
    hash, which costs as much as the rest of the polynomial in a SIMD loop."""
    return _sin_cos_reduced(d, d - d)


@nb.njit(cache=True, error_model="numpy")
def wound_count(row, a, b):
    """How many ``(row[j] - a) - b`` are beyond ``WOUND`` (or NaN): angles :func:`sin_cos_near` does
    not take."""
    count = 0
    for j in range(row.shape[0]):
        count += 0 if abs((row[j] - a) - b) <= WOUND else 1
    return count


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _sin_cos_reduced(d, nonfinite):
    """:func:`sin_cos` of ``d`` within ``WOUND``; ``nonfinite`` is added to both (0, or NaN)."""
    qf = (d * TWO_OVER_PI + ROUND) - ROUND  # the nearest multiple of pi/2
    r = (d - qf * PIO2_HI) - qf * PIO2_LO  # in [-pi/4, pi/4]
    q = np.int32(qf)
    z = r * r
    s = r + r * z * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))))
    c = 1.0 - 0.5 * z + z * z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))))
    odd = (q & 1) != 0
    sq = c if odd else s
    cq = s if odd else c
    sq = -sq if (q & 2) != 0 else sq
    cq = -cq if ((q + 1) & 2) != 0 else cq
    return sq + nonfinite, cq + nonfinite


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def sin_cos_about(s_ref, c_ref, d):
    """(sin(ref + d), cos(ref + d)) from sin/cos of the reference angle, for an offset ``d`` within
    ``WOUND`` (:func:`sin_cos_near`; a loop whose block has wound offsets unwinds them first,
    :func:`unwound`, which gives :func:`sin_cos`'s bits). Only the near form is compiled into the
    loops: numba inlines an ``inline="always"`` function by copying its IR, both branches of a
    choice included, at every call site."""
    s, c = sin_cos_near(d)
    return s_ref * c + c_ref * s, c_ref * c - s_ref * s


@nb.njit(cache=True, inline="always")
def attitude_reference(ref_pitch, ref_roll, ref_yaw):
    """A reference attitude and its sines and cosines, as :func:`attitude_sin_cos` takes it."""
    return (ref_pitch, math.sin(ref_pitch), math.cos(ref_pitch), ref_roll, math.sin(ref_roll), math.cos(ref_roll),
            ref_yaw, math.sin(ref_yaw), math.cos(ref_yaw))


# attitude_reference(0, 0, 0), the level attitude heading north: each angle with its sine and cosine
LEVEL = (0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0)


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def attitude_sin_cos(pitch, roll, yaw, att):
    """(sin, cos) of a particle's pitch, roll and yaw, each as the reference ``att``
    (:func:`attitude_reference`) plus an offset within ``WOUND`` (:func:`sin_cos_about`; rows with
    wound offsets go through :func:`unwound_attitude` first)."""
    ref_pitch, s_pitch, c_pitch, ref_roll, s_roll, c_roll, ref_yaw, s_yaw, c_yaw = att
    st, ct = sin_cos_about(s_pitch, c_pitch, pitch - ref_pitch)
    sg, cg = sin_cos_about(s_roll, c_roll, roll - ref_roll)
    sp, cp = sin_cos_about(s_yaw, c_yaw, yaw - ref_yaw)
    return st, ct, sg, cg, sp, cp


@nb.njit(cache=True)
def attitude_wound(pitch, roll, yaw, att):
    """How many of the attitude offsets of rows ``pitch``, ``roll``, ``yaw`` from ``att`` are
    beyond ``WOUND`` (:func:`wound_count`): 0 lets a loop take :func:`sin_cos_near`."""
    return wound_count(pitch, att[0], 0.0) + wound_count(roll, att[3], 0.0) + wound_count(yaw, att[6], 0.0)


@nb.njit(cache=True, error_model="numpy")
def unwound(d):
    """``d``, or, for a finite ``d`` beyond ``WOUND``, the angle :func:`sin_cos` takes for it
    (:func:`wound_angle`): ``sin_cos_near(unwound(d))`` is ``sin_cos(d)`` bit for bit (NaN and
    infinities stay, and give NaN)."""
    return wound_angle(d) if abs(d) > WOUND and d - d == 0.0 else d


def wound_angle_numpy(d):
    """Plain-numpy reference of :func:`wound_angle`, element by element (an array of ``d``'s shape): the
    int64 product of d's bits and the constant wraps modulo 2^64, as the kernel's does."""
    d = np.asarray(d, dtype=np.float64)
    bits = np.atleast_1d(d).view(np.int64)
    h = bits * HASH_MULTIPLIER  # an array product: wraps without a warning
    return (((h >> 11) & FRACTION_MASK).astype(np.float64) * TURN_PER_2_53 - math.pi).reshape(d.shape)


def unwound_numpy(d):
    """Plain-numpy reference of :func:`unwound`, element by element (an array of ``d``'s shape)."""
    d = np.asarray(d, dtype=np.float64)
    return np.where((np.abs(d) > WOUND) & np.isfinite(d), wound_angle_numpy(d), d)


@nb.njit(cache=True, error_model="numpy")
def unwound_offsets(row, ref, out):
    """``out[j] = unwound(row[j] - ref)`` (:func:`unwound`)."""
    for j in range(row.shape[0]):
        out[j] = unwound(row[j] - ref)


@nb.njit(cache=True)
def unwound_attitude(pitch, roll, yaw, att):
    """The rows ``pitch``, ``roll``, ``yaw`` as offsets from the reference ``att``, unwound
    (:func:`unwound_offsets`), and ``att`` with its angles zero and its sines and cosines kept:
    ``attitude_sin_cos(p[j], r[j], y[j], att0)`` is then :func:`sin_cos` of each offset from
    ``att``, rotated, bit for bit, wound angles included. A block with wound angles (rare: a filter
    that lost its heading) thus runs the same loop as the others."""
    n = pitch.shape[0]
    p, r, y = np.empty(n), np.empty(n), np.empty(n)
    unwound_offsets(pitch, att[0], p)
    unwound_offsets(roll, att[3], r)
    unwound_offsets(yaw, att[6], y)
    return p, r, y, (0.0, att[1], att[2], 0.0, att[4], att[5], 0.0, att[7], att[8])
