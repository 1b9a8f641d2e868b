"""Error-state Kalman filter of the navigation system (the loose TAN's "main SINS" filter).

The loosely coupled TAN of the survey (Melo & Matos, Section 5; Hagen et al. 2011) and
of the paper (Section 2) hands its position fixes to the navigation system's Kalman
filter, which estimates the navigation errors the fixes make observable. Here the
navigation solution is *corrected* (closed loop): a corrected position ``p_c``, yaw
``psi_c`` and z-gyro bias ``b_c`` are dead-reckoned from the navigation system's
interval increments (``navigation/increments.py``) exactly as one tight-filter particle
is (``filters/propagate.propagate_tight`` with zero noise), and this filter estimates
the error state

    x = [e_E, e_N, e_psi, e_b] = truth - corrected      (m, m, rad, rad/s)

Over an interval with corrected displacement d (2,), bias sensitivity
B = -Rz(psi_c - psi_nav) [JAZE, JAZN] (the displacement's derivative with respect to
the z-gyro bias) and yaw sensitivity SZ (``increments.SZ``), to first order

    e_p' = e_p + J d e_psi + B e_b,   J = [[0, -1], [1, 0]]
    e_psi' = e_psi - SZ e_b
    e_b' = e_b

plus white noise: position ``q_pos`` per interval (DVL noise, scale error), heading
``q_yaw`` (gyro angle random walk) and a bias random walk ``q_bias``. A heading error
thus shows only as a *cross-track* position error growing as e_psi x travelled distance:
heading is observable from successive position fixes while the vehicle moves, and the
longer the track between fixes the better (docs/model.md, Section 6.2).

A fix z (2,) with covariance R (2, 2) gives the innovation nu = z - p_c, predicted
covariance S = P_pp + R and the consistency statistic chi2 = nu^T S^-1 nu; a fix with
chi2 above the gate is rejected (chi^2 with 2 degrees of freedom: 13.8 rejects a
consistent fix once in a thousand). An accepted fix updates (x, P) (Joseph form); the
caller then injects x into the corrected navigation and resets x to zero (closed loop).
"""

from __future__ import annotations

import numba as nb
import numpy as np

# error-state layout
EE, EN, EPSI, EB = range(4)
N_ERROR = 4


@nb.njit(cache=True)
def copy_matrix(dst, src):
    """``dst[:, :] = src`` element by element (an array assigned to a slice compiles numba's
    shape-mismatch error message, string formatting included: ~2 s on a cold cache)."""
    for i in range(dst.shape[0]):
        for j in range(dst.shape[1]):
            dst[i, j] = src[i, j]


@nb.njit(cache=True)
def eskf_predict(p, d_e, d_n, b_e, b_n, sz, q_pos, q_yaw, q_bias):
    """Propagate the error covariance ``p`` (4, 4) in place over one interval.

    ``(d_e, d_n)`` corrected displacement, ``(b_e, b_n)`` its derivative w.r.t. the z-gyro
    bias, ``sz`` the yaw sensitivity to the bias; ``q_*`` noise standard deviations.
    """
    f = np.eye(N_ERROR)
    f[EE, EPSI] = -d_n
    f[EN, EPSI] = d_e
    f[EE, EB] = b_e
    f[EN, EB] = b_n
    f[EPSI, EB] = -sz
    fp = f @ p
    copy_matrix(p, fp @ f.T)
    p[EE, EE] += q_pos * q_pos
    p[EN, EN] += q_pos * q_pos
    p[EPSI, EPSI] += q_yaw * q_yaw
    p[EB, EB] += q_bias * q_bias


def eskf_predict_numpy(p, d_e, d_n, b_e, b_n, sz, q_pos, q_yaw, q_bias):
    """Plain-numpy reference of :func:`eskf_predict` (returns a new covariance)."""
    f = np.array([[1.0, 0.0, -d_n, b_e], [0.0, 1.0, d_e, b_n], [0.0, 0.0, 1.0, -sz], [0.0, 0.0, 0.0, 1.0]])
    q = np.diag([q_pos**2, q_pos**2, q_yaw**2, q_bias**2])
    return f @ p @ f.T + q


@nb.njit(cache=True)
def eskf_update(p, nu_e, nu_n, r, gate, dx):
    """Position fix with innovation ``(nu_e, nu_n)`` and covariance ``r`` (2, 2).

    Returns the fix's chi-square statistic. If it is below ``gate`` the correction goes
    into ``dx`` (4,) and ``p`` is updated in place (Joseph form); otherwise ``dx`` is zero
    and ``p`` unchanged.
    """
    s00 = p[EE, EE] + r[0, 0]
    s01 = p[EE, EN] + r[0, 1]
    s10 = p[EN, EE] + r[1, 0]
    s11 = p[EN, EN] + r[1, 1]
    det = s00 * s11 - s01 * s10
    i00 = s11 / det
    i01 = -s01 / det
    i10 = -s10 / det
    i11 = s00 / det
    chi2 = nu_e * (i00 * nu_e + i01 * nu_n) + nu_n * (i10 * nu_e + i11 * nu_n)
    for i in range(N_ERROR):
        dx[i] = 0.0
    if not chi2 < gate:
        return chi2
    k = np.empty((N_ERROR, 2))
    for i in range(N_ERROR):
        k[i, 0] = p[i, EE] * i00 + p[i, EN] * i10
        k[i, 1] = p[i, EE] * i01 + p[i, EN] * i11
        dx[i] = k[i, 0] * nu_e + k[i, 1] * nu_n
    a = np.eye(N_ERROR)
    for i in range(N_ERROR):
        a[i, EE] -= k[i, 0]
        a[i, EN] -= k[i, 1]
    new = a @ p @ a.T + k @ r @ k.T
    copy_matrix(p, 0.5 * (new + new.T))
    return chi2


