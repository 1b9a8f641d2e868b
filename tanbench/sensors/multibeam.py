"""Multibeam echo sounder: a fan of N beams across track, ray-cast on the true seafloor.

The fan lies in the body's across-track plane (x starboard, z up): beam j at angle a_j
from the vertical (starboard positive) points along (sin a_j, 0, -cos a_j), the form
the mission-log format gives as ``beams.multibeam.across_track_deg``
(:func:`fan_vectors` serves both). Two beam patterns (``sensors.multibeam_pattern``):

* ``equiangular``: a_j equally spaced over the swath, -swath/2 .. +swath/2;
* ``equidistant``: tan a_j equally spaced, so that on a flat seafloor the footprints are
  equally spaced across track (the outer beams closer in angle).

A ping is cast as the DVL beams are (:func:`tanbench.sensors.raycast.cast_rays`, the
march and bisection on the bilinear truth) from the true position along each beam
turned by the true attitude. Errors (docs/multibeam.md):

* **pointing**: each beam of each ping is cast along its angle plus a Gaussian error of
  std ``multibeam_angle_noise_deg`` (bottom detection and roll-sensor errors); the
  navigation is never told the error, so a method assumes the nominal fan;
* **range**: Gaussian noise of std ``multibeam_range_noise_m``, drawn as unit normals
  and scaled (cells that differ only in the noise level share their random numbers);
* the world faults of :mod:`tanbench.sensors.faults`: the sound-speed scale error
  scales every range; ``outlier_fraction`` of the ranges are wild (uniform on
  [0, max range], their own stream); the bottom-lock dropouts blank the multibeam ping
  taken at a lost DVL ping too (aeration and altitude blank every sonar: a choice);
* a beam with no bottom within ``max_range_m`` (outer beams over deep water) has no
  range (NaN), as a real sounder reports no detection.

Pings come with every k-th DVL ping (``multibeam_rate_hz`` = ``sonar_rate_hz`` / k), on
the DVL's time base (the mission-log format's single sonar clock); the observations hold
one row per DVL ping, NaN rows where the multibeam did not ping.
"""

from __future__ import annotations

import math
import numba as nb
import numpy as np

from tanbench.arrays import read_only
from tanbench.numpy_stream import standard_normal
from tanbench.sensors.faults import add_outliers
from tanbench.sensors.raycast import cast_rays
from tanbench.vehicle.attitude import dcm_body_to_nav, dcm_body_to_nav_numpy


def fan_angles_deg(beams: int, swath_deg: float, pattern: str = "equiangular") -> np.ndarray:
    """Across-track angles (deg, from the vertical, starboard positive) of a fan of ``beams`` beams
    spanning ``swath_deg``; one beam points straight down."""
    if beams < 1:
        return np.zeros(0)
    if beams == 1:
        return np.zeros(1)
    half = 0.5 * swath_deg
    if pattern == "equiangular":
        return np.linspace(-half, half, beams)
    if pattern == "equidistant":
        t = math.tan(math.radians(half))
        return np.degrees(np.arctan(np.linspace(-t, t, beams)))
    raise ValueError(f"unknown multibeam pattern {pattern!r}")


def fan_vectors(angles_deg) -> np.ndarray:
    """Body-frame (rfu) unit vectors (m, 3) of beams at across-track ``angles_deg``."""
    a = np.radians(np.asarray(angles_deg, dtype=float))
    return np.stack([np.sin(a), np.zeros_like(a), -np.cos(a)], axis=1)


def sensor_fan(sensors) -> tuple[np.ndarray, np.ndarray]:
    """(angles in degrees (N,), body-frame unit vectors (N, 3)) of a ``SensorSpec``'s multibeam."""
    angles = fan_angles_deg(sensors.multibeam_beams, sensors.multibeam_swath_deg, sensors.multibeam_pattern)
    return angles, fan_vectors(angles)


def ping_rows(sensors, pings: int) -> np.ndarray:
    """The DVL ping rows at which the multibeam pings (every k-th, from the first)."""
    k = int(round(sensors.sonar_rate_hz / sensors.multibeam_rate_hz))
    return np.arange(0, pings, max(k, 1))


