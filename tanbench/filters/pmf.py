"""Point-mass filter (Bergman 1999; MBARI TRN): a grid Bayesian filter over position and heading.

The posterior is a bank of ``H`` heading hypotheses. Slice k holds the navigation heading
plus a fixed offset ``delta_k`` and a square ``n x n`` grid of probability masses over
east/north, centred on its own ``centre[k]`` with the spacing ``s`` shared by all
slices. One update:

1. **prediction**: every slice's grid moves by the navigation system's displacement
   rotated by its own heading offset, ``Rz(delta_k) D0`` (an exact translation of the
   grid's coordinates, no interpolation). The process noise (Table 2's velocity noise
   plus the cross-track effect of the heading uncertainty *within* one slice) is
   accumulated and applied as a separable Gaussian convolution once it reaches a
   quarter of a cell's variance, so tiny noise is neither lost nor smeared by
   interpolation every update. The heading drift (gyro bias and random walk) moves mass
   between neighbouring slices: a random walk on the heading lattice;
2. **likelihood**: the same map-aware terrain-altitude likelihood as the loose particle
   filter (``likelihood.loglik_loose``) at every grid node, the beams projected with the
   navigation attitude turned by ``delta_k``;
3. **re-gridding**: each slice re-centres on its own mean when the mean drifts an
   eighth of the grid away; the shared spacing follows the posterior,
   ``s = max(s_min, 8 sigma / (n - 1))`` (hysteresis: only when it changes by 2x), so
   a converged posterior is resolved finely and a spreading one (a plane seafloor) is
   still covered. Re-gridding samples the old density bilinearly at the new nodes.
   Slices without mass are skipped and parked at the global mean.

The bank is centred on the navigation heading and spans +-2.5 sigma of the heading prior
(at most ``heading_span``), so a small prior gets fine slices and the paper's 30 deg gets
15 slices 8.6 deg apart over +-60 deg.

With ``H = 1`` this is the position-only PMF (TRN's): the whole 30 deg heading prior
then enters as cross-track process noise, as in the loose particle filter.
The initial grid covers the same ``initial_area`` square as the particle filters'
initial cloud; the heading prior N(0, sigma_psi^2) weights the slices.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters.beams import nav_frame_offsets
from tanbench.filters.likelihood import Likelihood, loglik_loose
from tanbench.terrain.grid import node_grid_of
from tanbench.terrain.grid import bilinear_numpy

DEAD_MASS = 1e-12


@nb.njit(cache=True)
def grid_nodes(ce, cn, s, n, out):
    """Node positions (2, n*n: east row, north row) of a grid centred on (ce, cn) with spacing s,
    nodes row-major (north rows): the likelihood kernels' layout (a column per position)."""
    c = 0.5 * (n - 1)
    for i in range(n):
        for j in range(n):
            out[0, i * n + j] = ce + (j - c) * s
            out[1, i * n + j] = cn + (i - c) * s


def grid_nodes_numpy(ce, cn, s, n):
    """Plain-numpy reference of :func:`grid_nodes`."""
    c = 0.5 * (n - 1)
    jj, ii = np.meshgrid(np.arange(n), np.arange(n))
    return np.stack([ce + (jj.ravel() - c) * s, cn + (ii.ravel() - c) * s])


@nb.njit(cache=True)
def gaussian_kernel(sigma_cells):
    """Sampled, normalised Gaussian of std ``sigma_cells`` truncated at 3 sigma (at least 1 tap each side)."""
    r = max(1, int(math.ceil(3.0 * sigma_cells)))
    k = np.empty(2 * r + 1)
    total = 0.0
    for t in range(-r, r + 1):
        v = math.exp(-0.5 * (t / sigma_cells) ** 2) if sigma_cells > 0 else (1.0 if t == 0 else 0.0)
        k[t + r] = v
        total += v
    for t in range(2 * r + 1):
        k[t] /= total
    return k


@nb.njit(cache=True)
def blur_separable(p, sigma_cells, scratch):
    """Convolve grid ``p`` (n, n) in place with a Gaussian of std ``sigma_cells``; zero outside."""
    k = gaussian_kernel(sigma_cells)
    r = (k.shape[0] - 1) // 2
    n0, n1 = p.shape
    for i in range(n0):
        for j in range(n1):
            acc = 0.0
            for t in range(-r, r + 1):
                jj = j + t
                if 0 <= jj < n1:
                    acc += k[t + r] * p[i, jj]
            scratch[i, j] = acc
    for i in range(n0):
        for j in range(n1):
            acc = 0.0
            for t in range(-r, r + 1):
                ii = i + t
                if 0 <= ii < n0:
                    acc += k[t + r] * scratch[ii, j]
            p[i, j] = acc