def eskf_update_numpy(p, nu, r, gate):
    """Plain-numpy reference of :func:`eskf_update`: (chi2, dx, new P)."""
    h = np.zeros((2, N_ERROR))
    h[0, EE] = h[1, EN] = 1.0
    s = h @ p @ h.T + r
    chi2 = float(nu @ np.linalg.solve(s, nu))
    if not chi2 < gate:
        return chi2, np.zeros(N_ERROR), p.copy()
    k = p @ h.T @ np.linalg.inv(s)
    a = np.eye(N_ERROR) - k @ h
    new = a @ p @ a.T + k @ r @ k.T
    return chi2, k @ nu, 0.5 * (new + new.T)


@nb.njit(cache=True)
def _inv2(a, out):
    det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    if not det > 0.0:
        return False
    out[0, 0] = a[1, 1] / det
    out[0, 1] = -a[0, 1] / det
    out[1, 0] = -a[1, 0] / det
    out[1, 1] = a[0, 0] / det
    return True


@nb.njit(cache=True)
def terrain_only_fix(m_post, p_post, m_prior, p_prior, max_std, z, r):
    """The terrain's own information in a PF posterior: the posterior with its prior removed.

    The PF's posterior N(m_post, p_post) at a fix combines its prior over the window since
    the last fix, N(m_prior, p_prior) (the last posterior moved by the same corrected
    navigation the KF uses, plus the PF's process noise), with the terrain measurements of
    the window. Fed to the KF as it is, it would count the prior - the KF's own
    prediction - again, and the KF would take a prior-driven, precise-looking fix for a
    heading observation. In information form the terrain's part is

        R^-1 = p_post^-1 - p_prior^-1,   z = R (p_post^-1 m_post - p_prior^-1 m_prior).

    Fills ``z`` (2,) and ``r`` (2, 2); returns False (no fix) when the window carried no
    usable terrain information (R^-1 not positive definite, or an axis of R above
    ``max_std`` metres).
    """
    ipost = np.empty((2, 2))
    iprior = np.empty((2, 2))
    info = np.empty((2, 2))
    if not _inv2(p_post, ipost) or not _inv2(p_prior, iprior):
        return False
    for i in range(2):
        for j in range(2):
            info[i, j] = ipost[i, j] - iprior[i, j]
    info[0, 1] = info[1, 0] = 0.5 * (info[0, 1] + info[1, 0])
    if not (info[0, 0] > 0.0 and info[1, 1] > 0.0):
        return False
    if not _inv2(info, r):
        return False
    # the larger eigenvalue of r
    tr = r[0, 0] + r[1, 1]
    disc = np.sqrt(max(0.25 * (r[0, 0] - r[1, 1]) ** 2 + r[0, 1] * r[1, 0], 0.0))
    if 0.5 * tr + disc > max_std * max_std:
        return False
    a0 = ipost[0, 0] * m_post[0] + ipost[0, 1] * m_post[1] - iprior[0, 0] * m_prior[0] - iprior[0, 1] * m_prior[1]
    a1 = ipost[1, 0] * m_post[0] + ipost[1, 1] * m_post[1] - iprior[1, 0] * m_prior[0] - iprior[1, 1] * m_prior[1]
    z[0] = r[0, 0] * a0 + r[0, 1] * a1
    z[1] = r[1, 0] * a0 + r[1, 1] * a1
    return True


@nb.njit(cache=True)
def fix_prior_chi2(z, r, m_prior, p_prior):
    """The terrain-only fix's chi-square (2 dof) against the window's prior: (z - m_prior)^T
    (r + p_prior)^-1 (z - m_prior). By the algebra of :func:`terrain_only_fix` it equals the
    fix's distance from the PF's own posterior mean under its covariance, so a large value
    means the fix disagrees with the cloud it was divided out of (a near-singular r^-1
    extrapolates the small difference between two Monte Carlo moments; docs/filters.md 9).
    inf for a singular sum."""
    s = np.empty((2, 2))
    inv = np.empty((2, 2))
    for i in range(2):
        for j in range(2):
            s[i, j] = r[i, j] + p_prior[i, j]
    if not _inv2(s, inv):
        return np.inf
    d0 = z[0] - m_prior[0]
    d1 = z[1] - m_prior[1]
    return d0 * (inv[0, 0] * d0 + inv[0, 1] * d1) + d1 * (inv[1, 0] * d0 + inv[1, 1] * d1)


def fix_prior_chi2_numpy(z, r, m_prior, p_prior):
    """Plain-numpy reference of :func:`fix_prior_chi2`."""
    s = np.asarray(r, dtype=float) + np.asarray(p_prior, dtype=float)
    if not np.linalg.det(s) > 0:
        return np.inf
    d = np.asarray(z, dtype=float) - np.asarray(m_prior, dtype=float)
    return float(d @ np.linalg.solve(s, d))


def terrain_only_fix_numpy(m_post, p_post, m_prior, p_prior, max_std):
    """Plain-numpy reference of :func:`terrain_only_fix`: (usable, z, r)."""
    ipost, iprior = np.linalg.inv(p_post), np.linalg.inv(p_prior)
    info = ipost - iprior
    info = 0.5 * (info + info.T)
    if np.linalg.det(p_post) <= 0 or np.linalg.det(p_prior) <= 0 or info[0, 0] <= 0 or info[1, 1] <= 0 \
            or np.linalg.det(info) <= 0:
        return False, None, None
    r = np.linalg.inv(info)
    if np.linalg.eigvalsh(r).max() > max_std**2:
        return False, None, None
    return True, r @ (ipost @ m_post - iprior @ m_prior), r
