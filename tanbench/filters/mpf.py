"""Marginalized (Rao-Blackwellised) particle filter (Schön, Gustafsson & Nordlund 2005; Karlsson 2005).

Split of the state:

* **particles** carry the nonlinear states, horizontal position and yaw (E, N, psi): the
  terrain measurement is a nonlinear function of them (the map), and the yaw enters the
  position increments through a rotation;
* **a Kalman filter per particle** carries the linear ones, given the particle's trajectory:
  - the depth (or tide) bias ``b`` of the pressure-derived up coordinate: every beam's
    terrain-altitude innovation is nu_i = U_nav + o_up,i - h(p_i) = b + v_i, linear in b
    with H = 1 once the particle fixes p_i;
  - the z-gyro bias ``eps_z``: the yaw dynamics are psi' = psi + dpsi_nav - S_z eps_z + w,
    linear in eps_z with the known coefficient S_z (``navigation/increments.py``); the
    sampled yaw transition is the KF's measurement of eps_z (the MPF's "nonlinear state
    dynamics as measurement" step). Its effect on position (-eps_z J A_z, under a
    millimetre per interval) uses the KF mean.

  The two KFs are independent (b only meets the terrain measurement, eps_z only the yaw
  transition), so each particle carries two means and two variances: columns
  [E, N, psi, b, P_b, eps_z, P_eps]. Pitch, roll and up are taken from the navigation
  system (levelling and pressure), the x-gyro bias is dropped (its heading effect scales
  with sin(roll) ~ 0: it is barely observable, docs/model.md).

The weights are the marginal likelihood of the beams with b integrated out,
N(nu; b_hat 1, P_b 1 1^T + sigma_u^2 I), in closed form (Sherman-Morrison); the yaw is
sampled from its marginal N(psi + dpsi - S_z eps_hat, S_z^2 P_eps + q_psi). Resampling,
regularisation (position and yaw) and divergence handling are the tight filter's.
The kernels are compiled without fastmath: with FMA contraction a kernel's last bits
depended on whether it was compiled inline in the loop or on its own first, so a run
could differ by an ulp between processes.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters.beams import nav_frame_offsets
from tanbench.filters.cloud import uniform_horizontal, uniform_horizontal_numpy
from tanbench.filters.estimate import weighted_estimate
from tanbench.filters.resample import (effective_sample_size, normalize_log_weights, resample_and_regularise,
                                      resampling_of)
from tanbench.filters.rng import fill_normals, fill_numpy
from tanbench.filters.tight import divergence_of
from tanbench.filters.trig import sin_cos
from tanbench.navigation.increments import D0E, D0N, DYAW, JAZE, JAZN, SZ
from tanbench.terrain.grid import MapArgs, bilinear, bilinear_numpy
from tanbench.units import DEG_PER_H

E, N, PSI, B, PB, EPS, PEPS = range(7)
N_MPF = 7
REG_COLS = np.array([E, N, PSI], dtype=np.int64)


@nb.njit(cache=True)
def mpf_propagate(x, inc, yaw_nav0, noise, sig_pos, q_psi, q_eps, q_b):
    """Move particles (``x`` (7, M), a column per particle) and their Kalman filters over one
    interval; ``noise`` (3, M) standard normals."""
    for j in range(x.shape[1]):
        s, c = sin_cos(x[PSI, j] - yaw_nav0)
        eps = x[EPS, j]
        ue = inc[D0E] - eps * inc[JAZE]
        un = inc[D0N] - eps * inc[JAZN]
        x[E, j] += c * ue - s * un + sig_pos * noise[0, j]
        x[N, j] += s * ue + c * un + sig_pos * noise[1, j]
        # yaw from its marginal, then that transition updates the bias KF
        sz = inc[SZ]
        s_var = sz * sz * x[PEPS, j] + q_psi
        step = inc[DYAW] - sz * eps + math.sqrt(s_var) * noise[2, j]
        x[PSI, j] += step
        innov = step - (inc[DYAW] - sz * eps)
        gain = -sz * x[PEPS, j] / s_var
        x[EPS, j] = eps + gain * innov
        x[PEPS, j] = x[PEPS, j] * q_psi / s_var + q_eps
        x[PB, j] += q_b


def mpf_propagate_numpy(x, inc, yaw_nav0, noise, sig_pos, q_psi, q_eps, q_b):
    """Plain-numpy reference of :func:`mpf_propagate` (returns a new array)."""
    x = x.copy()
    d = x[PSI] - yaw_nav0
    eps = x[EPS].copy()
    u = np.stack([inc[D0E] - eps * inc[JAZE], inc[D0N] - eps * inc[JAZN]])
    x[E] += np.cos(d) * u[0] - np.sin(d) * u[1] + sig_pos * noise[0]
    x[N] += np.sin(d) * u[0] + np.cos(d) * u[1] + sig_pos * noise[1]
    s_var = inc[SZ] ** 2 * x[PEPS] + q_psi
    pred = inc[DYAW] - inc[SZ] * eps
    step = pred + np.sqrt(s_var) * noise[2]
    x[PSI] += step
    x[EPS] = eps - inc[SZ] * x[PEPS] / s_var * (step - pred)
    x[PEPS] = x[PEPS] * q_psi / s_var + q_eps
    x[PB] += q_b
    return x


@nb.njit(cache=True)
def mpf_loglik_update(x, offsets_k, up, yaw_nav, z, e0, n0, inv_re, inv_rn, sig_u, outside_sigma, out):
    """Marginal log-likelihood of the beams per particle into ``out`` (b integrated out); then the
    depth-bias KF update. ``offsets_k`` (m, 3) beams with the navigation attitude. Returns the best
    per-beam chi^2 (about the KF mean)."""
    m = offsets_k.shape[0]
    r2 = sig_u * sig_u
    outside_sq = outside_sigma * outside_sigma
    best = np.inf
    for j in range(x.shape[1]):
        s, c = sin_cos(x[PSI, j] - yaw_nav)
        bhat = x[B, j]
        pb = x[PB, j]
        used = 0
        outside = 0
        sy = 0.0
        syy = 0.0
        for i in range(m):
            if offsets_k[i, 2] != offsets_k[i, 2]:
                continue
            oe = offsets_k[i, 0]
            on = offsets_k[i, 1]
            h = bilinear(z, e0, n0, inv_re, inv_rn, x[E, j] + c * oe - s * on, x[N, j] + s * oe + c * on)
            if h != h:
                outside += 1
                continue
            d = up + offsets_k[i, 2] - h - bhat
            sy += d
            syy += d * d
            used += 1
        quad = syy / r2 - pb * sy * sy / (r2 * (r2 + used * pb))
        out[j] = -0.5 * (quad + outside * outside_sq + math.log(1.0 + used * pb / r2))
        if used + outside > 0:
            chi = (syy / r2 + outside * outside_sq) / (used + outside)
            if chi < best:
                best = chi
        if used > 0:
            p_new = 1.0 / (1.0 / pb + used / r2) if pb > 0 else 0.0
            x[B, j] = bhat + p_new * sy / r2
            x[PB, j] = p_new
    return best


def mpf_loglik_update_numpy(x, offsets_k, up, yaw_nav, z, e0, n0, inv_re, inv_rn, sig_u, outside_sigma):
    """Plain-numpy reference of :func:`mpf_loglik_update`: (loglik, best chi^2, updated x), with the
    marginal likelihood evaluated by the dense Gaussian density (no Sherman-Morrison)."""
    x = x.copy()
    ok = ~np.isnan(offsets_k[:, 2])
    o = offsets_k[ok]
    d = x[PSI] - yaw_nav
    c, s = np.cos(d)[:, None], np.sin(d)[:, None]
    qe = x[E][:, None] + c * o[:, 0] - s * o[:, 1]
    qn = x[N][:, None] + s * o[:, 0] + c * o[:, 1]
    h = bilinear_numpy(z, e0, n0, inv_re, inv_rn, qe, qn)
    ll = np.empty(x.shape[1])
    best = np.inf
    for j in range(x.shape[1]):
        inside = ~np.isnan(h[j])
        y = up + o[inside, 2] - h[j, inside]
        k = y.size
        cov = sig_u**2 * np.eye(k) + x[PB, j] * np.ones((k, k))
        r = y - x[B, j]
        sign, logdet = np.linalg.slogdet(cov / sig_u**2) if k else (1.0, 0.0)
        outside = (~inside).sum()
        ll[j] = -0.5 * (r @ np.linalg.solve(cov, r) + outside * outside_sigma**2 + logdet) if k else \
            -0.5 * outside * outside_sigma**2
        if k + outside:
            best = min(best, ((r**2).sum() / sig_u**2 + outside * outside_sigma**2) / (k + outside))
        if k:
            p_new = 1.0 / (1.0 / x[PB, j] + k / sig_u**2)
            x[B, j] = x[B, j] + p_new * r.sum() / sig_u**2
            x[PB, j] = p_new
    return ll, best, x


@nb.njit(cache=True)
def init_mpf(x, rng, centre_e, centre_n, yaw, half_side, std_yaw, var_b, var_eps):
    """The initial cloud (``x`` (7, M)): uniform square, Gaussian yaw, the KFs at their priors."""
    uniform_horizontal(x, rng, centre_e, centre_n, half_side)
    fill_normals(rng, x[PSI])
    for j in range(x.shape[1]):
        x[PSI, j] = yaw + std_yaw * x[PSI, j]
        x[B, j] = 0.0
        x[PB, j] = var_b
        x[EPS, j] = 0.0
        x[PEPS, j] = var_eps


def init_mpf_numpy(x, rng, centre_e, centre_n, yaw, half_side, std_yaw, var_b, var_eps):
    """Plain-numpy reference of :func:`init_mpf` (returns a new array of ``x``'s shape): its numbers drawn
    from ``rng`` as the kernel's fills draw them (``rng.fill_numpy``, ``rng`` advanced in place): the square's
    uniforms (east row, then north), then the yaw row's normals."""
    m = np.shape(x)[1]
    x = uniform_horizontal_numpy(np.empty((N_MPF, m)), fill_numpy(rng, (2, m), False), centre_e, centre_n, half_side)
    x[PSI] = yaw + std_yaw * fill_numpy(rng, m, True)
    x[B] = 0.0
    x[PB] = var_b
    x[EPS] = 0.0
    x[PEPS] = var_eps
    return x


@nb.njit(cache=True)
def mpf_loop(x, rng, track, offsets, zmap, settings, out):
    """Run the MPF over K updates; fill ``out`` (:class:`MpfOutputs`: est/var (K, 7), the
    particle means/variances of the columns, ESS and reinitialisations).

    ``x`` (7, M) is the initial cloud, a column per particle; ``track`` the increments
    (K-1, 12), yaw and up (K,) of the navigation at the updates (:class:`MpfTrack`); ``zmap``
    is the map's ``MapArgs``; ``settings`` the :class:`MpfSettings` (its ``rs``' ``cols``: E, N, psi).
    """
    inc, nav_yaw, nav_up = track
    _, model, prior, rs, div = settings
    sig_pos, q_psi, q_eps, q_b, sig_u, outside_sigma = model
    half_side, std_yaw, var_b, var_eps = prior
    est, var, ess_out, reinit_out = out
    z, e0, n0, inv_re, inv_rn = zmap
    div_sigma, div_steps = div.sigma, div.steps
    m = x.shape[1]
    steps = offsets.shape[0]
    logw = np.zeros(m)
    ll = np.empty(m)
    w = np.empty(m)
    noise = np.empty((3, m))
    uni = np.empty(m)
    idx = np.empty(m, dtype=np.int64)
    scratch = np.empty_like(x)
    mean = np.empty(N_MPF)
    v = np.empty(N_MPF)
    cov = np.empty((2, 2))
    bad = 0
    for k in range(steps):
        if k > 0:
            fill_normals(rng, noise)
            mpf_propagate(x, inc[k - 1], nav_yaw[k - 1], noise, sig_pos, q_psi, q_eps, q_b)
        best = mpf_loglik_update(x, offsets[k], nav_up[k], nav_yaw[k], z, e0, n0, inv_re, inv_rn, sig_u,
                                 outside_sigma, ll)
        for j in range(m):
            logw[j] += ll[j]
        normalize_log_weights(logw, w)
        weighted_estimate(x, w, PSI, nav_yaw[k], mean, v, cov)
        ess = effective_sample_size(w)
        est[k, :] = mean
        var[k, :] = v
        ess_out[k] = ess
        reinit_out[k] = 0
        if best < np.inf:
            bad = bad + 1 if best > div_sigma * div_sigma else 0
        if bad >= div_steps:
            init_mpf(x, rng, mean[E], mean[N], nav_yaw[k], half_side, std_yaw, var_b, var_eps)
            logw[:] = 0.0
            bad = 0
            reinit_out[k] = 1
            continue
        resample_and_regularise(x, w, logw, ess, rng, rs, 3, math.sqrt(v[E] + v[N]), uni, idx, scratch)


# the MPF's bundles: process noise (position std, heading, gyro-bias and depth-bias variances per
# update), altitude std and off-map innovation; the prior (initial square's half side, heading
# std, depth-bias and gyro-bias variances); all settings; the navigation at the updates; outputs
MpfModel = namedtuple("MpfModel", "sig_pos q_psi q_eps q_b sig_u outside_sigma")
MpfPrior = namedtuple("MpfPrior", "half_side std_yaw var_b var_eps")
MpfSettings = namedtuple("MpfSettings", "particles model prior rs div")
MpfTrack = namedtuple("MpfTrack", "inc yaw up")
MpfOutputs = namedtuple("MpfOutputs", "est var ess reinit")


def mpf_settings(scenario, options) -> MpfSettings:
    """The MPF's settings from the scenario and the method's options (``methods/mpf.py:MpfOptions``)."""
    f, s, T = scenario.filter, scenario.sensors, scenario.sampling_time_s
    q_eps = 2.0 * (s.gyro_bias_instability_deg_h * DEG_PER_H) ** 2 * T / s.gyro_bias_corr_time_s
    model = MpfModel(scenario.position_noise_m(), scenario.attitude_noise_rad**2, q_eps,
                     options.depth_bias_walk_m_sqrt_s**2 * T, scenario.range_sigma_m, f.outside_map_sigma)
    prior = MpfPrior(f.initial_area_m / 2.0, f.initial_std_heading_rad, options.initial_std_depth_bias_m**2,
                     f.initial_std_gyro_bias_rad_s**2)
    return MpfSettings(scenario.particles, model, prior, resampling_of(f, REG_COLS), divergence_of(f))


def run_mpf(nav, inc, beams, ranges, zargs, rng, settings: MpfSettings) -> dict:
    """MPF on plain arrays: ``nav`` the navigation at the updates
    (:class:`~tanbench.navigation.increments.NavAtUpdates`), ``inc`` (K-1, 12) increments, the
    beams and their ranges, the map's ``MapArgs`` ``zargs``, ``rng`` the run's Generator."""
    offsets = nav_frame_offsets(nav.pitch, nav.roll, nav.yaw, beams, ranges)
    k_steps = offsets.shape[0]
    x = np.empty((N_MPF, settings.particles))  # a column per particle
    nav_en = np.asarray(nav.en, dtype=float)
    nav_yaw = np.ascontiguousarray(nav.yaw, dtype=float)
    p = settings.prior
    init_mpf(x, rng, nav_en[0, 0], nav_en[0, 1], nav_yaw[0], p.half_side, p.std_yaw, p.var_b, p.var_eps)
    est = np.empty((k_steps, N_MPF))
    var = np.empty((k_steps, N_MPF))
    ess = np.empty(k_steps)
    reinit = np.zeros(k_steps, dtype=np.int64)
    mpf_loop(x, rng, MpfTrack(np.ascontiguousarray(inc), nav_yaw, np.ascontiguousarray(nav.up, dtype=float)), offsets,
             MapArgs(*zargs), settings, MpfOutputs(est, var, ess, reinit))
    return {"est_e": est[:, E], "est_n": est[:, N], "est_yaw": est[:, PSI],
            "var_e": var[:, E], "var_n": var[:, N], "var_yaw": var[:, PSI],
            "depth_bias_m": est[:, B], "var_depth_bias": est[:, PB] + var[:, B],
            "bias_z": est[:, EPS], "var_bias_z": est[:, PEPS] + var[:, EPS],
            "ess": ess, "reinit": reinit}