def blur_separable_numpy(p, sigma_cells):
    """Plain-numpy reference of :func:`blur_separable` (returns a new array). The centred part of the full
    convolutions (``mode="same"`` returns the longer of grid and kernel: a kernel of more taps than the grid
    has nodes, which the kernel allows, would have given an array of the wrong size)."""
    r = max(1, int(math.ceil(3.0 * sigma_cells)))
    t = np.arange(-r, r + 1)
    k = np.exp(-0.5 * (t / sigma_cells) ** 2) if sigma_cells > 0 else (t == 0).astype(float)
    k = k / k.sum()
    n0, n1 = np.shape(p)
    rows = np.array([np.convolve(row, k)[r:r + n1] for row in p])
    return np.array([np.convolve(col, k)[r:r + n0] for col in rows.T]).T


@nb.njit(cache=True)
def resample_grid(p, ce, cn, s, ce_new, cn_new, s_new, out):
    """Density of grid ``p`` (centre (ce, cn), spacing s) sampled bilinearly at the nodes of a new grid
    (same node count, centre (ce_new, cn_new), spacing s_new), into ``out``; zero outside the old grid."""
    n = p.shape[0]
    c = 0.5 * (n - 1)
    for i in range(n):
        fy = ((cn_new + (i - c) * s_new) - cn) / s + c
        for j in range(n):
            fx = ((ce_new + (j - c) * s_new) - ce) / s + c
            if fx < 0.0 or fy < 0.0 or fx > n - 1 or fy > n - 1:
                out[i, j] = 0.0
                continue
            j0 = min(int(fx), n - 2)
            i0 = min(int(fy), n - 2)
            tx = fx - j0
            ty = fy - i0
            out[i, j] = ((p[i0, j0] * (1 - tx) + p[i0, j0 + 1] * tx) * (1 - ty)
                         + (p[i0 + 1, j0] * (1 - tx) + p[i0 + 1, j0 + 1] * tx) * ty)


def resample_grid_numpy(p, ce, cn, s, ce_new, cn_new, s_new):

    n = p.shape[0]
    c = 0.5 * (n - 1)
    nodes = grid_nodes_numpy(ce_new, cn_new, s_new, n)
    v = bilinear_numpy(p, ce - c * s, cn - c * s, 1.0 / s, 1.0 / s, nodes[0], nodes[1])
    return np.nan_to_num(v, nan=0.0).reshape(n, n)


@nb.njit(cache=True)
def slice_moments(p, ce, cn, s):
    """(mass, mean e, mean n, var e, var n, cov en) of one grid."""
    n = p.shape[0]
    c = 0.5 * (n - 1)
    m = 0.0
    se = 0.0
    sn = 0.0
    see = 0.0
    snn = 0.0
    sen = 0.0
    for i in range(n):
        dn = (i - c) * s
        for j in range(n):
            v = p[i, j]
            de = (j - c) * s
            m += v
            se += v * de
            sn += v * dn
            see += v * de * de
            snn += v * dn * dn
            sen += v * de * dn
    if m <= 0.0:
        return 0.0, ce, cn, 0.0, 0.0, 0.0
    me = se / m
    mn = sn / m
    return (m, ce + me, cn + mn, max(see / m - me * me, 0.0), max(snn / m - mn * mn, 0.0),
            sen / m - me * mn)


def slice_moments_numpy(p, ce, cn, s):
    n = p.shape[0]
    nodes = grid_nodes_numpy(ce, cn, s, n)
    w = p.ravel()
    m = w.sum()
    if m <= 0:
        return 0.0, ce, cn, 0.0, 0.0, 0.0
    mu = nodes @ w / m
    d = nodes - mu[:, None]
    return (m, mu[0], mu[1], w @ (d[0] ** 2) / m, w @ (d[1] ** 2) / m, w @ (d[0] * d[1]) / m)


