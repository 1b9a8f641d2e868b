"""Particle propagation (Eq. 1, Algorithm 1 line 4) between filter updates.

Particles are stored a row per state and a column per particle (``x[state, j]``), so each
kernel's loop over particles reads and writes contiguous rows and compiles to SIMD
instructions (no branch, no call inside: ``trig.sin_cos`` is branch free).

Tight: each particle moves by the navigation system's displacement rotated into its own
heading and corrected for its own gyro biases (see ``navigation/increments.py``); its
yaw integrates the gyro rate minus its biases; up, pitch and roll follow the pressure
sensor and the levelled accelerometers, each with its own random-walk noise.

The east/north "distance" innovations of Eqs. 14-18 have three readings (docs/model.md):

* ``DIST_PARTICLE`` (default): the DVL distance rotated through the particle's *own*
  attitude against the particle's predicted displacement. The innovation is then
  minus the particle's position process noise e ~ N(0, q^2), weighted by N(e; 0, r^2):
  exactly the same as drawing e from N(0, q^2 r^2 / (q^2 + r^2)) with no weight term,
  which is how it is implemented (same posterior, no extra weight variance). It never
  pulls the heading anywhere;
* ``DIST_NAVIGATION``: the navigation system's dead-reckoned distance against the
  particle's displacement; this pins every particle to the navigation heading;
* ``DIST_NONE``: no distance innovation (terrain altitude only, Table 2 process noise).

Only ``DIST_NAVIGATION`` leaves a per-particle innovation for the likelihood.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.state import BX, BZ, E, N, PITCH, ROLL, U, YAW
from tanbench.filters.trig import (LEVEL, WOUND, attitude_sin_cos, attitude_wound, sin_cos_about, unwound,
                                   unwound_attitude, unwound_numpy, wound_count)
from tanbench.navigation.increments import (D0E, D0N, DPITCH, DROLL, DUP, DYAW, EU_VX, EU_VY, EU_WX, EU_WZ,
                                            JAXE, JAXN, JAZE, JAZN, SX, SZ)
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

from tanbench.options import DISTANCE_INNOVATION

DIST_NONE, DIST_PARTICLE, DIST_NAVIGATION = (DISTANCE_INNOVATION[k] for k in ("none", "particle", "navigation"))


@nb.njit(cache=True, inline="always")
def _rows(x, lo, n):
    """The eight state rows of particles ``lo .. lo + n - 1`` as 1-D views. The kernels loop over
    such views: indexing the 2-D array with an offset (``x[E, lo + j]``) hides from the compiler
    that the rows do not overlap, and the loop then runs without SIMD (4x slower)."""
    return (x[E, lo:lo + n], x[N, lo:lo + n], x[U, lo:lo + n], x[PITCH, lo:lo + n], x[ROLL, lo:lo + n],
            x[YAW, lo:lo + n], x[BX, lo:lo + n], x[BZ, lo:lo + n])


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _block_views(x, lo, noise, dist_innov):
    """The 1-D views a propagation pass works on: the block's state rows (:func:`_rows`), the
    six noise rows and the two distance-innovation rows."""
    return (_rows(x, lo, noise.shape[1]), (noise[0], noise[1], noise[2], noise[3], noise[4], noise[5]),
            (dist_innov[0], dist_innov[1]))


# what every particle of a propagation pass shares over one interval (:func:`shared_motion`):
# the navigation system's displacement (d0e, d0n), the increments of up, pitch and roll, the
# noise stds of up and of the attitude angles, and whether the distance innovations of
# ``DIST_NAVIGATION`` are kept (``navigation``)
SharedMotion = namedtuple("SharedMotion", "d0e d0n dup dpitch droll sig_up sig_att navigation")


@nb.njit(cache=True, inline="always")
def shared_motion(inc, sig_up, sig_att, dist_mode):
    """The :class:`SharedMotion` of one row ``inc`` of the increments table."""
    return SharedMotion(inc[D0E], inc[D0N], inc[DUP], inc[DPITCH], inc[DROLL], sig_up, sig_att,
                        dist_mode == DIST_NAVIGATION)


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _move_particle(rows, noise, dist, j, de, dn, dyaw, shared):
    """Particle ``j`` of a block (views from :func:`_block_views`) moves by (de, dn) (noise
    included), its yaw by ``dyaw`` plus noise, its up, pitch and roll by the increments of
    ``shared`` (:class:`SharedMotion`) plus noise; the distance innovations of
    ``DIST_NAVIGATION`` go to ``dist``. The two readings of Eq. 1 share it."""
    rows[0][j] += de
    rows[1][j] += dn
    rows[2][j] += shared.dup + shared.sig_up * noise[2][j]
    rows[3][j] += shared.dpitch + shared.sig_att * noise[3][j]
    rows[4][j] += shared.droll + shared.sig_att * noise[4][j]
    rows[5][j] += dyaw + shared.sig_att * noise[5][j]
    if shared.navigation:
        dist[0][j] = shared.d0e - de
        dist[1][j] = shared.d0n - dn


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def propagate_tight(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, yaw_off=0.0, lo=0):
    """Move particles ``x`` (8, M; a row per state, a column per particle) over one interval.

    ``sig_pos`` is the east/north noise per update (for ``DIST_PARTICLE`` the caller
    passes the combined q r / sqrt(q^2 + r^2), see :func:`position_noise`).

    ``inc`` is one row of the increments table, ``yaw_nav0`` the navigation yaw at the
    interval start, ``noise`` (6, M) standard normals for E, N, U, pitch, roll, yaw. Each
    particle's heading offset from the navigation, ``x[YAW] - yaw_nav0``, rotates its
    displacement; its sine and cosine are taken about ``yaw_off`` (rad; the cloud's offset,
    ``trig.sin_cos_about``), which keeps the argument small and does not change the motion.
    For ``DIST_NAVIGATION`` the distance innovations (east, north) go to ``dist_innov`` (2, M).
    The loop has no branch and no call: it compiles to SIMD instructions.

    Only the particles ``lo .. lo + n - 1`` move, ``n`` the columns of ``noise`` (and of
    ``dist_innov``): the filter loops run their particle passes over blocks of the cloud.
    """
    n = noise.shape[1]
    wound = wound_count(x[YAW, lo:lo + n], yaw_nav0, yaw_off)
    if wound == 0:  # the same bits as trig.sin_cos, without the wound angles' hash
        _propagate_tight_near(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, yaw_off, lo)
    else:
        _propagate_tight_wound(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, yaw_off, lo,
                               wound)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _propagate_tight_near(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, yaw_off, lo):
    """:func:`propagate_tight` of heading offsets all within ``trig.WOUND`` (``trig.sin_cos_near``)."""
    s_off, c_off = math.sin(yaw_off), math.cos(yaw_off)
    shared = shared_motion(inc, sig_up, sig_att, dist_mode)
    lever = _lever(inc)
    dyaw, sx, sz = inc[DYAW], inc[SX], inc[SZ]
    rows, nz, dist = _block_views(x, lo, noise, dist_innov)
    e, nn, u, pitch, roll, yaw, bxs, bzs = rows
    n_e, n_n = nz[0], nz[1]
    for j in range(noise.shape[1]):
        bx = bxs[j]
        bz = bzs[j]
        de, dn = _displacement(s_off, c_off, (yaw[j] - yaw_nav0) - yaw_off, bx, bz, lever, sig_pos, n_e[j], n_n[j])
        _move_particle(rows, nz, dist, j, de, dn, dyaw + bx * sx - bz * sz, shared)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _propagate_tight_wound(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, yaw_off, lo,
                           wound):
    """:func:`propagate_tight` of a block with ``wound`` heading offsets beyond ``trig.WOUND`` (or NaN;
    only a filter that lost its heading has them): every particle moves in the near loop, then the
    wound ones' horizontal step, the one part of the motion their heading's sine and cosine enter,
    is taken again from where they started, with the offset unwound (``trig.unwound``: the bits of
    ``trig.sin_cos``). No second SIMD loop to compile."""
    rows, nz, dist = _block_views(x, lo, noise, dist_innov)
    e, nn, yaw, bxs, bzs = rows[0], rows[1], rows[5], rows[6], rows[7]
    which = np.empty(wound, dtype=np.int64)
    start = np.empty((3, wound))  # east, north, yaw before the move
    i = 0
    for j in range(noise.shape[1]):
        if not abs((yaw[j] - yaw_nav0) - yaw_off) <= WOUND:
            which[i] = j
            start[0, i], start[1, i], start[2, i] = e[j], nn[j], yaw[j]
            i += 1
    _propagate_tight_near(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, yaw_off, lo)
    s_off, c_off = math.sin(yaw_off), math.cos(yaw_off)
    shared = shared_motion(inc, sig_up, sig_att, dist_mode)
    lever = _lever(inc)
    for i in range(wound):
        j = which[i]
        de, dn = _displacement(s_off, c_off, unwound((start[2, i] - yaw_nav0) - yaw_off), bxs[j], bzs[j], lever,
                               sig_pos, nz[0][j], nz[1][j])
        e[j] = start[0, i] + de
        nn[j] = start[1, i] + dn
        if shared.navigation:  # as _move_particle
            dist[0][j] = shared.d0e - de
            dist[1][j] = shared.d0n - dn


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def dead_reckon(x, inc, yaw_nav0):
    """:func:`propagate_tight` of one particle (``x`` (8, 1)) without noise or distance
    innovations (``DIST_NONE``): the loose loops' corrected navigation, with the same bits, compiled
    without the SIMD pass and its wound-angle twin (the offset unwound, ``trig.unwound``)."""
    zero = np.zeros((6, 1))
    rows, nz, dist = _block_views(x, 0, zero, zero[:2])
    bx, bz = rows[6][0], rows[7][0]
    de, dn = _displacement(0.0, 1.0, unwound(rows[5][0] - yaw_nav0), bx, bz, _lever(inc), 0.0, nz[0][0], nz[1][0])
    _move_particle(rows, nz, dist, 0, de, dn, inc[DYAW] + bx * inc[SX] - bz * inc[SZ],
                   shared_motion(inc, 0.0, 0.0, DIST_NONE))


def dead_reckon_numpy(x, inc, yaw_nav0):
    """Plain-numpy reference of :func:`dead_reckon` (returns a new array of ``x``'s shape, (8, 1)): the
    navigation displacement corrected for the gyro biases and rotated by the heading offset
    ``x[YAW] - yaw_nav0`` (a wound offset replaced as ``trig.sin_cos`` replaces it,
    :func:`~tanbench.filters.trig.unwound_numpy`), yaw by the bias-corrected heading increment, up,
    pitch and roll by their increments; no noise."""
    x = np.array(x, dtype=np.float64)
    bx, bz = x[BX], x[BZ]
    with np.errstate(invalid="ignore"):  # sin and cos of an infinite offset: NaN, as the kernel's
        delta = unwound_numpy(x[YAW] - yaw_nav0)
        s, c = np.sin(delta), np.cos(delta)
    ue = inc[D0E] + bx * inc[JAXE] - bz * inc[JAZE]
    un = inc[D0N] + bx * inc[JAXN] - bz * inc[JAZN]
    x[E] += c * ue - s * un
    x[N] += s * ue + c * un
    x[U] += inc[DUP]
    x[PITCH] += inc[DPITCH]
    x[ROLL] += inc[DROLL]
    x[YAW] += inc[DYAW] + bx * inc[SX] - bz * inc[SZ]
    return x


@nb.njit(cache=True, inline="always")
def _lever(inc):
    """The navigation displacement and its gyro-bias lever terms of one increments row:
    (d0e, d0n, jaxe, jaxn, jaze, jazn) (``navigation.increments``)."""
    return inc[D0E], inc[D0N], inc[JAXE], inc[JAXN], inc[JAZE], inc[JAZN]


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _displacement(s_off, c_off, d, bx, bz, lever, sig_pos, n_e, n_n):
    """A particle's east/north step: the navigation displacement (``lever``, :func:`_lever`)
    corrected for its gyro biases ``bx``, ``bz``, rotated by its heading offset ``d`` (within
    ``trig.WOUND``) about the reference whose sine and cosine are ``s_off``, ``c_off``
    (``trig.sin_cos_about``), plus ``sig_pos`` times its noise ``n_e``, ``n_n``."""
    d0e, d0n, jaxe, jaxn, jaze, jazn = lever
    s, c = sin_cos_about(s_off, c_off, d)
    ue = d0e + bx * jaxe - bz * jaze
    un = d0n + bx * jaxn - bz * jazn
    return c * ue - s * un + sig_pos * n_e, s * ue + c * un + sig_pos * n_n


def propagate_tight_numpy(x, inc, yaw_nav0, noise, sig_pos, sig_up, sig_att, dist_mode):
    """Plain-numpy reference of :func:`propagate_tight`: returns (new x, dist_innov (2, M), zero
    unless ``DIST_NAVIGATION``)."""
    x = x.copy()
    bx, bz = x[BX], x[BZ]
    delta = x[YAW] - yaw_nav0
    ue = inc[D0E] + bx * inc[JAXE] - bz * inc[JAZE]
    un = inc[D0N] + bx * inc[JAXN] - bz * inc[JAZN]
    d = np.stack([np.cos(delta) * ue - np.sin(delta) * un, np.sin(delta) * ue + np.cos(delta) * un])
    d = d + sig_pos * noise[:2]
    yaw_inc = inc[DYAW] + bx * inc[SX] - bz * inc[SZ]
    x[[E, N]] += d
    x[U] += inc[DUP] + sig_up * noise[2]
    x[PITCH] += inc[DPITCH] + sig_att * noise[3]
    x[ROLL] += inc[DROLL] + sig_att * noise[4]
    x[YAW] += yaw_inc + sig_att * noise[5]
    if dist_mode == DIST_NAVIGATION:
        innov = np.array([[inc[D0E]], [inc[D0N]]]) - d
    else:
        innov = np.zeros_like(d)
    return x, innov


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def propagate_tight_euler(x, u, dt, inc, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, att=LEVEL, lo=0):
    """Eq. 1 read as one Euler step of length ``dt`` (the sampling time), Algorithm 1 line 4.

    ``u`` = (v_x, v_y, w_x, w_z): the DVL body velocity and body turn rates
    (``navigation.increments.euler_inputs``), held over the interval. Each particle moves
    by ``[1 0 0; 0 1 0] C_b^n(Theta_j) [v_x, v_y, 0] dt`` with its own attitude at the
    interval start, and its yaw by ``(-sin g_j (w_x - eps_x,j) + cos g_j (w_z - eps_z,j)) /
    cos th_j * dt``; up, pitch and roll follow the navigation system (``inc``: Eq. 1's 0_3,
    as in :func:`propagate_tight`). Noise and distance innovations as there; the
    navigation distance of ``DIST_NAVIGATION`` is the navigation system's displacement.
    ``att`` (``trig.attitude_reference``; ``LEVEL``, the level attitude heading north, if not
    given) only centres the trigonometry (``trig.attitude_sin_cos``): the navigation attitude at
    the interval start, or the cloud's; it does not change the motion. Particles
    ``lo .. lo + n - 1`` move, as in :func:`propagate_tight`.
    """
    n = noise.shape[1]
    pitch, roll, yaw = x[PITCH, lo:lo + n], x[ROLL, lo:lo + n], x[YAW, lo:lo + n]
    if attitude_wound(pitch, roll, yaw, att) == 0:  # the trigonometry's offsets from the state rows
        _euler_loop(x, u, dt, inc, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, (pitch, roll, yaw, att), lo)
    else:  # wound angles (rare): from their offsets, unwound (the bits of trig.sin_cos)
        _euler_loop(x, u, dt, inc, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov,
                    unwound_attitude(pitch, roll, yaw, att), lo)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _euler_loop(x, u, dt, inc, noise, sig_pos, sig_up, sig_att, dist_mode, dist_innov, angles, lo):
    """:func:`propagate_tight_euler`'s pass; the particles' sines and cosines from ``angles`` =
    (pitch, roll, yaw rows, reference), as ``trig.attitude_sin_cos`` takes them."""
    p, r, y, att = angles
    vx, vy, wx, wz = u[EU_VX] * dt, u[EU_VY] * dt, u[EU_WX], u[EU_WZ]
    shared = shared_motion(inc, sig_up, sig_att, dist_mode)
    rows, nz, dist = _block_views(x, lo, noise, dist_innov)
    e, nn, u, pitch, roll, yaw, bxs, bzs = rows
    n_e, n_n = nz[0], nz[1]
    for j in range(noise.shape[1]):
        st, ct, sg, cg, sp, cp = attitude_sin_cos(p[j], r[j], y[j], att)
        de = (cg * cp - st * sg * sp) * vx - ct * sp * vy + sig_pos * n_e[j]
        dn = (cg * sp + st * sg * cp) * vx + ct * cp * vy + sig_pos * n_n[j]
        yaw_rate = (-sg * (wx - bxs[j]) + cg * (wz - bzs[j])) / ct
        _move_particle(rows, nz, dist, j, de, dn, yaw_rate * dt, shared)


def propagate_tight_euler_numpy(x, u, dt, inc, noise, sig_pos, sig_up, sig_att, dist_mode):
    """Plain-numpy reference of :func:`propagate_tight_euler`: returns (new x, dist_innov (2, M))."""
    x = x.copy()
    c = dcm_body_to_nav_numpy(x[PITCH], x[ROLL], x[YAW])  # (M, 3, 3)
    d = (c @ np.array([u[EU_VX], u[EU_VY], 0.0]))[:, :2].T * dt + sig_pos * noise[:2]
    yaw_rate = (-np.sin(x[ROLL]) * (u[EU_WX] - x[BX]) + np.cos(x[ROLL]) * (u[EU_WZ] - x[BZ])) / np.cos(x[PITCH])
    x[[E, N]] += d
    x[U] += inc[DUP] + sig_up * noise[2]
    x[PITCH] += inc[DPITCH] + sig_att * noise[3]
    x[ROLL] += inc[DROLL] + sig_att * noise[4]
    x[YAW] += yaw_rate * dt + sig_att * noise[5]
    innov = np.array([[inc[D0E]], [inc[D0N]]]) - d if dist_mode == DIST_NAVIGATION else np.zeros_like(d)
    return x, innov


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def propagate_loose(x, d0e, d0n, noise, sig_pos, sig_heading, lo=0):
    """Loose filter: move every particle (``x`` (2, M)) by the navigation displacement plus noise.

    ``noise`` (3, M): isotropic position noise ``sig_pos`` (rows 0, 1) and a cross-track
    term ``sig_heading * |D0|`` (row 2): the position error that the navigation system's
    heading uncertainty (rad) causes over the interval. Particles ``lo .. lo + n - 1`` move, as in
    :func:`propagate_tight`.
    """
    n = noise.shape[1]
    e = x[0, lo:lo + n]
    nn = x[1, lo:lo + n]
    n_e, n_n, n_h = noise[0], noise[1], noise[2]
    for j in range(n):
        h = sig_heading * n_h[j]
        e[j] += d0e + sig_pos * n_e[j] - h * d0n
        nn[j] += d0n + sig_pos * n_n[j] + h * d0e


def propagate_loose_numpy(x, d0e, d0n, noise, sig_pos, sig_heading):
    """Plain-numpy reference of :func:`propagate_loose`."""
    h = sig_heading * noise[2]
    return x + np.array([[d0e], [d0n]]) + sig_pos * noise[:2] + h * np.array([[-d0n], [d0e]])
