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