@nb.njit(cache=True)
def mix_headings(p, centres, s, a, buf, out):
    """Heading random walk on the slice lattice: each slice passes a fraction ``a`` of its mass to
    each neighbour (re-sampled onto the neighbour's grid). ``out`` (H, n, n) receives the result."""
    h = p.shape[0]
    for k in range(h):
        nb_count = (1 if k > 0 else 0) + (1 if k < h - 1 else 0)
        out[k] = (1.0 - a * nb_count) * p[k]
        for q in (k - 1, k + 1):
            if 0 <= q < h:
                resample_grid(p[q], centres[q, 0], centres[q, 1], s, centres[k, 0], centres[k, 1], s, buf)
                out[k] += a * buf


def mix_headings_numpy(p, centres, s, a):
    h = p.shape[0]
    out = np.empty_like(p)
    for k in range(h):
        nbs = [q for q in (k - 1, k + 1) if 0 <= q < h]
        out[k] = (1.0 - a * len(nbs)) * p[k]
        for q in nbs:
            out[k] += a * resample_grid_numpy(p[q], *centres[q], s, *centres[k], s)
    return out


@nb.njit(cache=True)
def pmf_init(p, centres, deltas, centre_e, centre_n, sig_heading0):
    """Uniform mass over every slice's grid, slices weighted by the heading prior N(0, sig^2)."""
    h = p.shape[0]
    total = 0.0
    for k in range(h):
        wk = math.exp(-0.5 * (deltas[k] / sig_heading0) ** 2) if (h > 1 and sig_heading0 > 0) else 1.0
        p[k, :, :] = wk
        total += wk * p.shape[1] * p.shape[2]
        centres[k, 0] = centre_e
        centres[k, 1] = centre_n
    p /= total


def pmf_init_numpy(shape, deltas, centre_e, centre_n, sig_heading0):
    """Plain-numpy reference of :func:`pmf_init` for a bank ``p`` of ``shape`` (H, n, n): returns
    (p, centres (H, 2)). Slice k's mass is in proportion to exp(-delta_k^2 / (2 sig^2)) (the same for
    every slice of a single-slice bank or for sig <= 0), spread evenly over its nodes; the bank's mass 1;
    every slice centred on (centre_e, centre_n)."""
    h = shape[0]
    d = np.asarray(deltas, dtype=np.float64)[:h]
    with np.errstate(over="ignore", invalid="ignore"):  # weights underflowing to 0; all of them: 0 / 0, as the kernel's
        weight = np.exp(-0.5 * (d / sig_heading0) ** 2) if (h > 1 and sig_heading0 > 0) else np.ones(h)
        per_node = weight / (weight.sum() * shape[1] * shape[2])
    p = np.broadcast_to(per_node[:, None, None], shape).copy()
    return p, np.tile([centre_e, centre_n], (h, 1)).astype(np.float64)


