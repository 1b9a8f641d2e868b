"""What happened between two filter updates, summarised once for every particle.

The particle filter runs every ``sampling_time`` seconds while the navigation system
runs at 100 Hz. A particle j differs from the navigation system by a heading offset
delta_j and by its own gyro-bias estimates (eps_x, eps_z). Over the interval its
heading is psi_nav(t) + delta_j + eps_x Sx(t) - eps_z Sz(t) (Eq. 1's yaw row, with
Sx = int sin(roll)/cos(pitch) dt and Sz = int cos(roll)/cos(pitch) dt since the
interval start), so its displacement is, to first order in the small bias term,

    d_j = Rz(delta_j) [D0 + eps_x J Ax - eps_z J Az],   J = [[0, -1], [1, 0]],

with D0 the navigation system's displacement and Ax = sum_i Sx(t_i) d_i,
Az = sum_i Sz(t_i) d_i over its 100 Hz steps d_i. These few numbers per interval let
every particle integrate the whole 100 Hz history at the cost of one rotation; the
neglected second-order term is below (eps * T)^2 * |D0| / 2, under a millimetre for
T = 10 s at 55 deg/h.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.arrays import read_only
from tanbench.earth import EARTH_RATE
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

# columns of the increments table
D0E, D0N, JAXE, JAXN, JAZE, JAZN, SX, SZ, DYAW, DPITCH, DROLL, DUP = range(12)
N_INCREMENTS = 12

# the navigation solution at the filter updates (K,) each, ``en`` (K, 2): what the estimators'
# drivers take instead of five arrays
NavAtUpdates = namedtuple("NavAtUpdates", "en up pitch roll yaw")


def nav_at_updates(nav, update_idx) -> NavAtUpdates:
    """The navigation solution ``nav`` (pos, pitch, roll, yaw at the IMU samples) at ``update_idx``."""
    return NavAtUpdates(nav.pos[update_idx, :2], nav.pos[update_idx, 2], nav.pitch[update_idx], nav.roll[update_idx],
                        nav.yaw[update_idx])


@nb.njit(cache=True)
def interval_increments(dt, pos, pitch, roll, yaw, update_idx, out):
    """Fill ``out`` (K, 12) for the K intervals between consecutive ``update_idx`` samples."""
    for m in range(update_idx.shape[0] - 1):
        k0 = update_idx[m]
        k1 = update_idx[m + 1]
        sx = 0.0
        sz = 0.0
        axe = axn = aze = azn = 0.0
        # a sample's sensitivities, computed once and carried to the next step (the same values)
        cp = math.cos(pitch[k0])
        rx1 = math.sin(roll[k0]) / cp
        rz1 = math.cos(roll[k0]) / cp
        for i in range(k0, k1):
            # heading-rate sensitivities, trapezoid over the step; value at the step's middle
            rx0 = rx1
            rz0 = rz1
            cp = math.cos(pitch[i + 1])
            rx1 = math.sin(roll[i + 1]) / cp
            rz1 = math.cos(roll[i + 1]) / cp
            mx = sx + 0.25 * dt * (rx0 + rx1)
            mz = sz + 0.25 * dt * (rz0 + rz1)
            de = pos[i + 1, 0] - pos[i, 0]
            dn = pos[i + 1, 1] - pos[i, 1]
            axe += mx * de
            axn += mx * dn
            aze += mz * de
            azn += mz * dn
            sx += 0.5 * dt * (rx0 + rx1)
            sz += 0.5 * dt * (rz0 + rz1)
        out[m, D0E] = pos[k1, 0] - pos[k0, 0]
        out[m, D0N] = pos[k1, 1] - pos[k0, 1]
        out[m, JAXE] = -axn
        out[m, JAXN] = axe
        out[m, JAZE] = -azn
        out[m, JAZN] = aze
        out[m, SX] = sx
        out[m, SZ] = sz
        out[m, DYAW] = yaw[k1] - yaw[k0]
        out[m, DPITCH] = pitch[k1] - pitch[k0]
        out[m, DROLL] = roll[k1] - roll[k0]
        out[m, DUP] = pos[k1, 2] - pos[k0, 2]


def compute_increments(dt, pos, pitch, roll, yaw, update_idx) -> np.ndarray:
    """The (K, 12) increments table for the intervals between ``update_idx`` samples."""
    update_idx = np.ascontiguousarray(update_idx, dtype=np.int64)
    out = np.empty((max(update_idx.size - 1, 0), N_INCREMENTS))
    interval_increments(dt, *(read_only(np.ascontiguousarray(a)) for a in (pos, pitch, roll, yaw)), read_only(update_idx),
                        out)
    return out


class SharedIncrements:
    """The increments tables of one run's navigation solution, each computed once and shared by
    the run's methods.

    A run's observations carry one (``Observations.shared_increments``, handed on to every
    method's own copy of them); a method asks through its context
    (:meth:`tanbench.methods.api.MethodContext.increments`) and gets a copy of its own. A table
    is remembered only while the navigation arrays cannot change (read-only, as a method's
    views of a run's are), under ``dt``, the updates and the arrays' memory, so a copy of the
    observations with another navigation solution computes its own.
    """

    def __init__(self):
        self._tables: list = []  # (arrays, dt, update_idx, read-only table); the arrays keep their memory alive

    def table(self, dt, nav, update_idx) -> np.ndarray:
        """The table of :func:`compute_increments` for ``nav``'s solution at ``update_idx``: a writeable copy."""
        arrays = (nav.pos, nav.pitch, nav.roll, nav.yaw)
        update_idx = np.ascontiguousarray(update_idx, dtype=np.int64)
        if not all(_frozen(a) for a in arrays):
            return compute_increments(dt, *arrays, update_idx)
        for kept, kept_dt, kept_idx, table in self._tables:
            if (kept_dt == dt and all(_same_memory(a, b) for a, b in zip(arrays, kept))
                    and np.array_equal(kept_idx, update_idx)):
                return table.copy()
        table = compute_increments(dt, *arrays, update_idx)
        table.flags.writeable = False
        self._tables.append((arrays, dt, update_idx.copy(), table))
        return table.copy()


def _memory_owner(arr: np.ndarray) -> np.ndarray | None:
    """The array owning ``arr``'s memory (through views and read-only memoryviews of arrays),
    or None if it is not an array's (a buffer that could change behind a read-only view)."""
    while True:
        base = arr.base
        if base is None:
            return arr
        if isinstance(base, memoryview):
            base = base.obj
        if not isinstance(base, np.ndarray):
            return None
        arr = base


def _frozen(arr) -> bool:
    """Whether ``arr``'s values cannot change: it and the array owning its memory are read-only."""
    if not isinstance(arr, np.ndarray) or arr.flags.writeable:
        return False
    owner = _memory_owner(arr)
    return owner is not None and not owner.flags.writeable


def _same_memory(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two arrays read the same memory the same way (address, shape, strides, type)."""
    return (a.__array_interface__["data"][0] == b.__array_interface__["data"][0] and a.shape == b.shape
            and a.strides == b.strides and a.dtype == b.dtype)


def increments_numpy(dt, pos, pitch, roll, yaw, update_idx) -> np.ndarray:
    """Plain-numpy reference of :func:`compute_increments` (vectorised per interval)."""
    out = np.empty((len(update_idx) - 1, N_INCREMENTS))
    rx = np.sin(roll) / np.cos(pitch)
    rz = np.cos(roll) / np.cos(pitch)
    for m, (k0, k1) in enumerate(zip(update_idx[:-1], update_idx[1:])):
        stepx = 0.5 * dt * (rx[k0:k1] + rx[k0 + 1:k1 + 1])
        stepz = 0.5 * dt * (rz[k0:k1] + rz[k0 + 1:k1 + 1])
        mx = np.concatenate([[0.0], np.cumsum(stepx)[:-1]]) + 0.5 * stepx
        mz = np.concatenate([[0.0], np.cumsum(stepz)[:-1]]) + 0.5 * stepz
        d = np.diff(pos[k0:k1 + 1, :2], axis=0)
        ax = mx @ d
        az = mz @ d
        out[m] = [pos[k1, 0] - pos[k0, 0], pos[k1, 1] - pos[k0, 1], -ax[1], ax[0], -az[1], az[0],
                  stepx.sum(), stepz.sum(), yaw[k1] - yaw[k0], pitch[k1] - pitch[k0],
                  roll[k1] - roll[k0], pos[k1, 2] - pos[k0, 2]]
    return out


# columns of the Euler-step inputs table (Eq. 1 read as one Euler step over the sampling time)
EU_VX, EU_VY, EU_WX, EU_WZ = range(4)
N_EULER = 4


@nb.njit(cache=True)
def euler_inputs(gyro, vel_dvl, pitch, roll, yaw, earth_rate_n, earth_rate_u, update_idx, window, out):
    """Fill ``out`` (K, 4) with the inputs of Eq. 1 for the K intervals between updates.

    For the interval ending at update sample k1: the DVL body velocity (v_x, v_y) and the
    body turn rates w_nb^b x and z (gyro minus the Earth rate projected into the body by
    the navigation attitude; the transport rate, ~0.06 deg/h at 2 m/s, is neglected),
    each averaged over the ``window`` IMU samples before the update (samples
    k1 - window .. k1 - 1; an integrating gyro's sample i is the mean rate over [i, i+1]).
    ``window = 1`` is the single sample at the update.
    """
    for m in range(update_idx.shape[0] - 1):
        k1 = update_idx[m + 1]
        k0 = max(k1 - window, 0)
        vx = vy = wx = wz = 0.0
        for i in range(k0, k1):
            st, ct = math.sin(pitch[i]), math.cos(pitch[i])
            sg, cg = math.sin(roll[i]), math.cos(roll[i])
            sp, cp = math.sin(yaw[i]), math.cos(yaw[i])
            # omega_ie^b = (C_b^n)^T omega_ie^n with omega_ie^n = (0, earth_rate_n, earth_rate_u)
            bx = (cg * sp + st * sg * cp) * earth_rate_n - ct * sg * earth_rate_u
            bz = (sg * sp - st * cg * cp) * earth_rate_n + ct * cg * earth_rate_u
            vx += vel_dvl[i, 0]
            vy += vel_dvl[i, 1]
            wx += gyro[i, 0] - bx
            wz += gyro[i, 2] - bz
        count = max(k1 - k0, 1)
        out[m, EU_VX] = vx / count
        out[m, EU_VY] = vy / count
        out[m, EU_WX] = wx / count
        out[m, EU_WZ] = wz / count


def compute_euler_inputs(gyro, vel_dvl, pitch, roll, yaw, latitude_rad, update_idx, window) -> np.ndarray:
    """The (K, 4) Euler-step inputs table (see :func:`euler_inputs`)."""
    update_idx = np.ascontiguousarray(update_idx, dtype=np.int64)
    out = np.empty((max(update_idx.size - 1, 0), N_EULER))
    euler_inputs(np.ascontiguousarray(gyro), np.ascontiguousarray(vel_dvl), np.ascontiguousarray(pitch),
                 np.ascontiguousarray(roll), np.ascontiguousarray(yaw), EARTH_RATE * math.cos(latitude_rad),
                 EARTH_RATE * math.sin(latitude_rad), update_idx, int(window), out)
    return out


def euler_inputs_numpy(gyro, vel_dvl, pitch, roll, yaw, latitude_rad, update_idx, window) -> np.ndarray:
    """Plain-numpy reference of :func:`compute_euler_inputs`."""
    w_ie = EARTH_RATE * np.array([0.0, math.cos(latitude_rad), math.sin(latitude_rad)])
    c = dcm_body_to_nav_numpy(pitch, roll, yaw)  # (n, 3, 3)
    w_nb = gyro - np.einsum("nji,j->ni", c, w_ie)
    out = np.empty((len(update_idx) - 1, N_EULER))
    for m, k1 in enumerate(update_idx[1:]):
        sl = slice(max(k1 - window, 0), k1)
        out[m] = [vel_dvl[sl, 0].mean(), vel_dvl[sl, 1].mean(), w_nb[sl, 0].mean(), w_nb[sl, 2].mean()]
    return out
