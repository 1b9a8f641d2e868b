"""Sonar beams: the DVL's four Janus beams and the single-beam altimeter (SBE).

Beam unit vectors are in the body frame (x starboard, y forward, z up). A DVL beam
with tilt t from the vertical and azimuth a (clockwise from forward) points along
(sin t sin a, sin t cos a, -cos t); the altimeter points straight down the body z
axis. Ranges are cast on the *true* seafloor with the *true* attitude, then get
uniform noise of half-width ``noise_m``. The unit uniform draws are scaled by
``noise_m``, so runs that differ only in noise level share their random numbers.
Optionally (``beam_footprint``) a beam of finite width returns its first echo: the
shortest of five rays (axis and four at the half-beamwidth on the cone).
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.arrays import read_only
from tanbench.numpy_stream import uniform
from tanbench.sensors.raycast import cast_rays
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy


def dvl_beam_vectors(tilt_deg: float, azimuths_deg) -> np.ndarray:
    """Body-frame unit vectors (m, 3) of DVL beams."""
    t = math.radians(tilt_deg)
    a = np.radians(np.asarray(azimuths_deg, dtype=float))
    return np.stack([math.sin(t) * np.sin(a), math.sin(t) * np.cos(a), -math.cos(t) * np.ones_like(a)], axis=1)


def altimeter_beam_vectors() -> np.ndarray:
    """Body-frame unit vector (1, 3) of the single-beam altimeter."""
    return np.array([[0.0, 0.0, -1.0]])


def _cone_rays(beams: np.ndarray, half_angle: float) -> np.ndarray:
    """Each beam's axis and four rays on its cone of ``half_angle`` rad: (m, 5, 3)."""
    out = np.empty((beams.shape[0], 5, 3))
    for i, b in enumerate(beams):
        helper = np.array([1.0, 0.0, 0.0]) if abs(b[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        p = np.cross(b, helper)
        p /= np.linalg.norm(p)
        q = np.cross(b, p)
        out[i, 0] = b
        for k, (cp, cq) in enumerate(((1, 0), (0, 1), (-1, 0), (0, -1))):
            v = math.cos(half_angle) * b + math.sin(half_angle) * (cp * p + cq * q)
            out[i, k + 1] = v / np.linalg.norm(v)
    return out


def true_ranges(truth_map, pos, pitch, roll, yaw, beams, beamwidth_deg=0.0, max_range=200.0):
    """Noise-free ranges (n, m) of ``beams`` from poses (n) on the true seafloor; NaN if none."""
    c_bn = dcm_body_to_nav_numpy(pitch, roll, yaw)  # (n, 3, 3)
    rays = _cone_rays(beams, math.radians(beamwidth_deg) / 2.0) if beamwidth_deg > 0 else beams[:, None, :]
    dirs = np.einsum("nij,mrj->nmri", c_bn, rays)  # (n, m, r, 3)
    n, m, r, _ = dirs.shape
    origins = np.broadcast_to(pos[:, None, None, :], dirs.shape).reshape(-1, 3)
    out = np.empty(n * m * r)
    step = 0.5 * min(truth_map.res_e, truth_map.res_n)
    cast_rays(*truth_map.kernel_args(), read_only(np.ascontiguousarray(origins)),
              read_only(np.ascontiguousarray(dirs.reshape(-1, 3))), float(max_range), step, out)
    # first echo in the cone: the shortest ray that hits (a ray that misses does not blank the beam)
    return np.fmin.reduce(out.reshape(n, m, r), axis=2) if r > 1 else out.reshape(n, m)


def measure_ranges(true_range: np.ndarray, noise_m: float, rng) -> np.ndarray:
    """Add uniform noise of half-width ``noise_m`` (common unit draws across noise levels)."""
    return true_range + noise_m * uniform(rng, -1.0, 1.0, true_range.shape)
