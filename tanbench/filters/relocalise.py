"""Global re-localisation of a diverged tight filter by a batch terrain match (``filter.recovery: global``).

When a tight filter is declared diverged (``filters/tight.py``; from its own innovations and
spread, never from the truth) the built-in re-draws the cloud around the filter's own estimate,
which by then may have followed a wrong path far from the vehicle (docs/filters.md 8). With
``filter.recovery: global`` the loop first asks where the vehicle is by matching the filter's
own last ``filter.recovery_profile_updates`` updates of terrain measurements against the map:

* the profile: every beam's footprint of those updates, placed by the navigation solution's
  relative track between them (its displacements, ``navigation/increments.py``) plus the beam
  vector times the measured range turned into the navigation frame with the navigation
  attitude (``filters/beams.py``), with the measured bottom height (the navigation's up, i.e.
  the pressure depth, plus the beam's vertical part): what the vehicle observes, relative to
  its position at the current update (all the updates so far while the run is younger than
  the profile);
* the search: that profile rotated about the current position by headings within
  +-``filter.recovery_heading_span_deg`` of the navigation heading, in steps of
  ``filter.recovery_heading_step_deg``, and translated over a square of half side
  ``filter.recovery_max_side_m`` / 2 around the filter's estimate in steps of the map spacing,
  scored by TERCOM's mean-removed MSD (``filters/tercom.py``: :func:`profile_surface`), then
  refined around the best candidate at a fifth of the spacing and half the heading step;
* the answer is refused (the built-in re-draw then applies) when fewer than ``MIN_UPDATES``
  updates (or the profile's length, if shorter) have been made (too early in the run), when
  the best candidate sits on the search square's edge or at either end of the headings searched
  (the vehicle may be beyond them), or when the match is ambiguous (TERCOM's
  test: the MSD surface turned into a likelihood has a position std above
  ``filter.recovery_fix_std_m``; :func:`tanbench.filters.tercom.surface_likelihood_moments`).

An accepted match gives the position at the current update and the heading correction delta:
the loop re-draws the cloud in the usual uniform square of ``reinit_half_side`` around that
position, with headings about the navigation heading plus delta.

The kernels take plain arrays; each has a plain-numpy reference below it.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters.beams import nav_frame_offsets
from tanbench.filters.tercom import (_best, profile_surface, profile_surface_numpy, surface_likelihood_moments,
                                     surface_likelihood_moments_numpy, surface_likelihood_sums)
from tanbench.navigation.increments import D0E, D0N
from tanbench.terrain.grid import MapArgs

# the spec's side of the search (Python only): profile length in updates, half side of the
# translation square (m), heading span and step (rad), the ambiguity test's std (m), the
# navigation solution's east and north at the updates (K, 2) when a refused match around the
# estimate is tried again around it (``filter.recovery_search_around``), else None, whether
# only a navigation solution outside the first square is searched around, and whether the second
# square's ambiguity test weighs both squares' candidates (``filter.recovery_second_ambiguity``)
GlobalSearch = namedtuple("GlobalSearch", "window half_side span step fix_std nav_en distant_only both_squares")

# what the jitted loop takes: the beams' navigation-frame vectors times ranges at every update
# (K, m, 3; NaN without a range), the map (``MapArgs``), the heading candidates (D,), the search
# square's half side in cells and its cell (m), the profile length, the altitude std of the
# ambiguity test's likelihood and its position std threshold, the second search's centres at
# the updates (K, 2; no rows: no second search), the least offset (m, on either axis) of a
# centre from the estimate for it to be searched (0: always; the square's half side: outside it),
# and whether a second square's match must also be unambiguous over the first square's candidates
Relocalise = namedtuple("Relocalise", "offsets zmap deltas half_cells step window sig_u fix_std nav_en nav_min_offset "
                                      "both_squares")

# refinement around the best coarse candidate: +-FINE_CELLS steps of a fifth of the map spacing (as TERCOM's)
FINE_CELLS = 5
FINE_DIVISOR = 5.0
# the coarse search steps one map cell when its step times the cells per metre is 1 within this
ALIGNED_TOL = 1e-12
# a profile shorter than this many updates (early in a run) is not matched
MIN_UPDATES = 120


def global_search_of(f, nav_en=None):
    """The :class:`GlobalSearch` of a ``FilterSpec`` with ``recovery: global``, else None (the loop
    then compiles without the search). ``nav_en``: the navigation solution's east and north at the
    updates (K, 2), kept when ``f.recovery_search_around`` asks for the second search around it."""
    if f.recovery != "global":
        return None
    second = f.recovery_search_around != "estimate" and nav_en is not None
    return GlobalSearch(int(f.recovery_profile_updates), f.recovery_max_side_m / 2.0,
                        math.radians(f.recovery_heading_span_deg), math.radians(f.recovery_heading_step_deg),
                        float(f.recovery_fix_std_m), np.ascontiguousarray(nav_en, dtype=np.float64) if second else None,
                        f.recovery_search_around == "estimate-then-distant-navigation",
                        f.recovery_second_ambiguity == "both-squares")


def heading_candidates(span, step) -> np.ndarray:
    """Headings -span..+span in steps of ``step`` (rad), symmetric about 0 and holding 0."""
    half = int(math.floor(span / step + 1e-9)) if step > 0 else 0
    return np.arange(-half, half + 1, dtype=np.float64) * step


def map_of_grid(grid) -> MapArgs:
    """The heights of a filter's ``NodeGrid`` as ``MapArgs`` (the first of its interleaved grids)."""
    z = np.ascontiguousarray(np.asarray(grid.nodes).reshape(grid.ny, grid.nx, grid.grids)[:, :, 0])
    return MapArgs(z, float(grid.e0), float(grid.n0), float(grid.inv_re), float(grid.inv_rn))


