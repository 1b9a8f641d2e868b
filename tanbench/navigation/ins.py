"""Strapdown navigation at the IMU rate: what the vehicle believes without terrain aiding.

Per sample k (docs/model.md gives the equations and their sources):

* levelling (Eqs. 7-8): pitch = asin(f_y / g), roll = asin(-f_x / (g cos pitch)), with
  f the accelerometer specific force averaged over the last ``window`` samples and,
  if ``compensate``, the kinematic term omega x v_DVL removed first (Eqs. 7-8 hold for
  constant velocity; in a turn the centripetal acceleration would tilt the level);
  g from Eqs. 9-13 at the pressure depth;
* heading: the yaw row of Eq. 1 without bias estimates,
  psi_dot = (-sin(roll) wx + cos(roll) wz) / cos(pitch), with w the gyro rate minus
  Earth and transport rate projected into the body frame by the current attitude;
* dead reckoning: east/north integrate C_b^n (Eq. 5) [vx, vy, 0] (Eq. 6) of the held
  DVL velocity with the trapezoidal rule; up is minus the pressure depth.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.earth import EARTH_RATE, gravity, radii_of_curvature
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy


@nb.njit(cache=True)
def _gravity(g0, r0, up):
    return g0 / (1.0 + up / r0)


# the strapdown loop's inputs: the sensor streams at the IMU samples, the start (east, north,
# yaw), the earth at the latitude (latitude, radii of curvature, gravity and its radius), and
# its outputs pos (n, 3), pitch, roll, yaw (n,)
Streams = namedtuple("Streams", "gyro accel vel_dvl depth")
Start = namedtuple("Start", "e n yaw")
EarthAt = namedtuple("EarthAt", "lat r_n r_e g0 r0")
NavOutputs = namedtuple("NavOutputs", "pos pitch roll yaw")


@nb.njit(cache=True)
def strapdown(dt, streams, start, earth, window, compensate, out):
    """Fill ``out`` (:class:`NavOutputs`) with the navigation solution from the :class:`Streams`."""
    gyro, accel, vel_dvl, depth = streams
    e_start, n_start, yaw_start = start
    lat, r_n, r_e, g0, r0 = earth
    pos, pitch, roll, yaw = out
    n = gyro.shape[0]
    wie_n = EARTH_RATE * math.cos(lat)
    wie_u = EARTH_RATE * math.sin(lat)
    tan_lat = math.tan(lat)
    fsum = np.zeros(3)
    fbuf = np.zeros((window, 3))
    ve_prev = 0.0
    vn_prev = 0.0
    # the previous sample's attitude sines and cosines, carried over (the same values computed again before)
    st_prev = ct_prev = sg_prev = cg_prev = sps_prev = cps_prev = 0.0
    for k in range(n):
        # --- levelling from the (compensated) specific force, moving average
        fx = accel[k, 0]
        fy = accel[k, 1]
        fz = accel[k, 2]
        if compensate:
            wx, wy, wz = gyro[k, 0], gyro[k, 1], gyro[k, 2]
            vx, vy, vz = vel_dvl[k, 0], vel_dvl[k, 1], vel_dvl[k, 2]
            fx -= wy * vz - wz * vy
            fy -= wz * vx - wx * vz
            fz -= wx * vy - wy * vx
        slot = k % window
        fsum[0] += fx - fbuf[slot, 0]
        fsum[1] += fy - fbuf[slot, 1]
        fsum[2] += fz - fbuf[slot, 2]
        fbuf[slot, 0] = fx
        fbuf[slot, 1] = fy
        fbuf[slot, 2] = fz
        count = min(k + 1, window)
        up = -depth[k]
        g = _gravity(g0, r0, up)
        sp = min(1.0, max(-1.0, fsum[1] / count / g))
        th = math.asin(sp)
        ct_k = math.cos(th)
        sr = min(1.0, max(-1.0, -fsum[0] / count / (g * ct_k)))
        ga = math.asin(sr)
        pitch[k] = th
        roll[k] = ga
        # --- heading: integrate the yaw rate of the previous sample interval
        if k == 0:
            yaw[k] = yaw_start
        else:
            ps0 = yaw[k - 1]
            up0 = pos[k - 1, 2]
            w_e = -vn_prev / (r_n + up0)
            w_n = wie_n + ve_prev / (r_e + up0)
            w_u = wie_u + ve_prev * tan_lat / (r_e + up0)
            st, ct = st_prev, ct_prev  # of pitch[k - 1], roll[k - 1], yaw[k - 1]
            sg, cg = sg_prev, cg_prev
            sps, cps = sps_prev, cps_prev
            # omega_in^b = C_n^b omega_in^n = (C_b^n)^T omega_in^n: columns x and z of Eq. 5
            bx = (cg * cps - st * sg * sps) * w_e + (cg * sps + st * sg * cps) * w_n - ct * sg * w_u
            bz = (sg * cps + st * cg * sps) * w_e + (sg * sps - st * cg * cps) * w_n + ct * cg * w_u
            wx = gyro[k - 1, 0] - bx
            wz = gyro[k - 1, 2] - bz
            yaw[k] = ps0 + dt * (-sg * wx + cg * wz) / ct
        # --- dead reckoning with Eq. 5 applied to (vx, vy, 0)
        st, ct = math.sin(th), ct_k
        sg, cg = math.sin(ga), math.cos(ga)
        sps, cps = math.sin(yaw[k]), math.cos(yaw[k])
        st_prev, ct_prev, sg_prev, cg_prev, sps_prev, cps_prev = st, ct, sg, cg, sps, cps
        vx = vel_dvl[k, 0]
        vy = vel_dvl[k, 1]
        ve = (cg * cps - st * sg * sps) * vx - ct * sps * vy
        vn = (cg * sps + st * sg * cps) * vx + ct * cps * vy
        if k == 0:
            pos[k, 0] = e_start
            pos[k, 1] = n_start
        else:
            pos[k, 0] = pos[k - 1, 0] + 0.5 * dt * (ve_prev + ve)
            pos[k, 1] = pos[k - 1, 1] + 0.5 * dt * (vn_prev + vn)
        pos[k, 2] = up
        ve_prev = ve
        vn_prev = vn


def run_strapdown(dt, gyro, accel, vel_dvl, depth, start_en, yaw_start, latitude_rad,
                  window_s=1.0, compensate=True):
    """Navigation solution arrays (pos (n,3), pitch, roll, yaw) from the sensor streams."""
    n = gyro.shape[0]
    r_n, r_e = radii_of_curvature(latitude_rad)
    g0 = gravity(latitude_rad, 0.0)
    r0 = math.sqrt(r_n * r_e)
    window = max(1, int(round(window_s / dt)))
    pos = np.empty((n, 3))
    pitch, roll, yaw = np.empty(n), np.empty(n), np.empty(n)
    streams = Streams(np.ascontiguousarray(gyro), np.ascontiguousarray(accel), np.ascontiguousarray(vel_dvl),
                      np.ascontiguousarray(depth))
    strapdown(dt, streams, Start(float(start_en[0]), float(start_en[1]), float(yaw_start)),
              EarthAt(float(latitude_rad), r_n, r_e, g0, r0), window, bool(compensate), NavOutputs(pos, pitch, roll, yaw))
    return pos, pitch, roll, yaw


def strapdown_numpy(dt, gyro, accel, vel_dvl, depth, start_en, yaw_start, latitude_rad,
                    window_s=1.0, compensate=True):
    """Plain-numpy reference of :func:`run_strapdown` (levelling vectorised, heading looped)."""
    n = gyro.shape[0]
    window = max(1, int(round(window_s / dt)))
    f = accel - np.cross(gyro, vel_dvl) if compensate else accel.copy()
    csum = np.cumsum(np.vstack([np.zeros((1, 3)), f]), axis=0)
    k = np.arange(n)
    lo = np.maximum(0, k + 1 - window)
    fmean = (csum[k + 1] - csum[lo]) / (k + 1 - lo)[:, None]
    up = -np.asarray(depth, dtype=float)
    g = gravity(latitude_rad, up)
    pitch = np.arcsin(np.clip(fmean[:, 1] / g, -1, 1))
    roll = np.arcsin(np.clip(-fmean[:, 0] / (g * np.cos(pitch)), -1, 1))
    r_n, r_e = radii_of_curvature(latitude_rad)
    yaw = np.empty(n)
    pos = np.empty((n, 3))
    yaw[0] = yaw_start
    vb = np.stack([vel_dvl[:, 0], vel_dvl[:, 1], np.zeros(n)], axis=1)
    v_prev = None
    for i in range(n):
        if i > 0:
            ve, vn = v_prev
            w_in = np.array([-vn / (r_n + pos[i - 1, 2]),
                             EARTH_RATE * math.cos(latitude_rad) + ve / (r_e + pos[i - 1, 2]),
                             EARTH_RATE * math.sin(latitude_rad) + ve * math.tan(latitude_rad) / (r_e + pos[i - 1, 2])])
            c = dcm_body_to_nav_numpy(pitch[i - 1], roll[i - 1], yaw[i - 1])
            w = gyro[i - 1] - c.T @ w_in
            yaw[i] = yaw[i - 1] + dt * (-math.sin(roll[i - 1]) * w[0] + math.cos(roll[i - 1]) * w[2]) / math.cos(pitch[i - 1])
        v = dcm_body_to_nav_numpy(pitch[i], roll[i], yaw[i]) @ vb[i]
        if i == 0:
            pos[0, :2] = start_en
        else:
            pos[i, :2] = pos[i - 1, :2] + 0.5 * dt * (np.asarray(v_prev) + v[:2])
        pos[i, 2] = up[i]
        v_prev = (v[0], v[1])
    return pos, pitch, roll, yaw
