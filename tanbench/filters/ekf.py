"""Iterated extended Kalman filter with local terrain linearisation (SITAN; Hostetler & Andreas 1983).

State x = [E, N, delta, eps_z] in the map frame: the horizontal
position, the heading offset from the navigation heading (yaw = nav yaw + delta) and the
z-gyro bias (rad/s). Between updates (the navigation increments, ``navigation/increments.py``)

    p  <- p + Rz(delta) D0,        delta <- delta - S_z eps_z + w_psi,     eps_z <- eps_z,

with the Jacobian d(Rz(delta) D0)/d delta = Rz'(delta) D0; the process noise is Table 2's
velocity noise on position and the heading random walk on delta.

Each beam's terrain-altitude innovation nu_i = U + o_up,i - h(p + Rz(delta) o_i) (beams
projected with the navigation attitude, ``beams.py``) is linearised about the current
iterate with the map's slope. As in SITAN's stochastic linearisation the slope is a
central difference over the larger of the map spacing and the current position std, so
a wide prior sees the terrain's trend rather than one cell's; the terrain's departure
from that plane (the second difference) is added to the beam's measurement variance.
The iterated update is Gauss-Newton on the MAP cost (``iterations`` passes); an update
whose normalised innovation exceeds the ``gate`` chi^2 is rejected (no terrain fix that
far from the linearisation).

This is the textbook baseline: it converges when started close (within about one
correlation length of the relief) and fails from a large initial error, where the
terrain is far from linear over the prior; tanbench reports both regimes.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters.beams import nav_frame_offsets
from tanbench.navigation.increments import D0E, D0N, SZ
from tanbench.terrain.grid import MapArgs, bilinear, bilinear_numpy

NX = 4


@nb.njit(cache=True)
def terrain_slope(z, e0, n0, inv_re, inv_rn, e, n, step):
    """(h, dh/de, dh/dn, curvature residual) at (e, n): central differences over ``step`` metres.

    The residual is the RMS departure of the four neighbours from the fitted plane
    (half the second differences); NaN where any of the five points is off the map.
    """
    h = bilinear(z, e0, n0, inv_re, inv_rn, e, n)
    he1 = bilinear(z, e0, n0, inv_re, inv_rn, e + step, n)
    he0 = bilinear(z, e0, n0, inv_re, inv_rn, e - step, n)
    hn1 = bilinear(z, e0, n0, inv_re, inv_rn, e, n + step)
    hn0 = bilinear(z, e0, n0, inv_re, inv_rn, e, n - step)
    ge = (he1 - he0) / (2.0 * step)
    gn = (hn1 - hn0) / (2.0 * step)
    ce = 0.5 * (he1 + he0 - 2.0 * h)
    cn = 0.5 * (hn1 + hn0 - 2.0 * h)
    return h, ge, gn, math.sqrt(0.5 * (ce * ce + cn * cn))


def terrain_slope_numpy(z, e0, n0, inv_re, inv_rn, e, n, step):
    pts = np.array([[e, n], [e + step, n], [e - step, n], [e, n + step], [e, n - step]])
    h, he1, he0, hn1, hn0 = bilinear_numpy(z, e0, n0, inv_re, inv_rn, pts[:, 0], pts[:, 1])
    ce = 0.5 * (he1 + he0 - 2 * h)
    cn = 0.5 * (hn1 + hn0 - 2 * h)
    return h, (he1 - he0) / (2 * step), (hn1 - hn0) / (2 * step), math.sqrt(0.5 * (ce**2 + cn**2))


@nb.njit(cache=True)
def ekf_predict(x, p, d0e, d0n, s_z, q_pos, q_delta, q_bias):
    """Propagate mean ``x`` (4,) and covariance ``p`` (4, 4) in place over one interval."""
    c = math.cos(x[2])
    s = math.sin(x[2])
    f = np.eye(NX)
    f[0, 2] = -s * d0e - c * d0n
    f[1, 2] = c * d0e - s * d0n
    f[2, 3] = -s_z
    x[0] += c * d0e - s * d0n
    x[1] += s * d0e + c * d0n
    x[2] -= s_z * x[3]
    pn = f @ p @ f.T
    pn[0, 0] += q_pos
    pn[1, 1] += q_pos
    pn[2, 2] += q_delta
    pn[3, 3] += q_bias
    p[:, :] = 0.5 * (pn + pn.T)


def ekf_predict_numpy(x, p, d0e, d0n, s_z, q_pos, q_delta, q_bias):
    c, s = math.cos(x[2]), math.sin(x[2])
    rot = np.array([[c, -s], [s, c]])
    drot = np.array([[-s, -c], [c, -s]])
    xn = x.copy()
    xn[:2] += rot @ [d0e, d0n]
    xn[2] -= s_z * x[3]
    f = np.eye(4)
    f[:2, 2] = drot @ [d0e, d0n]
    f[2, 3] = -s_z
    return xn, f @ p @ f.T + np.diag([q_pos, q_pos, q_delta, q_bias])


@nb.njit(cache=True)
def beam_linearisation(xi, offsets_k, up, zmap, step, sig_u, hmat, resid, rvar):
    """Innovations ``resid`` (m,), Jacobian rows ``hmat`` (m, 4) and variances ``rvar`` (m,) of the beams
    at iterate ``xi``, on the map ``zmap`` (its ``MapArgs``); returns the number of usable beams
    (others get a zero row and unit variance)."""
    z, e0, n0, inv_re, inv_rn = zmap
    c = math.cos(xi[2])
    s = math.sin(xi[2])
    used = 0
    for i in range(offsets_k.shape[0]):
        oe = offsets_k[i, 0]
        on = offsets_k[i, 1]
        hmat[i, :] = 0.0
        resid[i] = 0.0
        rvar[i] = 1.0
        if offsets_k[i, 2] != offsets_k[i, 2]:
            continue
        qe = xi[0] + c * oe - s * on
        qn = xi[1] + s * oe + c * on
        h, ge, gn, curv = terrain_slope(z, e0, n0, inv_re, inv_rn, qe, qn, step)
        if not (h == h and ge == ge and gn == gn):
            continue
        used += 1
        # nu = U + o_up - h(q); d nu / dx = -grad h . dq/dx
        hmat[i, 0] = -ge
        hmat[i, 1] = -gn
        hmat[i, 2] = -(ge * (-s * oe - c * on) + gn * (c * oe - s * on))
        resid[i] = up + offsets_k[i, 2] - h
        rvar[i] = sig_u * sig_u + curv * curv
    return used


@nb.njit(cache=True)
def iekf_update(x, p, offsets_k, up, zmap, res, sig_u, iterations, gate):
    """Iterated EKF update of ``x``, ``p`` in place, on the map ``zmap`` (its ``MapArgs``); returns
    (normalised innovation squared, beams used) or (-1, 0) when no beam is usable, (NIS, m) with
    nothing changed when NIS exceeds ``gate``."""
    _, _, _, inv_re, inv_rn = zmap
    m = offsets_k.shape[0]
    hmat = np.empty((m, NX))
    resid = np.empty(m)
    rvar = np.empty(m)
    x0 = x.copy()
    xi = x.copy()
    step = max(1.0 / min(inv_re, inv_rn), math.sqrt(max(p[0, 0], p[1, 1])))
    step = max(step, res)
    nis = -1.0
    used = 0
    gain = np.zeros((NX, m))
    for it in range(iterations):
        used = beam_linearisation(xi, offsets_k, up, zmap, step, sig_u, hmat, resid, rvar)
        if used == 0:
            return -1.0, 0
        s_mat = hmat @ p @ hmat.T
        for i in range(m):
            s_mat[i, i] += rvar[i]
        # Gauss-Newton: innovation about the prior mean, linearised at xi
        v = resid + hmat @ (x0 - xi)
        sinv = np.linalg.inv(s_mat)
        if it == 0:
            nis = v @ sinv @ v
            if nis > gate:
                return nis, used
        gain = p @ hmat.T @ sinv
        xi = x0 - gain @ v
    x[:] = xi
    ikh = np.eye(NX) - gain @ hmat
    pn = ikh @ p
    p[:, :] = 0.5 * (pn + pn.T)
    return nis, used


def iekf_update_numpy(x, p, offsets_k, up, zmap, res, sig_u, iterations, gate):
    """Plain-numpy reference of :func:`iekf_update`: returns (x, p, nis, used). A beam is used when it has a
    range and its five map heights (:func:`terrain_slope_numpy`) are on the map, whatever its slope: one on
    a level patch of map (a Jacobian row of zeros) still counts, as in the kernel."""
    z, e0, n0, inv_re, inv_rn = zmap
    x0 = x.copy()
    xi = x.copy()
    step = max(1.0 / min(inv_re, inv_rn), math.sqrt(max(p[0, 0], p[1, 1])), res)
    ok = ~np.isnan(offsets_k[:, 2])
    gain = None
    nis = -1.0
    used = 0
    for it in range(iterations):
        c, s = math.cos(xi[2]), math.sin(xi[2])
        rows, resid, rvar = [], [], []
        used = 0
        for o in offsets_k[ok]:
            qe, qn = xi[0] + c * o[0] - s * o[1], xi[1] + s * o[0] + c * o[1]
            h, ge, gn, curv = terrain_slope_numpy(z, e0, n0, inv_re, inv_rn, qe, qn, step)
            if np.isnan([h, ge, gn]).any():
                rows.append([0.0] * 4)
                resid.append(0.0)
                rvar.append(1.0)
                continue
            used += 1
            rows.append([-ge, -gn, -(ge * (-s * o[0] - c * o[1]) + gn * (c * o[0] - s * o[1])), 0.0])
            resid.append(up + o[2] - h)
            rvar.append(sig_u**2 + curv**2)
        if used == 0:
            return x, p, -1.0, 0
        hm = np.array(rows).reshape(-1, 4)
        sm = hm @ p @ hm.T + np.diag(rvar)
        v = np.array(resid) + hm @ (x0 - xi)
        if it == 0:
            nis = v @ np.linalg.solve(sm, v)
            if nis > gate:
                return x, p, nis, used
        gain = p @ hm.T @ np.linalg.inv(sm)
        xi = x0 - gain @ v
    pn = (np.eye(4) - gain @ hm) @ p
    return xi, 0.5 * (pn + pn.T), nis, used


@nb.njit(cache=True)
def ekf_loop(x, p, inc_d0, inc_sz, offsets, nav_up, zmap, settings, out):
    """Run the IEKF from the state ``x`` and covariance ``p`` along the increments (``inc_d0``
    (K-1, 2), ``inc_sz`` (K-1,)); ``zmap`` the map's ``MapArgs``; ``settings`` an
    :class:`EkfSettings`; fills ``out`` (:class:`EkfOutputs`): ``est``/``var`` (K, 4) and
    ``rejected`` (K,) (1 = update gated out)."""
    _, _, _, inv_re, inv_rn = zmap
    q_pos, q_delta, q_bias, sig_u, iterations, gate = settings.q_pos, settings.q_delta, settings.q_bias, \
        settings.sig_u, settings.iterations, settings.gate
    est, var, rejected = out
    steps = offsets.shape[0]
    res = 1.0 / min(inv_re, inv_rn)
    for k in range(steps):
        if k > 0:
            ekf_predict(x, p, inc_d0[k - 1, 0], inc_d0[k - 1, 1], inc_sz[k - 1], q_pos, q_delta, q_bias)
        nis, used = iekf_update(x, p, offsets[k], nav_up[k], zmap, res, sig_u, iterations, gate)
        rejected[k] = 1 if nis > gate else 0
        for c in range(NX):
            est[k, c] = x[c]
            var[k, c] = p[c, c]


# the IEKF's settings: the prior (initial square's side, heading std, z-gyro bias std), the
# process noise variances per update (position, heading offset, bias), altitude std, the
# Gauss-Newton passes per update and the NIS gate; and its outputs
EkfSettings = namedtuple("EkfSettings", "initial_area_m std_heading std_bias q_pos q_delta q_bias sig_u iterations gate")
EkfOutputs = namedtuple("EkfOutputs", "est var rejected")


def ekf_settings(scenario, options) -> EkfSettings:
    """The IEKF's settings from the scenario and the method's options (``methods/ekf.py:EkfOptions``)."""
    f = scenario.filter
    return EkfSettings(f.initial_area_m, f.initial_std_heading_rad, f.initial_std_gyro_bias_rad_s,
                       scenario.position_noise_m()**2,
                       math.radians(options.heading_drift_deg_sqrt_s) ** 2 * scenario.sampling_time_s, 0.0,
                       scenario.range_sigma_m, int(options.iterations), float(options.gate))


def run_ekf(nav, inc, beams, ranges, zargs, settings: EkfSettings) -> dict:
    """IEKF on plain arrays: ``nav`` the navigation at the updates
    (:class:`~tanbench.navigation.increments.NavAtUpdates`), ``inc`` the (K-1, 12) increments
    table, beams, ranges, the map's kernel args. Deterministic.

    The initial position is the navigation position with the variance of the particle
    filters' uniform initial square (side^2 / 12).
    """
    offsets = nav_frame_offsets(nav.pitch, nav.roll, nav.yaw, beams, ranges)
    k_steps = offsets.shape[0]
    x = np.array([nav.en[0, 0], nav.en[0, 1], 0.0, 0.0])
    s = settings
    p = np.diag([s.initial_area_m**2 / 12.0, s.initial_area_m**2 / 12.0, s.std_heading ** 2, s.std_bias ** 2])
    est = np.empty((k_steps, NX))
    var = np.empty((k_steps, NX))
    rejected = np.zeros(k_steps, dtype=np.int64)
    ekf_loop(x, p, np.ascontiguousarray(inc[:, [D0E, D0N]]), np.ascontiguousarray(inc[:, SZ]), offsets,
             np.ascontiguousarray(nav.up, dtype=float), MapArgs(*zargs), settings, EkfOutputs(est, var, rejected))
    return {"est_e": est[:, 0], "est_n": est[:, 1], "est_yaw": np.asarray(nav.yaw) + est[:, 2],
            "var_e": var[:, 0], "var_n": var[:, 1], "var_yaw": var[:, 2],
            "bias_z": est[:, 3], "var_bias_z": var[:, 3], "rejected": rejected}