def relocaliser(search: GlobalSearch, track, beams, ranges, grid, sig_u: float) -> Relocalise:
    """The loop's :class:`Relocalise` bundle from the search settings, the navigation solution at the
    updates (``TightTrack``: pitch, roll, yaw), the beams and measured ranges, and the filter's map."""
    offsets = nav_frame_offsets(track.pitch, track.roll, track.yaw, beams, ranges)
    zmap = map_of_grid(grid)
    res = 1.0 / min(zmap.inv_re, zmap.inv_rn)
    nav_en = search.nav_en if search.nav_en is not None else np.empty((0, 2))
    half_cells = int(math.ceil(search.half_side / res))
    return Relocalise(offsets, zmap, heading_candidates(search.span, search.step), half_cells, float(res),
                      int(search.window), float(sig_u), float(search.fix_std), nav_en,
                      half_cells * float(res) if search.distant_only else 0.0, bool(search.both_squares))


@nb.njit(cache=True)
def relative_profile(inc, offsets, up, k, window, pe, pn, ph):
    """The profile of updates max(0, k - window + 1)..k into ``pe, pn, ph``: each beam's footprint
    relative to the navigation position at update ``k`` (the navigation displacements ``inc[:, D0E:D0N+1]``
    between the updates plus the beam's navigation-frame vector ``offsets[j, b, :2]``) and its measured
    bottom height ``up[j] + offsets[j, b, 2]``; beams without a range are left out. Newest first.
    Returns the number of points."""
    npts = 0
    re = 0.0
    rn = 0.0
    j0 = max(0, k - window + 1)
    for j in range(k, j0 - 1, -1):
        if j < k:
            re -= inc[j, D0E]
            rn -= inc[j, D0N]
        for b in range(offsets.shape[1]):
            h = offsets[j, b, 2]
            if h == h:
                pe[npts] = re + offsets[j, b, 0]
                pn[npts] = rn + offsets[j, b, 1]
                ph[npts] = up[j] + h
                npts += 1
    return npts