@nb.njit(cache=True)
def pmf_loop(track, offsets, grid, settings, out):
    """Run the PMF over all K updates.

    ``track`` (:class:`PmfTrack`): ``en`` (K, 2), ``up`` (K,), ``yaw`` (K,), the navigation
    solution at the updates, and ``d0`` (K-1, 2) its displacements; ``settings`` the
    :class:`PmfSettings` (``n`` cells per side, ``div_sigma``, ``div_steps``, and those below); ``offsets`` (K, m, 3): beam vectors times ranges in
    the navigation frame with the navigation attitude (NaN = no range); ``grid`` the navigation
    map as the likelihood reads it (``terrain.grid.NodeGrid``). ``deltas`` (H,) heading
    offsets (rad); ``sig_pos`` position noise per update (m); ``sig_cross`` cross-track noise
    per metre travelled (rad: the heading uncertainty inside one slice);
    ``sig_heading_step`` heading random walk per update (rad).
    Fills ``out`` (:class:`PmfOutputs`): ``est`` (K, 3) east, north, yaw; ``var`` (K, 3);
    ``reinit`` and ``live`` (K,) (slices evaluated at each update: the cost driver).
    """
    nav_en, nav_up, nav_yaw, d0 = track
    (n, deltas, sig_heading0, half_side, sig_pos, sig_cross, sig_heading_step, s_min, sig_u, outside_sigma,
     div_sigma, div_steps) = settings
    est, var, reinit_out, live_out = out
    h = deltas.shape[0]
    steps = nav_en.shape[0]
    m_beams = offsets.shape[1]
    p = np.empty((h, n, n))
    mixed = np.empty((h, n, n))
    buf = np.empty((n, n))
    centres = np.empty((h, 2))
    nodes = np.empty((2, n * n))
    plain = Likelihood(False, 0, 4.0)
    ll = np.empty((h, n * n))
    rot = np.empty((m_beams, 3))
    mom = np.empty((h, 6))
    s0 = 2.0 * half_side / (n - 1)
    s = s0
    pmf_init(p, centres, deltas, nav_en[0, 0], nav_en[0, 1], sig_heading0)
    q_acc = 0.0
    a_acc = 0.0
    dh = deltas[1] - deltas[0] if h > 1 else 1.0
    bad = 0
    for k in range(steps):
        if k > 0:
            de = d0[k - 1, 0]
            dn = d0[k - 1, 1]
            for q in range(h):
                c = math.cos(deltas[q])
                sn = math.sin(deltas[q])
                centres[q, 0] += c * de - sn * dn
                centres[q, 1] += sn * de + c * dn
            q_acc += sig_pos * sig_pos + (sig_cross * sig_cross) * (de * de + dn * dn)
            if q_acc >= 0.25 * s * s:
                for q in range(h):
                    blur_separable(p[q], math.sqrt(q_acc) / s, buf)
                q_acc = 0.0
            if h > 1:
                a_acc += 0.5 * (sig_heading_step / dh) ** 2
                if a_acc >= 0.02:
                    mix_headings(p, centres, s, min(a_acc, 0.25), buf, mixed)
                    p[:, :, :] = mixed
                    a_acc = 0.0
        # likelihood, slice by slice; slices without mass are skipped
        mx = -np.inf
        best = np.inf
        live = 0
        for q in range(h):
            if p[q].max() <= 0.0:
                continue
            live += 1
            c = math.cos(deltas[q])
            sn = math.sin(deltas[q])
            for i in range(m_beams):
                rot[i, 0] = c * offsets[k, i, 0] - sn * offsets[k, i, 1]
                rot[i, 1] = sn * offsets[k, i, 0] + c * offsets[k, i, 1]
                rot[i, 2] = offsets[k, i, 2]
            grid_nodes(centres[q, 0], centres[q, 1], s, n, nodes)
            b = loglik_loose(nodes, rot, nav_up[k], grid, plain, sig_u, outside_sigma, ll[q])
            if b < best:
                best = b
            flat = p[q].reshape(n * n)
            for t in range(n * n):
                if ll[q, t] > mx and flat[t] > 0.0:
                    mx = ll[q, t]
        total = 0.0
        for q in range(h):
            if p[q].max() <= 0.0:
                continue
            flat = p[q].reshape(n * n)
            for t in range(n * n):
                if flat[t] > 0.0:  # a node without mass stays at 0 (exp may overflow there: 0 x inf)
                    flat[t] *= math.exp(ll[q, t] - mx)
                    total += flat[t]
        p /= total
        live_out[k] = live
        # estimate: mixture moments over slices
        me = 0.0
        mn = 0.0
        myaw = 0.0
        for q in range(h):
            r = slice_moments(p[q], centres[q, 0], centres[q, 1], s)
            for c6 in range(6):
                mom[q, c6] = r[c6]
            me += r[0] * r[1]
            mn += r[0] * r[2]
            myaw += r[0] * deltas[q]
        ve = 0.0
        vn = 0.0
        vyaw = dh * dh / 12.0 if h > 1 else sig_heading0 * sig_heading0
        for q in range(h):
            ve += mom[q, 0] * (mom[q, 3] + (mom[q, 1] - me) ** 2)
            vn += mom[q, 0] * (mom[q, 4] + (mom[q, 2] - mn) ** 2)
            if h > 1:
                vyaw += mom[q, 0] * (deltas[q] - myaw) ** 2
        est[k, 0] = me
        est[k, 1] = mn
        est[k, 2] = nav_yaw[k] + myaw
        var[k, 0] = ve + s * s / 12.0
        var[k, 1] = vn + s * s / 12.0
        var[k, 2] = vyaw
        reinit_out[k] = 0
        if best < np.inf:
            bad = bad + 1 if best > div_sigma * div_sigma else 0
        if bad >= div_steps:
            s = s0
            pmf_init(p, centres, deltas, me, mn, sig_heading0)
            q_acc = 0.0
            bad = 0
            reinit_out[k] = 1
            continue
        # re-gridding: shared spacing follows the widest live slice, slices re-centre on their mean
        sig_max = 0.0
        for q in range(h):
            if mom[q, 0] > 1e-3:
                sig_max = max(sig_max, math.sqrt(max(mom[q, 3], mom[q, 4])))
        s_t = max(s_min, 8.0 * sig_max / (n - 1))
        new_s = s_t if (s_t < 0.5 * s or s_t > 2.0 * s) else s
        for q in range(h):
            if mom[q, 0] < DEAD_MASS:
                p[q, :, :] = 0.0
                centres[q, 0] = me
                centres[q, 1] = mn
                continue
            off = max(abs(mom[q, 1] - centres[q, 0]), abs(mom[q, 2] - centres[q, 1]))
            if new_s != s or off > 0.125 * n * s:
                resample_grid(p[q], centres[q, 0], centres[q, 1], s, mom[q, 1], mom[q, 2], new_s, buf)
                # keep the slice's mass (the density was sampled at a new spacing)
                bm = buf.sum()
                if bm > 0.0:
                    p[q, :, :] = buf * (mom[q, 0] / bm)
                centres[q, 0] = mom[q, 1]
                centres[q, 1] = mom[q, 2]
        s = new_s


