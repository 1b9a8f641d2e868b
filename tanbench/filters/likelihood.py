"""Measurement likelihood (Eqs. 15-20): terrain altitude innovations of the sonar beams.

For beam i with unit vector a_i (body frame) and measured range r_i, a particle with
attitude Theta predicts the bottom at its position plus C_b^n(Theta) a_i r_i (Eqs. 15,
17); the innovation d_i is the predicted bottom's height minus the navigation map's
height under it. Eq. 20's |R| is read as per-component variances. Two densities per beam:

* plain (the paper's reading): Gaussian with the sonar's variance sigma_U^2,
      log p = -1/2 [ (dE^2 + dN^2) / sigma_d^2 + sum_i d_i^2 / sigma_U^2 ] + const;
* map-aware (docs/model.md, Section 6.3): each beam's variance is the sonar's plus the
  navigation map's variance at the footprint, v_i = sigma_U^2 + m_i (a second grid on the
  map's nodes, ``terrain/representation.py``), and, because v_i depends on where a particle
  puts the footprint, its log-normaliser stays in:
      Gaussian:  log p_i = -1/2 [ d_i^2 / v_i + log(v_i / sigma_U^2) ]
      Student-t: log p_i = -(nu + 1)/2 log(1 + d_i^2 / (nu v_i)) - 1/2 log(v_i / sigma_U^2)
  (constants dropped; the Student-t's heavy tails bound the pull of one wild range).

Log-likelihoods are returned, never raw likelihoods, so nothing underflows. A beam whose
footprint falls off the map (or next to a NaN node) is charged ``outside_sigma`` sigmas
with the sonar's variance; a beam without a range (no bottom lock, NaN) is skipped. Each
kernel returns the smallest per-beam mean of d_i^2 / v_i over the particles, the filter's
divergence statistic.

Particles are columns of ``x`` (rows are states). The work runs beam by beam over all
particles in passes that compile to SIMD instructions (``attitude_matrices``,
``tight_footprints``/``loose_footprints``, ``add_beam_terms``, ``finish_loglik``); the one
scalar pass is the map look-up at the footprints (``terrain.grid.interpolate_cells``). The map-aware beams'
logs are taken of products: one log per particle for the normalisers and one for the
Student-t factors, every :data:`FOLD_BEAMS` beams (each factor is at least 1 and below
about 1e38, so a product of that many stays finite).
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.state import E, N, PITCH, ROLL, U, YAW
from tanbench.filters.trig import attitude_sin_cos, attitude_wound, unwound_attitude
from tanbench.filters.vecmath import log_positive
from tanbench.options import LIKELIHOOD
from tanbench.terrain.grid import bilinear_numpy, interpolate_cells, locate_cell, node_grid
from tanbench.terrain.representation import filter_map_variance
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

LIK_GAUSSIAN, LIK_STUDENT = LIKELIHOOD["gaussian"], LIKELIHOOD["student-t"]

# measurement model: the map-aware density (``mapaware``: the beam variance includes the map's
# variance grid, whose coefficients then follow the map's in the loop's cell table,
# terrain.grid.cell_grid), the beam density code (``kind``, options.LIKELIHOOD) and the
# Student-t degrees of freedom ``nu``
Likelihood = namedtuple("Likelihood", "mapaware kind nu")


def likelihood_of(f) -> Likelihood:
    """The :class:`Likelihood` bundle of a ``FilterSpec`` ``f``: the map-aware density when the
    map-aware variance or a non-Gaussian density is asked for."""
    mapaware = f.map_aware_likelihood or f.likelihood != "gaussian"
    return Likelihood(bool(mapaware), LIKELIHOOD[f.likelihood], float(f.student_nu))


def likelihood_grid(f, nmap):
    """The navigation map as the particle filters read it (:class:`~tanbench.terrain.grid.NodeGrid`):
    with the map-aware density, its variance grid interleaved with its heights: the map's
    representation variance with its declared error (``filter.map_aware_likelihood``,
    terrain/representation.py), or zero."""
    if not likelihood_of(f).mapaware:
        return node_grid(nmap)
    if f.map_aware_likelihood:
        mvar = filter_map_variance(f, nmap)
    else:
        mvar = np.where(np.isnan(nmap.z), np.nan, 0.0)
    return node_grid(nmap, mvar)
FOLD_BEAMS = 8

# the work arrays of the likelihood passes for one block of the cloud: the filter loops run
# their particle passes block by block (at most BLOCK particles), so that the arrays one
# block's passes touch stay in the core's caches. ``dcm`` (9, n); ``cell``, ``tx``, ``ty``, ``pu``
# (2, n): the footprints of two beams (:func:`tight_footprint_pair`); ``values`` (2 grids, n): the
# map's height (and variance) at the two beams' footprints (``terrain.grid.interpolate_cells``).
BLOCK = 1000000
LikelihoodWork = namedtuple("LikelihoodWork", "dcm cell tx ty pu values norm student chi logs")


@nb.njit(cache=True)
def new_likelihood_work(n, corners):
    """Work buffers for blocks of up to ``n`` particles and ``corners`` values per cell (4 per
    map grid: ``4 * NodeGrid.grids``); :func:`work_block` shapes them for a block."""
    return LikelihoodWork(np.empty(9 * n), np.empty(2 * n, dtype=np.int32), np.empty(2 * n), np.empty(2 * n),
                          np.empty(2 * n), np.empty(2 * max(corners // 4, 1) * n), np.empty(n), np.empty(n), np.empty(n),
                          np.empty(n))


@nb.njit(cache=True)
def work_block(work, n):
    """The work arrays of a block of ``n`` particles, C-contiguous (the passes vectorise only on
    contiguous rows): views of the buffers of :func:`new_likelihood_work`."""
    rows = work.values.shape[0] // work.norm.shape[0]
    return LikelihoodWork(work.dcm[:9 * n].reshape((9, n)), work.cell[:2 * n].reshape((2, n)),
                          work.tx[:2 * n].reshape((2, n)), work.ty[:2 * n].reshape((2, n)),
                          work.pu[:2 * n].reshape((2, n)),
                          work.values[:rows * n].reshape((rows, n)), work.norm[:n], work.student[:n],
                          work.chi[:n], work.logs[:n])


# the constants of the likelihood passes, from the measurement sigmas (:func:`beam_constants`):
# the sonar's variance sigma_U^2, the inverse variance 1 / sigma_d^2 of the distance
# innovations and the squared innovation ``outside_sigma``^2 charged to a beam off the map
BeamConstants = namedtuple("BeamConstants", "su2 inv_d2 out2")


@nb.njit(cache=True, inline="always")
def beam_constants(sig_u, sig_d, outside_sigma):
    """The :class:`BeamConstants` (sig_u^2, 1 / sig_d^2, outside_sigma^2) of the likelihood."""
    return BeamConstants(sig_u * sig_u, 1.0 / (sig_d * sig_d), outside_sigma * outside_sigma)


@nb.njit(cache=True)
def beam_vectors(beams, ranges):
    """(n, 3) beam vectors times ranges, body frame, of the n beams with a range (not NaN), in
    beam order."""
    used = 0
    for i in range(ranges.shape[0]):
        if ranges[i] == ranges[i]:
            used += 1
    vec = np.empty((used, 3))
    k = 0
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if r == r:
            vec[k, 0] = beams[i, 0] * r
            vec[k, 1] = beams[i, 1] * r
            vec[k, 2] = beams[i, 2] * r
            k += 1
    return vec


@nb.njit(cache=True)
def used_offsets(offsets):
    """The rows of beam offsets ``offsets`` (m, 3) with a range (third column not NaN), in order."""
    used = 0
    for i in range(offsets.shape[0]):
        if offsets[i, 2] == offsets[i, 2]:
            used += 1
    out = np.empty((used, 3))
    k = 0
    for i in range(offsets.shape[0]):
        if offsets[i, 2] == offsets[i, 2]:
            out[k, 0] = offsets[i, 0]
            out[k, 1] = offsets[i, 1]
            out[k, 2] = offsets[i, 2]
            k += 1
    return out


@nb.njit(cache=True, inline="always")
def _matrix_rows(dcm):
    """The nine rows of ``dcm`` as 1-D views (loops over views vectorise; see ``propagate._rows``)."""
    return dcm[0], dcm[1], dcm[2], dcm[3], dcm[4], dcm[5], dcm[6], dcm[7], dcm[8]


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def attitude_matrices(x, lo, att, dcm):
    """C_b^n of the attitudes of particles ``lo .. lo + n - 1`` into ``dcm`` (9, n), row-major
    entries c00..c22; the angles as offsets from the reference ``att`` (``trig.attitude_reference``)."""
    n = dcm.shape[1]
    pitch, roll, yaw = x[PITCH, lo:lo + n], x[ROLL, lo:lo + n], x[YAW, lo:lo + n]
    if attitude_wound(pitch, roll, yaw, att) == 0:  # the same bits without the wound angles' hash
        _attitude_rows_near(pitch, roll, yaw, att, dcm)
    else:  # wound angles (rare): the same loop on their offsets, unwound (the same bits as trig.sin_cos)
        p, r, y, att0 = unwound_attitude(pitch, roll, yaw, att)
        _attitude_rows_near(p, r, y, att0, dcm)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _attitude_rows_near(pitch, roll, yaw, att, dcm):
    """C_b^n of the rows ``pitch``, ``roll``, ``yaw`` into ``dcm``: offsets all within ``trig.WOUND``
    (``trig.sin_cos_near``)."""
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = _matrix_rows(dcm)
    for j in range(dcm.shape[1]):
        st, ct, sg, cg, sp, cp = attitude_sin_cos(pitch[j], roll[j], yaw[j], att)
        c00[j] = cg * cp - st * sg * sp
        c01[j] = -ct * sp
        c02[j] = sg * cp + st * cg * sp
        c10[j] = cg * sp + st * sg * cp
        c11[j] = ct * cp
        c12[j] = sg * sp - st * cg * cp
        c20[j] = -ct * sg
        c21[j] = st
        c22[j] = ct * cg


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _footprint(e, nn, u, c, a, grid):
    """The footprint of beam ``a`` (a0, a1, a2) from (e, nn, u) with attitude matrix ``c`` (its nine
    elements row by row): its map cell, position in the cell and height (cell, tx, ty, pu)."""
    _, _, e0, n0, inv_re, inv_rn, nx, ny = grid
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c
    a0, a1, a2 = a
    pe = e + c00 * a0 + c01 * a1 + c02 * a2
    pn = nn + c10 * a0 + c11 * a1 + c12 * a2
    pu = u + c20 * a0 + c21 * a1 + c22 * a2
    cell, tx, ty = locate_cell(pe, pn, e0, n0, inv_re, inv_rn, nx, ny)
    return cell, tx, ty, pu


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def tight_footprints(x, lo, dcm, a0, a1, a2, grid, cell, tx, ty, pu):
    """Beam ``(a0, a1, a2)`` (body frame, times its range) seen from particles ``lo ..``, with
    their attitude matrices ``dcm`` (9, n): its footprint's map cell (``cell``, -1 off the map),
    position in the cell (``tx``, ``ty``) and height (``pu``)."""
    n = dcm.shape[1]
    e, nn, u = x[E, lo:lo + n], x[N, lo:lo + n], x[U, lo:lo + n]
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = _matrix_rows(dcm)
    for j in range(n):
        m = (c00[j], c01[j], c02[j], c10[j], c11[j], c12[j], c20[j], c21[j], c22[j])
        cell[j], tx[j], ty[j], pu[j] = _footprint(e[j], nn[j], u[j], m, (a0, a1, a2), grid)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def tight_footprint_pair(x, lo, dcm, vec, i, grid, cell, tx, ty, pu):
    """:func:`tight_footprints` of beams ``i`` and ``i + 1`` of ``vec`` (``beam_vectors``) in one
    pass (each particle's matrix read once), into rows 0 and 1 of ``cell``, ``tx``, ``ty``,
    ``pu`` (2, n). (Two beams a pass: with four, LLVM no longer vectorised the loop.)"""
    n = dcm.shape[1]
    e, nn, u = x[E, lo:lo + n], x[N, lo:lo + n], x[U, lo:lo + n]
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = _matrix_rows(dcm)
    a = (vec[i, 0], vec[i, 1], vec[i, 2])
    b = (vec[i + 1, 0], vec[i + 1, 1], vec[i + 1, 2])
    cell_a, tx_a, ty_a, pu_a, cell_b, tx_b, ty_b, pu_b = cell[0], tx[0], ty[0], pu[0], cell[1], tx[1], ty[1], pu[1]
    for j in range(n):
        m = (c00[j], c01[j], c02[j], c10[j], c11[j], c12[j], c20[j], c21[j], c22[j])
        cell_a[j], tx_a[j], ty_a[j], pu_a[j] = _footprint(e[j], nn[j], u[j], m, a, grid)
        cell_b[j], tx_b[j], ty_b[j], pu_b[j] = _footprint(e[j], nn[j], u[j], m, b, grid)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def loose_footprints(x, lo, oe, on, height, grid, cell, tx, ty, pu):
    """:func:`tight_footprints` of a beam already in the navigation frame, (oe, on) from the
    positions of particles ``lo .. lo + n - 1`` (``x`` (2, M); ``n`` the length of ``cell``), at
    the height ``height``."""
    _, _, e0, n0, inv_re, inv_rn, nx, ny = grid
    n = cell.shape[0]
    e, nn = x[0, lo:lo + n], x[1, lo:lo + n]
    for j in range(n):
        pu[j] = height
        cell[j], tx[j], ty[j] = locate_cell(e[j] + oe, nn[j] + on, e0, n0, inv_re, inv_rn, nx, ny)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def add_beam_terms(values, cell, pu, su2, out2, mapaware, inv_nu, work):
    """Add one beam to every particle's terms: ``work.chi`` += d^2 / v and, map-aware, the
    normaliser product ``work.norm`` *= v / sigma_U^2 and the Student-t product
    ``work.student`` *= 1 + d^2 / (nu v) (``inv_nu`` = 1 / nu; 0 for the Gaussian, whose
    factor is then 1). ``values`` holds the map's height at the footprints and, map-aware, its
    variance grid's (``terrain.grid.interpolate_cells``)."""
    norm = work.norm
    student = work.student
    chi = work.chi
    inv_su2 = 1.0 / su2
    heights = values[0]
    variances = values[1 if mapaware else 0]
    for j in range(cell.shape[0]):
        q, v = _beam_term(heights[j], variances[j], cell[j], pu[j], su2, out2, mapaware)
        chi[j] += q
        norm[j] *= v * inv_su2
        student[j] *= 1.0 + q * inv_nu


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def _beam_term(h, mv, cell, pu, su2, out2, mapaware):
    """(d^2 / v, v) of one beam at one particle: map height ``h`` and variance ``mv`` (0 unless
    ``mapaware``) at its footprint in ``cell``, its height ``pu``."""
    mv = mv if mapaware else 0.0
    ok = (cell >= 0) & (h == h) & (mv == mv)
    v = su2 + mv if ok else su2
    d = pu - h
    return (d * d / v if ok else out2), v


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def add_beam_term_pair(values, grids, cell, pu, su2, out2, mapaware, inv_nu, work):
    """:func:`add_beam_terms` of two beams in one pass, the first then the second (the same
    operations in the same order): their footprints in rows 0 and 1 of ``cell`` and ``pu``,
    their map values in rows 0 .. grids - 1 and grids .. 2 grids - 1 of ``values``."""
    norm = work.norm
    student = work.student
    chi = work.chi
    inv_su2 = 1.0 / su2
    ha, hb = values[0], values[grids]
    va, vb = values[1 if mapaware else 0], values[grids + 1 if mapaware else grids]
    cell_a, cell_b, pu_a, pu_b = cell[0], cell[1], pu[0], pu[1]
    for j in range(cell_a.shape[0]):
        qa, vva = _beam_term(ha[j], va[j], cell_a[j], pu_a[j], su2, out2, mapaware)
        qb, vvb = _beam_term(hb[j], vb[j], cell_b[j], pu_b[j], su2, out2, mapaware)
        chi[j] = (chi[j] + qa) + qb
        norm[j] = (norm[j] * (vva * inv_su2)) * (vvb * inv_su2)
        student[j] = (student[j] * (1.0 + qa * inv_nu)) * (1.0 + qb * inv_nu)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def fold_beam_terms(work, half_nu1):
    """Move the products into the log sum: ``logs`` += -1/2 log(norm) - (nu + 1)/2 log(student);
    the products restart at 1."""
    for j in range(work.norm.shape[0]):
        work.logs[j] += -0.5 * log_positive(work.norm[j]) - half_nu1 * log_positive(work.student[j])
        work.norm[j] = 1.0
        work.student[j] = 1.0


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def start_beam_terms(work):
    for j in range(work.norm.shape[0]):
        work.norm[j] = 1.0
        work.student[j] = 1.0
        work.chi[j] = 0.0
        work.logs[j] = 0.0


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def finish_loglik(work, mapaware, student, half_nu1, dist, with_dist, inv_d2, out):
    """Every particle's log-likelihood into ``out`` from its beam terms, with its distance
    innovations (``dist`` (2, M), if ``with_dist``); returns the smallest sum of d^2 / v."""
    half = half_nu1 if student else 0.0
    chi, logs, norm, prod = work.chi, work.logs, work.norm, work.student
    dist_e, dist_n = dist[0], dist[1]
    for j in range(out.shape[0]):
        ll = -0.5 * chi[j] if not student else 0.0
        if mapaware:
            ll += logs[j] - 0.5 * log_positive(norm[j]) - half * log_positive(prod[j])
        if with_dist:
            ll -= 0.5 * (dist_e[j] * dist_e[j] + dist_n[j] * dist_n[j]) * inv_d2
        out[j] = ll
    best = np.inf
    for j in range(out.shape[0]):
        best = min(best, work.chi[j])
    return best


@nb.njit(cache=True)
def _beam_pass(grid, lik, su2, out2, inv_nu, half_nu1, work, used, i, r):
    """The map values and terms of beam ``i`` (its footprints in row ``r`` of ``work``'s); folds
    the products every FOLD_BEAMS beams."""
    cell, pu = work.cell[r], work.pu[r]
    interpolate_cells(cell, work.tx[r], work.ty[r], grid.nodes, grid.grids, grid.nx, work.values)
    add_beam_terms(work.values, cell, pu, su2, out2, lik.mapaware, inv_nu, work)
    _fold_after(lik, half_nu1, work, used, i)


@nb.njit(cache=True)
def _beam_pair_pass(grid, lik, su2, out2, inv_nu, half_nu1, work, used, i):
    """:func:`_beam_pass` of beams ``i`` and ``i + 1`` (``i`` even), their footprints in rows 0
    and 1 of ``work``'s."""
    g = grid.grids
    interpolate_cells(work.cell[0], work.tx[0], work.ty[0], grid.nodes, g, grid.nx, work.values[:g])
    interpolate_cells(work.cell[1], work.tx[1], work.ty[1], grid.nodes, g, grid.nx, work.values[g:2 * g])
    add_beam_term_pair(work.values, g, work.cell, work.pu, su2, out2, lik.mapaware, inv_nu, work)
    _fold_after(lik, half_nu1, work, used, i + 1)  # FOLD_BEAMS is even: never between the two


@nb.njit(cache=True, inline="always")
def _fold_after(lik, half_nu1, work, used, i):
    """Fold the products into the log sum after beam ``i`` every FOLD_BEAMS beams (not after the last)."""
    if lik.mapaware and (i + 1) % FOLD_BEAMS == 0 and i + 1 < used:
        fold_beam_terms(work, half_nu1)


@nb.njit(cache=True, inline="always")
def _density_constants(lik):
    student = lik.kind == LIK_STUDENT
    return (1.0 / lik.nu if student else 0.0), (0.5 * (lik.nu + 1.0) if student else 0.0), student


@nb.njit(cache=True)
def loglik_tight_pass(x, lo, vec, grid, lik, consts, att, dist, with_dist, work, out):
    """The log-likelihoods of particles ``lo .. lo + n - 1`` of the beams ``vec``
    (``beam_vectors``) into ``out`` (n,), with the block's work arrays ``work``
    (:func:`work_block`) and distance innovations ``dist`` (2, n), which enter if ``with_dist``;
    ``consts`` the :class:`BeamConstants`; ``att`` the attitude reference of the trigonometry
    (``trig.attitude_reference``; it does not change the result). Returns the best (smallest)
    mean d^2 / v per beam."""
    su2, inv_d2, out2 = consts
    inv_nu, half_nu1, student = _density_constants(lik)
    used = vec.shape[0]
    attitude_matrices(x, lo, att, work.dcm)
    start_beam_terms(work)
    for i in range(0, used - 1, 2):  # the beams in pairs (the terms still added beam by beam, in order)
        tight_footprint_pair(x, lo, work.dcm, vec, i, grid, work.cell, work.tx, work.ty, work.pu)
        _beam_pair_pass(grid, lik, su2, out2, inv_nu, half_nu1, work, used, i)
    if used % 2 == 1:
        i = used - 1
        tight_footprints(x, lo, work.dcm, vec[i, 0], vec[i, 1], vec[i, 2], grid, work.cell[0], work.tx[0],
                         work.ty[0], work.pu[0])
        _beam_pass(grid, lik, su2, out2, inv_nu, half_nu1, work, used, i, 0)
    best = finish_loglik(work, lik.mapaware, student, half_nu1, dist, with_dist, inv_d2, out)
    return best / used if used > 0 else np.inf


@nb.njit(cache=True)
def loglik_loose_pass(x, lo, rows, up, grid, lik, consts, work, out):
    """:func:`loglik_tight_pass` for the loose filter (``x`` (2, M)): ``rows`` the used beam
    offsets in the navigation frame (``used_offsets``), from the navigation height ``up``
    (``consts.inv_d2`` is not used)."""
    su2, _, out2 = consts
    inv_nu, half_nu1, student = _density_constants(lik)
    used = rows.shape[0]
    start_beam_terms(work)
    for i in range(used):
        loose_footprints(x, lo, rows[i, 0], rows[i, 1], up + rows[i, 2], grid, work.cell[0], work.tx[0], work.ty[0],
                         work.pu[0])
        _beam_pass(grid, lik, su2, out2, inv_nu, half_nu1, work, used, i, 0)
    best = finish_loglik(work, lik.mapaware, student, half_nu1, work.dcm, False, 0.0, out)
    return best / used if used > 0 else np.inf


@nb.njit(cache=True)
def loglik_tight(x, beams, ranges, grid, lik, sig_u, outside_sigma, dist_innov, sig_d, with_dist, att, out):
    """Fill ``out`` (M,) with each particle's log-likelihood (``x`` (8, M)); return the best chi^2
    per beam. ``grid`` is the map's :class:`~tanbench.terrain.grid.NodeGrid` (with the
    variance grid interleaved for the map-aware density), ``lik`` a
    :class:`Likelihood`; ``dist_innov`` (2, M) enters if
    ``with_dist``. ``att`` (``trig.attitude_reference`` of the navigation attitude) only centres
    the trigonometry."""
    m = x.shape[1]
    work = work_block(new_likelihood_work(m, 4 * grid.grids), m)
    return loglik_tight_pass(x, 0, beam_vectors(beams, ranges), grid, lik, beam_constants(sig_u, sig_d, outside_sigma),
                             att, dist_innov, with_dist, work, out)


@nb.njit(cache=True)
def loglik_loose(x, offsets, up, grid, lik, sig_u, outside_sigma, out):
    """Loose filter (``x`` (2, M)): beams projected once with the navigation attitude, ``offsets``
    (m, 3) in m; rows with NaN are beams without a range and are skipped."""
    m = x.shape[1]
    work = work_block(new_likelihood_work(m, 4 * grid.grids), m)
    return loglik_loose_pass(x, 0, used_offsets(offsets), up, grid, lik, beam_constants(sig_u, 1.0, outside_sigma),
                             work, out)


# ---- plain-numpy references --------------------------------------------------------------------
def _beam_logpdf_numpy(d2, v, sig_u, mapaware, kind, nu):
    if not mapaware:
        return -0.5 * d2 / sig_u**2
    norm = -0.5 * np.log(v / sig_u**2)
    if kind == LIK_STUDENT:
        return -0.5 * (nu + 1.0) * np.log1p(d2 / (nu * v)) + norm
    return -0.5 * d2 / v + norm


def _terms_numpy(pe, pn, pu, zmap, mvar, lik, sig_u, outside_sigma, used, dist_chi):
    h = bilinear_numpy(*zmap, pe, pn)
    mv = bilinear_numpy(mvar, *zmap[1:], pe, pn) if lik.mapaware else np.zeros_like(h)
    off = np.isnan(h) | np.isnan(mv)
    v = np.where(off, sig_u**2, sig_u**2 + np.nan_to_num(mv))
    d2 = np.where(off, outside_sigma**2 * sig_u**2, (pu - np.nan_to_num(h)) ** 2)
    ll = _beam_logpdf_numpy(d2, v, sig_u, lik.mapaware, lik.kind, lik.nu).sum(axis=1)
    chi = (d2 / v).sum(axis=1)
    best = (chi / used).min() if used else np.inf
    return ll - 0.5 * dist_chi, best


def loglik_tight_numpy(x, beams, ranges, zmap, mvar, lik, sig_u, outside_sigma, dist_innov, sig_d):
    """Plain-numpy reference of :func:`loglik_tight`: the map as its ``MapArgs`` ``zmap``
    (``Map.kernel_args()``) and the variance grid ``mvar`` (used if ``lik.mapaware``) where the
    kernel takes them interleaved in a ``NodeGrid``; ``dist_innov`` (2, M) or None (no distance
    innovation): (loglik (M,), best chi^2 per beam)."""
    c = dcm_body_to_nav_numpy(x[PITCH], x[ROLL], x[YAW])  # (M, 3, 3)
    ok = ~np.isnan(ranges)
    vec = beams[ok] * ranges[ok][:, None]  # (m', 3)
    p = x[[E, N, U]].T[:, None, :] + np.einsum("mij,bj->mbi", c, vec)  # (M, m', 3)
    dist_chi = 0.0 if dist_innov is None else (dist_innov**2).sum(axis=0) / sig_d**2
    return _terms_numpy(p[..., 0], p[..., 1], p[..., 2], zmap, mvar, lik, sig_u, outside_sigma, ok.sum(), dist_chi)


def loglik_loose_numpy(x, offsets, up, zmap, mvar, lik, sig_u, outside_sigma):
    """Plain-numpy reference of :func:`loglik_loose` (the map as in :func:`loglik_tight_numpy`):
    (loglik (M,), best chi^2 per beam)."""
    ok = ~np.isnan(offsets[:, 2])
    o = offsets[ok]
    pe = x[0][:, None] + o[:, 0]
    pn = x[1][:, None] + o[:, 1]
    pu = np.broadcast_to(up + o[:, 2], pe.shape)
    return _terms_numpy(pe, pn, pu, zmap, mvar, lik, sig_u, outside_sigma, ok.sum(), 0.0)