def relative_profile_numpy(inc, offsets, up, k, window):
    """Plain-numpy reference of :func:`relative_profile`: (pe, pn, ph) in the same order."""
    j0 = max(0, k - window + 1)
    js = np.arange(k, j0 - 1, -1)
    # position of update j relative to update k: minus the displacements j..k-1
    back = np.concatenate([[0.0], np.cumsum(inc[js[1:], D0E])])
    bn = np.concatenate([[0.0], np.cumsum(inc[js[1:], D0N])])
    pe = -back[:, None] + offsets[js, :, 0]
    pn = -bn[:, None] + offsets[js, :, 1]
    ph = up[js][:, None] + offsets[js, :, 2]
    ok = ~np.isnan(offsets[js, :, 2])
    return pe[ok], pn[ok], ph[ok]


@nb.njit(cache=True)
def aligned_msd_surface(pe, pn, ph, pivot_e, pivot_n, half_cells, deltas, zmap, msd_out):
    """TERCOM's demeaned MSD surface (:func:`tanbench.filters.tercom.profile_surface`, without the MAD)
    for a search whose translations step one map cell on both axes (square cells, ``step`` the spacing).

    A translation by whole cells moves every profile point to the same place in another cell: its
    bilinear weights are those at no translation, so each point's cell and weights are found once per
    heading, and the candidates of one row of translations read one row of map cells in order (a loop
    the compiler vectorises). The mean-removed MSD is sum r^2 / n - (sum r / n)^2 of the residuals
    r = measured - map height; equal to ``profile_surface``'s up to rounding (the numpy reference
    ``profile_surface_numpy`` is checked against it). +inf where a point is off the map (its
    cell not wholly on the grid: a point exactly on the grid's last node line counts as off) or the
    map has no height there (NaN)."""
    z, e0, n0, inv_re, inv_rn = zmap
    ny, nx = z.shape
    npts = pe.shape[0]
    side = 2 * half_cells + 1
    s1 = np.empty((side, side))
    s2 = np.empty((side, side))
    cols = np.empty(npts, dtype=np.int64)
    rows = np.empty(npts, dtype=np.int64)
    w = np.empty((npts, 4))
    for d in range(deltas.shape[0]):
        c = math.cos(deltas[d])
        s = math.sin(deltas[d])
        msd_out[d] = np.inf
        # each point's cell and weights at no translation; the candidates whose cells are all on the
        # grid (columns and rows 0..n-2) form a rectangle: the intersection of every point's
        i_lo, i_hi, j_lo, j_hi = 0, side - 1, 0, side - 1
        for t in range(npts):
            ue = pe[t] - pivot_e
            un = pn[t] - pivot_n
            fx = (pivot_e + c * ue - s * un - e0) * inv_re
            fy = (pivot_n + s * ue + c * un - n0) * inv_rn
            if not (abs(fx) < 1e15 and abs(fy) < 1e15):  # NaN or far off
                i_lo, i_hi = side, -1
                continue
            jx = math.floor(fx)
            iy = math.floor(fy)
            tx = fx - jx
            ty = fy - iy
            cols[t] = int(jx) - half_cells
            rows[t] = int(iy) - half_cells
            w[t, 0] = (1.0 - tx) * (1.0 - ty)
            w[t, 1] = tx * (1.0 - ty)
            w[t, 2] = (1.0 - tx) * ty
            w[t, 3] = tx * ty
            j_lo = max(j_lo, -cols[t])
            j_hi = min(j_hi, nx - 2 - cols[t])
            i_lo = max(i_lo, -rows[t])
            i_hi = min(i_hi, ny - 2 - rows[t])
        if npts == 0 or i_lo > i_hi or j_lo > j_hi:
            continue
        s1[:] = 0.0
        s2[:] = 0.0
        for t in range(npts):
            h_t = ph[t]
            w00, w01, w10, w11 = w[t, 0], w[t, 1], w[t, 2], w[t, 3]
            first = cols[t] + j_lo
            width = j_hi - j_lo + 1
            for i in range(i_lo, i_hi + 1):
                # views starting at the first candidate's cell: the inner loop's indices are 0.. (no
                # negative-index wrap for the compiler to test), so it vectorises
                z0 = z[rows[t] + i, first:first + width + 1]
                z1 = z[rows[t] + i + 1, first:first + width + 1]
                a1 = s1[i, j_lo:j_lo + width]
                a2 = s2[i, j_lo:j_lo + width]
                for q in range(width):
                    r = h_t - (w00 * z0[q] + w01 * z0[q + 1] + w10 * z1[q] + w11 * z1[q + 1])
                    a1[q] += r
                    a2[q] += r * r
        for i in range(i_lo, i_hi + 1):
            for j in range(j_lo, j_hi + 1):
                mean = s1[i, j] / npts
                v = s2[i, j] / npts - mean * mean
                if v == v:
                    msd_out[d, i, j] = max(v, 0.0)


