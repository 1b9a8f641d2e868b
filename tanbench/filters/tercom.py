"""TERCOM: batch correlation of a terrain profile against the map (Golden 1980; Melo & Matos Section 4.1).

The method keeps a *corrected navigation solution*: the navigation system's
displacements, turned by a heading correction, added to the last fix. The last ``N``
updates' beam footprints (positions in that solution, measured bottom heights
U + o_up) form the profile. Every ``interval`` updates the profile is matched against
the map over a search window around the corrected solution: candidates are a rotation
``delta`` of the whole profile about the current position and a translation (dx, dy),
scored by the mean squared difference (MSD) or the mean absolute difference (MAD) of
measured and map heights, the mean difference removed (so a constant depth or tide
bias does not matter). The search is coarse (the map spacing over the window,
``window = clamp(3 sigma, 3 res, window_max)``) then fine (a fifth of the map spacing
around the best coarse cell and heading).

A best match becomes a fix only if the profile pins it down: the MSD surface turned into
a likelihood, exp(-pings (MSD - MSD_min) / (2 sigma_u^2)) (one independent
observation per ping: a ping's beams share map errors), must have a position std below
``fix_std`` over the whole coarse window (no second, equally good match), the best MSD
must fit the noise (below (div_sigma / 2)^2 sigma_u^2, the particle filters'
consistency test) and the match may not sit on the window's edge. A fix replaces the
corrected position and heading and the profile is moved with it. Between fixes the
reported variance is the fix's (the fine likelihood surface's) plus Table 2's velocity noise
plus the heading variance times the squared distance from the fix (a heading error turns
the whole track since the fix about the fix's position).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters.beams import nav_frame_offsets
from tanbench.terrain.grid import MapArgs, bilinear, bilinear_numpy

MSD, MAD = 0, 1
METRICS = {"msd": MSD, "mad": MAD}


@nb.njit(cache=True)
def profile_surface(pe, pn, ph, pivot_e, pivot_n, half_cells, step, deltas, zmap, msd_out, mad_out):
    """Score every candidate (delta_d, dy_i, dx_j) = (deltas[d], (i - half) step, (j - half) step).

    ``pe, pn, ph`` (P,) profile points and measured heights, ``zmap`` the map's ``MapArgs``.
    Fills ``msd_out`` and ``mad_out`` (D, 2 half + 1, 2 half + 1) with the demeaned MSD and MAD;
    +inf where a point is off the map.
    """
    z, e0, n0, inv_re, inv_rn = zmap
    npts = pe.shape[0]
    side = 2 * half_cells + 1
    r = np.empty(npts)
    for d in range(deltas.shape[0]):
        c = math.cos(deltas[d])
        s = math.sin(deltas[d])
        for i in range(side):
            dy = (i - half_cells) * step
            for j in range(side):
                dx = (j - half_cells) * step
                tot = 0.0
                ok = True
                for t in range(npts):
                    ue = pe[t] - pivot_e
                    un = pn[t] - pivot_n
                    h = bilinear(z, e0, n0, inv_re, inv_rn, pivot_e + c * ue - s * un + dx,
                                 pivot_n + s * ue + c * un + dy)
                    if h != h:
                        ok = False
                        break
                    r[t] = ph[t] - h
                    tot += r[t]
                if not ok or npts == 0:
                    msd_out[d, i, j] = np.inf
                    mad_out[d, i, j] = np.inf
                    continue
                mean = tot / npts
                sq = 0.0
                ab = 0.0
                for t in range(npts):
                    v = r[t] - mean
                    sq += v * v
                    ab += abs(v)
                msd_out[d, i, j] = sq / npts
                mad_out[d, i, j] = ab / npts


def profile_surface_numpy(pe, pn, ph, pivot_e, pivot_n, half_cells, step, deltas, zmap):
    """Plain-numpy reference of :func:`profile_surface`: returns (msd, mad)."""
    off = (np.arange(2 * half_cells + 1) - half_cells) * step
    dx, dy = np.meshgrid(off, off)  # [i, j] -> (dx_j, dy_i)
    msd = np.empty((len(deltas),) + dx.shape)
    mad = np.empty_like(msd)
    for d, delta in enumerate(deltas):
        c, s = math.cos(delta), math.sin(delta)
        ue, un = pe - pivot_e, pn - pivot_n
        qe = pivot_e + c * ue - s * un + dx[..., None]
        qn = pivot_n + s * ue + c * un + dy[..., None]
        r = ph - bilinear_numpy(*zmap, qe, qn)
        r = r - r.mean(axis=-1, keepdims=True)
        bad = np.isnan(r).any(axis=-1)
        msd[d] = np.where(bad, np.inf, (r**2).mean(axis=-1))
        mad[d] = np.where(bad, np.inf, np.abs(r).mean(axis=-1))
    return msd, mad


@nb.njit(cache=True)
def surface_likelihood_sums(msd, deltas, half_cells, step, pings, sig_u, mn):
    """Sums of the likelihood w = exp(-pings (msd - mn) / (2 sig_u^2)) over the surface's finite candidates:
    (sum w, of w dx, w dy, w dx^2, w dy^2, w delta, w delta^2), (dx, dy) each candidate's offset from the
    surface's centre (m)."""
    tot = 0.0
    sx = sy = sxx = syy = sd = sdd = 0.0
    for d in range(msd.shape[0]):
        for i in range(msd.shape[1]):
            dy = (i - half_cells) * step
            for j in range(msd.shape[2]):
                v = msd[d, i, j]
                if v == np.inf:
                    continue
                dx = (j - half_cells) * step
                w = math.exp(-0.5 * pings * (v - mn) / (sig_u * sig_u))
                tot += w
                sx += w * dx
                sy += w * dy
                sxx += w * dx * dx
                syy += w * dy * dy
                sd += w * deltas[d]
                sdd += w * deltas[d] * deltas[d]
    return tot, sx, sy, sxx, syy, sd, sdd


