"""Beam footprints in the navigation frame, projected once with the navigation attitude.

The estimators that do not carry attitude per hypothesis (loose PF, point-mass filter, EKF,
TERCOM) turn every beam vector a_i r_i into the navigation frame with the navigation
system's attitude; a heading hypothesis delta then turns the horizontal part by Rz(delta)
(C_b^n = Rz(psi) Rx(theta) Ry(gamma), so C(psi + delta) = Rz(delta) C(psi)).
"""

from __future__ import annotations

import numpy as np

from tanbench.vehicle.attitude import dcm_body_to_nav_numpy


def nav_frame_offsets(nav_pitch, nav_roll, nav_yaw, beams, ranges) -> np.ndarray:
    """(K, m, 3) beam vectors times ranges in the navigation frame; NaN rows where no range."""
    c = dcm_body_to_nav_numpy(nav_pitch, nav_roll, nav_yaw)  # (K, 3, 3)
    return np.ascontiguousarray(np.einsum("kij,bj->kbi", c, beams) * ranges[:, :, None])