@nb.njit(cache=True)
def coarse_surface(ae, an, ph, centre_e, centre_n, half, step, deltas, zmap, msd):
    """The coarse search's MSD surface: :func:`aligned_msd_surface` when the translations step one map
    cell on both axes, else TERCOM's :func:`profile_surface` (which also fills a MAD surface)."""
    if zmap.inv_re == zmap.inv_rn and abs(step * zmap.inv_re - 1.0) < ALIGNED_TOL:
        aligned_msd_surface(ae, an, ph, centre_e, centre_n, half, deltas, zmap, msd)
    else:
        profile_surface(ae, an, ph, centre_e, centre_n, half, step, deltas, zmap, msd, np.empty_like(msd))


@nb.njit(cache=True)
def global_match(pe, pn, ph, centre_e, centre_n, pings, reloc):
    """Match the relative profile (``pe, pn, ph``, about the origin = the current position) over
    the search square around (``centre_e``, ``centre_n``) and the heading candidates; ``pings`` the
    updates it holds (the ambiguity test's independent observations).

    Returns (found, east, north, delta): the current position and heading correction of the best
    match, ``found`` False (and the centre, 0) when nothing on the map matched, the best coarse
    candidate is on the square's edge or at either end of the heading candidates, or the match
    is ambiguous."""
    return decide_match(pe, pn, ph, centre_e, centre_n, pings, reloc, match_surface(pe, pn, ph, centre_e, centre_n, reloc))


@nb.njit(cache=True)
def match_surface(pe, pn, ph, centre_e, centre_n, reloc):
    """The coarse MSD surface (headings, rows, columns) of the relative profile over the search square
    around (``centre_e``, ``centre_n``): :func:`coarse_surface`."""
    half = reloc.half_cells
    side = 2 * half + 1
    msd = np.empty((reloc.deltas.shape[0], side, side))
    coarse_surface(pe + centre_e, pn + centre_n, ph, centre_e, centre_n, half, reloc.step, reloc.deltas, reloc.zmap,
                   msd)
    return msd


@nb.njit(cache=True)
def decide_match(pe, pn, ph, centre_e, centre_n, pings, reloc, msd):
    """:func:`global_match`'s tests and refinement on its coarse surface ``msd`` (:func:`match_surface`)."""
    deltas = reloc.deltas
    half = reloc.half_cells
    step = reloc.step
    side = 2 * half + 1
    ae = pe + centre_e
    an = pn + centre_n
    best, bd, bi, bj = _best(msd)
    if best == np.inf:
        return False, centre_e, centre_n, 0.0
    if bi == 0 or bj == 0 or bi == side - 1 or bj == side - 1:
        return False, centre_e, centre_n, 0.0
    if deltas.shape[0] > 1 and (bd == 0 or bd == deltas.shape[0] - 1):
        return False, centre_e, centre_n, 0.0
    cm = surface_likelihood_moments(msd, deltas, half, step, pings, reloc.sig_u)
    if max(cm[2], cm[3]) > reloc.fix_std * reloc.fix_std:
        return False, centre_e, centre_n, 0.0
    # refine around the best coarse candidate (position and heading)
    dstep = deltas[1] - deltas[0] if deltas.shape[0] > 1 else 0.0
    fd = np.array([deltas[bd] - 0.5 * dstep, deltas[bd], deltas[bd] + 0.5 * dstep])
    if deltas.shape[0] <= 1:
        fd = np.full(1, deltas[bd])
    cx = (bj - half) * step
    cy = (bi - half) * step
    fstep = step / FINE_DIVISOR
    fside = 2 * FINE_CELLS + 1
    fsd = np.empty((fd.shape[0], fside, fside))
    fad = np.empty((fd.shape[0], fside, fside))
    profile_surface(ae + cx, an + cy, ph, centre_e + cx, centre_n + cy, FINE_CELLS, fstep, fd, reloc.zmap, fsd, fad)
    _, fbd, fbi, fbj = _best(fsd)
    return (True, centre_e + cx + (fbj - FINE_CELLS) * fstep, centre_n + cy + (fbi - FINE_CELLS) * fstep, fd[fbd])


