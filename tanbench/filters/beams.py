"""Beam footprints in the navigation frame, projected once with the navigation attitude.

The estimators that do not carry attitude per hypothesis (point-mass filter, EKF,
TERCOM, and the MPF's per-particle yaw turn) turn every beam vector a_i r_i into the
navigation frame with the navigation system's attitude; a heading hypothesis delta then
turns the horizontal part by Rz(delta) (C_b^n = Rz(psi) Rx(theta) Ry(gamma), so
C(psi + delta) = Rz(delta) C(psi)). Jitted (scalar, fixed summation order): numpy's
vectorised trigonometry and matrix products may round differently with the arrays'
memory alignment, which would break identical results across worker processes.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from tanbench.vehicle.attitude import dcm_body_to_nav, dcm_body_to_nav_numpy


@nb.njit(cache=True)
def project_beams(pitch, roll, yaw, beams, ranges, out):
    """Fill ``out`` (K, m, 3) with C_b^n(k) beams[i] * ranges[k, i] (NaN where no range)."""
    c = np.empty((3, 3))
    for k in range(ranges.shape[0]):
        dcm_body_to_nav(pitch[k], roll[k], yaw[k], c)
        for i in range(beams.shape[0]):
            r = ranges[k, i]
            for a in range(3):
                out[k, i, a] = (c[a, 0] * beams[i, 0] + c[a, 1] * beams[i, 1] + c[a, 2] * beams[i, 2]) * r


def nav_frame_offsets(nav_pitch, nav_roll, nav_yaw, beams, ranges) -> np.ndarray:
    """(K, m, 3) beam vectors times ranges in the navigation frame; NaN rows where no range."""
    ranges = np.ascontiguousarray(ranges, dtype=np.float64)
    out = np.empty(ranges.shape + (3,))
    project_beams(np.ascontiguousarray(nav_pitch, dtype=np.float64), np.ascontiguousarray(nav_roll, dtype=np.float64),
                  np.ascontiguousarray(nav_yaw, dtype=np.float64), np.ascontiguousarray(beams, dtype=np.float64),
                  ranges, out)
    return out


def nav_frame_offsets_numpy(nav_pitch, nav_roll, nav_yaw, beams, ranges) -> np.ndarray:
    """Plain-numpy reference of :func:`nav_frame_offsets`."""
    c = dcm_body_to_nav_numpy(nav_pitch, nav_roll, nav_yaw)  # (K, 3, 3)
    return np.einsum("kij,bj->kbi", c, beams) * ranges[:, :, None]
