"""Earth model: WGS84 radii of curvature, normal gravity and Earth rate.

Gravity follows Zhou et al. 2017, Eqs. 9-13; the radii are the WGS84 meridian (R_N)
and transverse (R_E) radii of curvature. Used by the IMU simulation (what the
sensors feel), by the navigation system (what it compensates) and by the
georeferencing of map files (``terrain/georef.py``: local metric projection of
geographic grids).
"""

from __future__ import annotations

import math

WGS84_A = 6378137.0  # semi-major axis, m
WGS84_E2 = 6.69437999014e-3  # first eccentricity squared
EARTH_RATE = 7.2921151467e-5  # rad/s


def radii_of_curvature(lat_rad: float) -> tuple[float, float]:
    """Meridian and transverse radii of curvature (R_N, R_E), metres (Eqs. 12-13)."""
    s2 = math.sin(lat_rad) ** 2
    w = 1.0 - WGS84_E2 * s2
    r_n = WGS84_A * (1.0 - WGS84_E2) / w**1.5
    r_e = WGS84_A / math.sqrt(w)
    return r_n, r_e


def gravity(lat_rad: float, up_m=0.0):
    """Magnitude of gravity at latitude ``lat_rad`` and height ``up_m`` (Eqs. 9-11), m/s^2.

    ``up_m`` may be an array (heights along a track); the result then is one too.
    """
    g0 = 9.780318 * (1.0 + 5.3024e-3 * math.sin(lat_rad) ** 2 - 5.9e-6 * math.sin(2.0 * lat_rad) ** 2)
    r_n, r_e = radii_of_curvature(lat_rad)
    r0 = math.sqrt(r_n * r_e)
    return g0 / (1.0 + up_m / r0)


def earth_rate_enu(lat_rad: float) -> tuple[float, float, float]:
    """Earth's rotation rate in the local east/north/up frame, rad/s."""
    return (0.0, EARTH_RATE * math.cos(lat_rad), EARTH_RATE * math.sin(lat_rad))