def global_match_numpy(pe, pn, ph, centre_e, centre_n, pings, reloc):
    """Plain-numpy reference of :func:`global_match` (on TERCOM's numpy references)."""
    return decide_match_numpy(pe, pn, ph, centre_e, centre_n, pings, reloc,
                              match_surface_numpy(pe, pn, ph, centre_e, centre_n, reloc))


def match_surface_numpy(pe, pn, ph, centre_e, centre_n, reloc):
    """Plain-numpy reference of :func:`match_surface` (TERCOM's ``profile_surface_numpy``)."""
    return profile_surface_numpy(np.asarray(pe) + centre_e, np.asarray(pn) + centre_n, ph, centre_e, centre_n,
                                 reloc.half_cells, reloc.step, np.asarray(reloc.deltas), reloc.zmap)[0]


def decide_match_numpy(pe, pn, ph, centre_e, centre_n, pings, reloc, msd):
    """Plain-numpy reference of :func:`decide_match`."""
    deltas, half, step = np.asarray(reloc.deltas), reloc.half_cells, reloc.step
    side = 2 * half + 1
    ae, an = np.asarray(pe) + centre_e, np.asarray(pn) + centre_n
    bd, bi, bj = np.unravel_index(np.argmin(msd), msd.shape)
    if not np.isfinite(msd[bd, bi, bj]) or bi in (0, side - 1) or bj in (0, side - 1):
        return False, centre_e, centre_n, 0.0
    if len(deltas) > 1 and bd in (0, len(deltas) - 1):
        return False, centre_e, centre_n, 0.0
    cm = surface_likelihood_moments_numpy(msd, deltas, half, step, pings, reloc.sig_u)
    if max(cm[2], cm[3]) > reloc.fix_std**2:
        return False, centre_e, centre_n, 0.0
    dstep = deltas[1] - deltas[0] if len(deltas) > 1 else 0.0
    fd = np.array([deltas[bd] - 0.5 * dstep, deltas[bd], deltas[bd] + 0.5 * dstep]) if len(deltas) > 1 else deltas[bd:bd + 1]
    cx, cy = (bj - half) * step, (bi - half) * step
    fstep = step / FINE_DIVISOR
    fsd, _ = profile_surface_numpy(ae + cx, an + cy, ph, centre_e + cx, centre_n + cy, FINE_CELLS, fstep, fd, reloc.zmap)
    fbd, fbi, fbj = np.unravel_index(np.argmin(fsd), fsd.shape)
    return True, centre_e + cx + (fbj - FINE_CELLS) * fstep, centre_n + cy + (fbi - FINE_CELLS) * fstep, fd[fbd]


@nb.njit(cache=True)
def relocalise(inc, up, k, centre_e, centre_n, reloc):
    """Where the vehicle is at update ``k`` by the profile of its last ``reloc.window`` updates, or
    of all its updates so far if fewer (:func:`relative_profile`, :func:`global_match` around the
    estimate ``centre_*``).

    Returns (found, east, north, delta); not found with fewer than ``min(MIN_UPDATES, window)``
    updates so far, or fewer points than half the profile's updates (dropouts)."""
    pe, pn, ph, pings = match_profile(inc, up, k, reloc)
    if pings == 0:
        return False, centre_e, centre_n, 0.0
    return global_match(pe, pn, ph, centre_e, centre_n, pings, reloc)