@nb.njit(cache=True)
def surface_likelihood_moments(msd, deltas, half_cells, step, pings, sig_u):
    """Likelihood exp(-pings (msd - min) / (2 sig_u^2)) over the surface: its
    (mean dx, mean dy, var dx, var dy, mean delta, var delta)."""
    tot, sx, sy, sxx, syy, sd, sdd = surface_likelihood_sums(msd, deltas, half_cells, step, pings, sig_u,
                                                             _best(msd)[0])
    if tot <= 0.0:
        return 0.0, 0.0, np.inf, np.inf, 0.0, np.inf
    mx = sx / tot
    my = sy / tot
    md = sd / tot
    return mx, my, max(sxx / tot - mx * mx, 0.0), max(syy / tot - my * my, 0.0), md, max(sdd / tot - md * md, 0.0)


def surface_likelihood_moments_numpy(msd, deltas, half_cells, step, pings, sig_u):
    off = (np.arange(2 * half_cells + 1) - half_cells) * step
    dx, dy = np.meshgrid(off, off)
    ok = np.isfinite(msd)
    if not ok.any():
        return 0.0, 0.0, np.inf, np.inf, 0.0, np.inf
    w = np.where(ok, np.exp(-0.5 * pings * (np.where(ok, msd, 0) - msd[ok].min()) / sig_u**2), 0.0)
    w = w / w.sum()
    dd = np.broadcast_to(np.asarray(deltas)[:, None, None], msd.shape)
    mx, my, md = (w * dx).sum(), (w * dy).sum(), (w * dd).sum()
    return (mx, my, (w * dx**2).sum() - mx**2, (w * dy**2).sum() - my**2, md, (w * dd**2).sum() - md**2)


@nb.njit(cache=True)
def _best(surface):
    b = np.inf
    bd = bi = bj = 0
    for d in range(surface.shape[0]):
        for i in range(surface.shape[1]):
            for j in range(surface.shape[2]):
                if surface[d, i, j] < b:
                    b = surface[d, i, j]
                    bd, bi, bj = d, i, j
    return b, bd, bi, bj


def best_numpy(surface):
    """Plain-numpy reference of :func:`_best`: (the smallest value, its index d, i, j), the first in C order;
    (inf, 0, 0, 0) when no value is below inf (NaN passed over)."""
    flat = np.asarray(surface, dtype=float).ravel()
    flat = np.where(np.isnan(flat), np.inf, flat)
    at = int(np.argmin(flat))
    if not flat[at] < np.inf:
        return np.inf, 0, 0, 0
    d, i, j = np.unravel_index(at, np.shape(surface))
    return float(flat[at]), int(d), int(i), int(j)


@nb.njit(cache=True)
def _collect(buf_e, buf_n, buf_h, count, pe, pn, ph):
    """Valid profile points of the ring buffer (rows of beams) into pe, pn, ph; returns their number."""
    npts = 0
    for k in range(count):
        for i in range(buf_e.shape[1]):
            if buf_h[k, i] == buf_h[k, i]:
                pe[npts] = buf_e[k, i]
                pn[npts] = buf_n[k, i]
                ph[npts] = buf_h[k, i]
                npts += 1
    return npts