@nb.njit(cache=True)
def fan_directions(pitch, roll, yaw, angles, out):
    """Navigation-frame unit directions ``out`` (n, m, 3) of across-track beams at ``angles`` (n, m)
    rad, each ping turned by its attitude (pitch, roll, yaw (n,))."""
    c = np.empty((3, 3))
    for k in range(angles.shape[0]):
        dcm_body_to_nav(pitch[k], roll[k], yaw[k], c)
        for j in range(angles.shape[1]):
            bx = math.sin(angles[k, j])
            bz = -math.cos(angles[k, j])
            for a in range(3):
                out[k, j, a] = c[a, 0] * bx + c[a, 2] * bz


def fan_directions_numpy(pitch, roll, yaw, angles) -> np.ndarray:
    """Plain-numpy reference of :func:`fan_directions`."""
    c = dcm_body_to_nav_numpy(np.asarray(pitch), np.asarray(roll), np.asarray(yaw))  # (n, 3, 3)
    b = np.stack([np.sin(angles), np.zeros_like(angles), -np.cos(angles)], axis=-1)  # (n, m, 3)
    return np.einsum("kij,kmj->kmi", c, b)


def swath_ranges(truth_map, pos, pitch, roll, yaw, angles_rad, max_range) -> np.ndarray:
    """Slant ranges (n, m) from ``pos`` (n, 3) along across-track beams at ``angles_rad`` (n, m) to the
    true seafloor; NaN where a beam finds no bottom within ``max_range`` or leaves the map."""
    angles_rad = np.ascontiguousarray(angles_rad, dtype=np.float64)
    n, m = angles_rad.shape
    dirs = np.empty((n, m, 3))
    fan_directions(np.ascontiguousarray(pitch, dtype=np.float64), np.ascontiguousarray(roll, dtype=np.float64),
                   np.ascontiguousarray(yaw, dtype=np.float64), angles_rad, dirs)
    origins = np.ascontiguousarray(np.broadcast_to(np.asarray(pos, dtype=np.float64)[:, None, :], dirs.shape)
                                   .reshape(-1, 3))
    out = np.empty(n * m)
    step = 0.5 * min(truth_map.res_e, truth_map.res_n)
    cast_rays(*truth_map.kernel_args(), read_only(origins), read_only(np.ascontiguousarray(dirs.reshape(-1, 3))),
              float(max_range), step, out)
    return out.reshape(n, m)


def true_swath(truth_map, truth, ping_idx, sensors) -> tuple[np.ndarray, np.ndarray]:
    """(the DVL ping rows of the multibeam pings, their noise-free ranges (pings, N)) along ``truth``
    (at the IMU samples; ``ping_idx`` the DVL pings' samples) with the nominal fan of ``sensors``."""
    rows = ping_rows(sensors, ping_idx.size)
    at = ping_idx[rows]
    angles, _ = sensor_fan(sensors)
    nominal = np.broadcast_to(np.radians(angles), (rows.size, angles.size))
    return rows, swath_ranges(truth_map, truth.pos[at], truth.pitch[at], truth.roll[at], truth.yaw[at], nominal,
                              sensors.max_range_m)


def measure_swath(sensors, faults, truth_map, truth, ping_idx, swath, lost, angle_rng, range_rng,
                  outlier_rng) -> np.ndarray:
    """Measured multibeam ranges (DVL pings, N): a row per DVL ping, NaN rows where the multibeam
    did not ping or the ping was lost (``lost`` (pings,) or None); ``swath`` is :func:`true_swath`'s
    (rows, noise-free ranges); see the module docstring."""
    s, fl = sensors, faults
    rows, nominal_ranges = swath
    angles, _ = sensor_fan(s)
    unit_angle = standard_normal(angle_rng, (rows.size, angles.size))
    if s.multibeam_angle_noise_deg > 0:
        at = ping_idx[rows]
        pointed = np.radians(angles) + math.radians(s.multibeam_angle_noise_deg) * unit_angle
        ranges = swath_ranges(truth_map, truth.pos[at], truth.pitch[at], truth.roll[at], truth.yaw[at], pointed,
                              s.max_range_m)
    else:
        ranges = np.array(nominal_ranges)
    if fl.sound_speed_scale_error:
        ranges = ranges * (1.0 + fl.sound_speed_scale_error)
    ranges = ranges + s.multibeam_range_noise_m * standard_normal(range_rng, ranges.shape)
    ranges = add_outliers(ranges, fl.outlier_fraction, s.max_range_m, outlier_rng)
    out = np.full((ping_idx.size, angles.size), np.nan)
    out[rows] = ranges
    if lost is not None:
        out[lost] = np.nan
    return out