@nb.njit(cache=True)
def match_profile(inc, up, k, reloc):
    """The profile :func:`relocalise` matches at update ``k`` (:func:`relative_profile`) and its pings (the
    ambiguity test's independent observations); 0 pings when it is not matched: fewer than
    ``min(MIN_UPDATES, window)`` updates so far, or fewer points than half the profile's updates."""
    updates = min(k + 1, reloc.window)
    cap = updates * reloc.offsets.shape[1]
    pe = np.empty(cap)
    pn = np.empty(cap)
    ph = np.empty(cap)
    if updates < min(MIN_UPDATES, reloc.window):
        return pe[:0], pn[:0], ph[:0], 0
    npts = relative_profile(inc, reloc.offsets, up, k, updates, pe, pn, ph)
    if 2 * npts < updates:
        return pe[:0], pn[:0], ph[:0], 0
    return pe[:npts], pn[:npts], ph[:npts], min(npts, updates)


@nb.njit(cache=True)
def relocalise_around(inc, up, k, est_e, est_n, reloc):
    """:func:`relocalise` around the diverged filter's estimate; when that match is refused and
    ``reloc.nav_en`` holds the navigation solution at update ``k``, again around it (a filter that
    followed a wrong path may have left the vehicle farther behind than half the square, while the
    navigation solution drifts only with its own errors; docs/filters.md 17), if it lies at least
    ``reloc.nav_min_offset`` from the estimate on either axis (section 18: outside the first square).
    Same returns."""
    pe, pn, ph, pings = match_profile(inc, up, k, reloc)
    if pings == 0:
        return False, est_e, est_n, 0.0
    first = match_surface(pe, pn, ph, est_e, est_n, reloc)
    found, east, north, delta = decide_match(pe, pn, ph, est_e, est_n, pings, reloc, first)
    if found or k >= reloc.nav_en.shape[0]:
        return found, east, north, delta
    nav_e, nav_n = reloc.nav_en[k, 0], reloc.nav_en[k, 1]
    if max(abs(nav_e - est_e), abs(nav_n - est_n)) < reloc.nav_min_offset:
        return found, east, north, delta
    second = match_surface(pe, pn, ph, nav_e, nav_n, reloc)
    answer = decide_match(pe, pn, ph, nav_e, nav_n, pings, reloc, second)
    if answer[0] and reloc.both_squares and both_squares_std(first, est_e, est_n, second, nav_e, nav_n, reloc.deltas,
                                                             reloc.half_cells, reloc.step, pings,
                                                             reloc.sig_u) > reloc.fix_std:
        return False, nav_e, nav_n, 0.0
    return answer


@nb.njit(cache=True)
def both_squares_std(first, e1, n1, second, e2, n2, deltas, half_cells, step, pings, sig_u):
    """TERCOM's ambiguity statistic over two searched squares: the larger position std (m, east or north) of
    the likelihood exp(-pings (msd - min) / (2 sig_u^2)) (:func:`~tanbench.filters.tercom.surface_likelihood_sums`)
    over the candidates of the coarse surface ``first`` (centred on ``e1``, ``n1``) and those of ``second``
    (centred on ``e2``, ``n2``) outside the first square; positions relative to the second centre."""
    edge = half_cells * step
    mn = min(_best(first)[0], _best(second)[0])
    outside = second.copy()
    for i in range(outside.shape[1]):
        for j in range(outside.shape[2]):
            if abs(e2 + (j - half_cells) * step - e1) <= edge and abs(n2 + (i - half_cells) * step - n1) <= edge:
                outside[:, i, j] = np.inf
    t1, x1, y1, xx1, yy1, _, _ = surface_likelihood_sums(first, deltas, half_cells, step, pings, sig_u, mn)
    t2, x2, y2, xx2, yy2, _, _ = surface_likelihood_sums(outside, deltas, half_cells, step, pings, sig_u, mn)
    ce, cn = e1 - e2, n1 - n2  # the first square's offsets moved to the second centre
    tot = t1 + t2
    if tot <= 0.0:
        return np.inf
    mx = (x1 + ce * t1 + x2) / tot
    my = (y1 + cn * t1 + y2) / tot
    vx = (xx1 + 2.0 * ce * x1 + ce * ce * t1 + xx2) / tot - mx * mx
    vy = (yy1 + 2.0 * cn * y1 + cn * cn * t1 + yy2) / tot - my * my
    return math.sqrt(max(vx, vy, 0.0))