def collect_numpy(buf_e, buf_n, buf_h, count):
    """Plain-numpy reference of :func:`_collect`: the profile points (pe, pn, ph) of the buffers' first
    ``count`` rows whose height is not NaN, row by row."""
    ok = ~np.isnan(buf_h[:count])
    return buf_e[:count][ok], buf_n[:count][ok], buf_h[:count][ok]


@nb.njit(cache=True)
def tercom_loop(d0, offsets, nav_up, start_e, start_n, zmap, settings, out):
    """Run TERCOM over K updates from the navigation's displacements ``d0`` (K-1, 2), up (K,) and
    start; ``zmap`` the map's ``MapArgs``; ``settings`` a :class:`TercomSettings`; fills ``out``
    (:class:`TercomOutputs`): ``est`` (K, 3) (east, north, heading correction), ``var`` (K, 3),
    ``fixes`` (K,) (1 where a fix was accepted)."""
    _, _, _, inv_re, inv_rn = zmap
    (profile_len, interval, metric, headings, window_max, fix_std, var0_pos, var0_heading, q_pos, q_heading, sig_u,
     div_sigma) = settings
    est, var, fixes = out
    steps = offsets.shape[0]
    m = offsets.shape[1]
    res = 1.0 / min(inv_re, inv_rn)
    buf_e = np.full((profile_len, m), np.nan)
    buf_n = np.full((profile_len, m), np.nan)
    buf_h = np.full((profile_len, m), np.nan)
    pe = np.empty(profile_len * m)
    pn = np.empty(profile_len * m)
    ph = np.empty(profile_len * m)
    pc_e = start_e
    pc_n = start_n
    dc = 0.0
    p_pos = var0_pos
    p_fix = var0_pos
    p_walk = 0.0
    fix_e = start_e
    fix_n = start_n
    p_head = var0_heading
    count = 0
    consistent = (0.5 * div_sigma) ** 2 * sig_u * sig_u
    for k in range(steps):
        if k > 0:
            c = math.cos(dc)
            s = math.sin(dc)
            pc_e += c * d0[k - 1, 0] - s * d0[k - 1, 1]
            pc_n += s * d0[k - 1, 0] + c * d0[k - 1, 1]
            p_walk += q_pos
            p_head += q_heading
            # a heading error rotates the whole track since the fix about the fix's position
            p_pos = p_fix + p_walk + p_head * ((pc_e - fix_e) ** 2 + (pc_n - fix_n) ** 2)
        # append this update's footprints to the profile (oldest row dropped)
        for r in range(profile_len - 1):
            for i in range(m):
                buf_e[r, i] = buf_e[r + 1, i]
                buf_n[r, i] = buf_n[r + 1, i]
                buf_h[r, i] = buf_h[r + 1, i]
        c = math.cos(dc)
        s = math.sin(dc)
        last = profile_len - 1
        for i in range(m):
            oe = offsets[k, i, 0]
            on = offsets[k, i, 1]
            buf_e[last, i] = pc_e + c * oe - s * on
            buf_n[last, i] = pc_n + s * oe + c * on
            buf_h[last, i] = nav_up[k] + offsets[k, i, 2]
        count = min(count + 1, profile_len)
        fixes[k] = 0
        if count == profile_len and k % interval == 0:
            npts = _collect(buf_e, buf_n, buf_h, count, pe, pn, ph)
            if npts >= profile_len:
                sig_pos = math.sqrt(p_pos)
                window = min(max(3.0 * sig_pos, 3.0 * res), window_max)
                half = int(math.ceil(window / res))
                sig_h = math.sqrt(p_head)
                span = min(2.0 * sig_h, math.radians(45.0))
                deltas = np.zeros(1)
                if headings > 1:
                    deltas = np.linspace(-span, span, headings)
                side = 2 * half + 1
                msd = np.empty((deltas.shape[0], side, side))
                mad = np.empty((deltas.shape[0], side, side))
                profile_surface(pe[:npts], pn[:npts], ph[:npts], pc_e, pc_n, half, res, deltas, zmap, msd, mad)
                score = msd if metric == MSD else mad
                best, bd, bi, bj = _best(score)
                cm = surface_likelihood_moments(msd, deltas, half, res, count, sig_u)
                ambiguous = max(cm[2], cm[3]) > fix_std * fix_std
                edge = bi == 0 or bj == 0 or bi == side - 1 or bj == side - 1
                if best < np.inf and not ambiguous and not edge:
                    # fine search around the best coarse candidate
                    dstep = deltas[1] - deltas[0] if deltas.shape[0] > 1 else 0.0
                    fd = np.array([deltas[bd] - 0.5 * dstep, deltas[bd], deltas[bd] + 0.5 * dstep])
                    if headings <= 1:
                        fd = np.zeros(1)
                    fstep = res / 5.0
                    fh = 5
                    cx = (bj - half) * res
                    cy = (bi - half) * res
                    fsd = np.empty((fd.shape[0], 2 * fh + 1, 2 * fh + 1))
                    fad = np.empty((fd.shape[0], 2 * fh + 1, 2 * fh + 1))
                    profile_surface(pe[:npts] + cx, pn[:npts] + cy, ph[:npts], pc_e + cx, pc_n + cy, fh, fstep,
                                    fd, zmap, fsd, fad)
                    fbest, fbd, fbi, fbj = _best(fsd if metric == MSD else fad)
                    fm = surface_likelihood_moments(fsd, fd, fh, fstep, count, sig_u)
                    if fsd[fbd, fbi, fbj] < consistent:
                        tx = cx + (fbj - fh) * fstep
                        ty = cy + (fbi - fh) * fstep
                        dd = fd[fbd]
                        # move the corrected solution and its profile with the fix
                        cr = math.cos(dd)
                        sr = math.sin(dd)
                        for r in range(profile_len):
                            for i in range(m):
                                ue = buf_e[r, i] - pc_e
                                un = buf_n[r, i] - pc_n
                                buf_e[r, i] = pc_e + cr * ue - sr * un + tx
                                buf_n[r, i] = pc_n + sr * ue + cr * un + ty
                        pc_e += tx
                        pc_n += ty
                        dc += dd
                        p_fix = max(fm[2], fm[3]) + fstep * fstep / 12.0
                        p_pos = p_fix
                        p_walk = 0.0
                        fix_e = pc_e
                        fix_n = pc_n
                        if headings > 1:
                            p_head = min(p_head, max(cm[5], dstep * dstep / 12.0))
                        fixes[k] = 1
        est[k, 0] = pc_e
        est[k, 1] = pc_n
        est[k, 2] = dc
        var[k, 0] = p_pos
        var[k, 1] = p_pos
        var[k, 2] = p_head