# the PMF's settings (``pmf_loop``'s docstring), the navigation at the updates and its outputs
PmfSettings = namedtuple("PmfSettings", "n deltas sig_heading0 half_side sig_pos sig_cross sig_heading_step s_min "
                                        "sig_u outside_sigma div_sigma div_steps")
PmfTrack = namedtuple("PmfTrack", "en up yaw d0")
PmfOutputs = namedtuple("PmfOutputs", "est var reinit live")


def pmf_settings(scenario, options) -> PmfSettings:
    """The PMF's settings from the scenario and the method's options (``methods/pmf.py:PmfOptions``).

    ``options.headings`` = 1 is the position-only filter (heading prior as cross-track noise)."""
    f = scenario.filter
    sig0 = f.initial_std_heading_rad
    if options.headings > 1:
        # the bank spans the heading prior (2.5 sigma), at most heading_span_deg
        span = min(math.radians(options.heading_span_deg), 2.5 * sig0) if sig0 > 0 else \
            math.radians(options.heading_span_deg)
        deltas = np.linspace(-span, span, options.headings)
        sig_cross = (deltas[1] - deltas[0]) / math.sqrt(12.0)
    else:
        deltas = np.zeros(1)
        sig_cross = sig0
    return PmfSettings(int(options.cells), deltas, sig0, f.initial_area_m / 2.0, scenario.position_noise_m(), sig_cross,
                       math.radians(options.heading_drift_deg_sqrt_s) * math.sqrt(scenario.sampling_time_s),
                       options.min_spacing_m, scenario.range_sigma_m, f.outside_map_sigma, f.divergence_sigma,
                       f.divergence_steps)


def run_pmf(nav, beams, ranges, zargs, settings: PmfSettings) -> dict:
    """Point-mass filter on plain arrays (``nav`` the navigation solution at the K updates,
    :class:`~tanbench.navigation.increments.NavAtUpdates`; beams (m, 3), ranges (K, m), the
    navigation map's ``kernel_args()``). Deterministic.

    Returns per-update east, north, yaw estimates and their variances, reinitialisations
    and the number of slices evaluated.
    """
    nav_en = np.ascontiguousarray(nav.en, dtype=float)
    k_steps = nav_en.shape[0]
    offsets = nav_frame_offsets(nav.pitch, nav.roll, nav.yaw, beams, ranges)
    d0 = np.ascontiguousarray(np.diff(nav_en, axis=0))
    est = np.empty((k_steps, 3))
    var = np.empty((k_steps, 3))
    reinit = np.zeros(k_steps, dtype=np.int64)
    live = np.zeros(k_steps, dtype=np.int64)
    track = PmfTrack(nav_en, np.ascontiguousarray(nav.up, dtype=float), np.ascontiguousarray(nav.yaw, dtype=float), d0)
    pmf_loop(track, offsets, node_grid_of(*zargs), settings, PmfOutputs(est, var, reinit, live))
    return {"est_e": est[:, 0], "est_n": est[:, 1], "est_yaw": est[:, 2],
            "var_e": var[:, 0], "var_n": var[:, 1], "var_yaw": var[:, 2],
            "reinit": reinit, "live_slices": live}