def both_squares_std_numpy(first, e1, n1, second, e2, n2, half_cells, step, pings, sig_u):
    """Plain-numpy reference of :func:`both_squares_std`."""
    off = (np.arange(2 * half_cells + 1) - half_cells) * step
    xs, ys, vs = [], [], []
    for msd, ce, cn, drop in ((first, e1 - e2, n1 - n2, False), (second, 0.0, 0.0, True)):
        dx, dy = np.meshgrid(ce + off, cn + off)
        dx = np.broadcast_to(dx, msd.shape)
        dy = np.broadcast_to(dy, msd.shape)
        keep = np.isfinite(msd)
        if drop:
            keep &= ~((np.abs(dx + e2 - e1) <= half_cells * step) & (np.abs(dy + n2 - n1) <= half_cells * step))
        xs.append(dx[keep])
        ys.append(dy[keep])
        vs.append(msd[keep])
    x, y, v = np.concatenate(xs), np.concatenate(ys), np.concatenate(vs)
    if v.size == 0:
        return np.inf
    w = np.exp(-0.5 * pings * (v - v.min()) / sig_u**2)
    w = w / w.sum()
    mx, my = (w * x).sum(), (w * y).sum()
    return float(np.sqrt(max((w * x**2).sum() - mx**2, (w * y**2).sum() - my**2, 0.0)))


def match_profile_numpy(inc, up, k, reloc):
    """Plain-numpy reference of :func:`match_profile`: (pe, pn, ph, pings), 0 pings when not matched."""
    updates = min(k + 1, reloc.window)
    if updates < min(MIN_UPDATES, reloc.window):
        return np.empty(0), np.empty(0), np.empty(0), 0
    pe, pn, ph = relative_profile_numpy(inc, reloc.offsets, up, k, updates)
    if 2 * pe.size < updates:
        return np.empty(0), np.empty(0), np.empty(0), 0
    return pe, pn, ph, min(pe.size, updates)


def relocalise_around_numpy(inc, up, k, est_e, est_n, reloc):
    """Plain-numpy reference of :func:`relocalise_around`, in its steps (and of :func:`relocalise`: the same without
    navigation centres)."""
    pe, pn, ph, pings = match_profile_numpy(inc, up, k, reloc)
    if pings == 0:
        return False, est_e, est_n, 0.0
    first = match_surface_numpy(pe, pn, ph, est_e, est_n, reloc)
    answer = decide_match_numpy(pe, pn, ph, est_e, est_n, pings, reloc, first)
    if answer[0] or k >= reloc.nav_en.shape[0]:
        return answer
    nav_e, nav_n = reloc.nav_en[k]
    if max(abs(nav_e - est_e), abs(nav_n - est_n)) < reloc.nav_min_offset:
        return answer
    second = match_surface_numpy(pe, pn, ph, nav_e, nav_n, reloc)
    answer = decide_match_numpy(pe, pn, ph, nav_e, nav_n, pings, reloc, second)
    if answer[0] and reloc.both_squares and both_squares_std_numpy(first, est_e, est_n, second, nav_e, nav_n,
                                                                   reloc.half_cells, reloc.step, pings,
                                                                   reloc.sig_u) > reloc.fix_std:
        return False, nav_e, nav_n, 0.0
    return answer