# TERCOM's settings (profile length and match interval in updates, metric code, heading candidates,
# largest window half-width, fix std threshold, initial position and heading variances, their
# process noise per update, altitude std, divergence sigma) and its outputs
TercomSettings = namedtuple("TercomSettings", "profile_len interval metric headings window_max fix_std var0_pos "
                                              "var0_heading q_pos q_heading sig_u div_sigma")
TercomOutputs = namedtuple("TercomOutputs", "est var fixes")


def tercom_settings(scenario, options) -> TercomSettings:
    """TERCOM's settings from the scenario and the method's options (``methods/tercom.py:TercomOptions``)."""
    f = scenario.filter
    return TercomSettings(int(options.profile_pings), int(options.interval), METRICS[options.metric],
                          int(options.headings), float(options.window_max_m), float(options.fix_std_m),
                          f.initial_area_m**2 / 12.0, f.initial_std_heading_rad ** 2, scenario.position_noise_m()**2,
                          math.radians(options.heading_drift_deg_sqrt_s) ** 2 * scenario.sampling_time_s,
                          scenario.range_sigma_m, f.divergence_sigma)


def run_tercom(nav, beams, ranges, zargs, settings: TercomSettings) -> dict:
    """TERCOM on plain arrays (``nav`` the navigation solution at the K updates,
    :class:`~tanbench.navigation.increments.NavAtUpdates`; beams, ranges, the map's kernel args).

    Deterministic. Returns the corrected navigation solution per update, its variances and
    where fixes were taken.
    """
    nav_en = np.asarray(nav.en, dtype=float)
    offsets = nav_frame_offsets(nav.pitch, nav.roll, nav.yaw, beams, ranges)
    k_steps = offsets.shape[0]
    est = np.empty((k_steps, 3))
    var = np.empty((k_steps, 3))
    fixes = np.zeros(k_steps, dtype=np.int64)
    tercom_loop(np.ascontiguousarray(np.diff(nav_en, axis=0)), offsets, np.ascontiguousarray(nav.up, dtype=float),
                nav_en[0, 0], nav_en[0, 1], MapArgs(*zargs), settings, TercomOutputs(est, var, fixes))
    return {"est_e": est[:, 0], "est_n": est[:, 1], "est_yaw": np.asarray(nav.yaw) + est[:, 2],
            "var_e": var[:, 0], "var_n": var[:, 1], "var_yaw": var[:, 2], "fixes": fixes}
