"""Mosaics of tiles, their seams, and the holes (NaN nodes) a map may have.

:func:`mosaic` joins tiles lying on one grid (overlaps averaged) and reports every seam;
:func:`tanbench.terrain.files.read_tiles` reads tiles, mosaics them in native coordinates
and projects once. :func:`find_holes` lists the NaN nodes a track's look-ups would read (:func:`over_holes`: which
points read one), :func:`fill_holes` fills them on request (the readers keep them).
"""

from __future__ import annotations

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.terrain.grid import EDGE_TOL, Map

# Positions that differ from the mosaic grid by less than this fraction of a cell are "on" it.
MOSAIC_TOLERANCE = 0.05


def mosaic(maps, *, tol: float = MOSAIC_TOLERANCE) -> tuple[Map, list[dict]]:
    """Join tiles lying on one grid into one Map, averaging overlaps; report the seams.

    The tiles must share a crs and a spacing, with offsets that are whole multiples of
    it: every node of every tile must lie within ``tol`` cells of the common grid (whose
    spacing is the tiles' median spacing, anchored on the first tile), else
    :class:`TanbenchError`. Nodes covered by no tile are NaN; overlapping nodes take the
    mean of the tiles' finite values.

    One seam entry is returned per pair of tiles that overlap or share an edge:
    ``tiles`` (the two names), ``kind`` (``'overlap'``; ``'east-west'`` for tiles side
    by side, the seam running north-south; ``'north-south'`` for one tile above the
    other), ``pairs`` (node pairs compared, NaN pairs left out), ``mean_abs_step`` and
    ``max_abs_step`` and ``worst_at`` (the (e, n) of the largest step). For an overlap
    the step is the difference between the two tiles' values at the same node. For an
    edge the raw jump between the two node rows (columns) adjacent to the join is
    ``mean_abs_jump``; the step is that jump minus the slope seen on either side (the
    mean of the last difference inside each tile), so that a smooth surface, a plane
    included, gives a step of 0 and an offset between tiles shows in full.
    """
    maps = list(maps)
    if not maps:
        raise TanbenchError("mosaic: no tiles given")
    labels = [tile_label(m, k) for k, m in enumerate(maps)]
    crs_set = {m.meta.get("crs", "metric") for m in maps}
    if "local" in crs_set and len(maps) > 1:
        k = next(k for k, m in enumerate(maps) if m.meta.get("crs") == "local")
        raise TanbenchError(
            f"{labels[k]}: this tile was projected from geographic coordinates on its own; "
            f"mosaic geographic tiles before projecting them: use read_tiles(...) or "
            f"read_grid(..., project=False) then mosaic() then to_local()"
        )
    if len(crs_set) > 1:
        raise TanbenchError(
            "mosaic: tiles are in different coordinate systems ("
            + ", ".join(f"{lab}: {m.meta.get('crs', 'metric')}" for lab, m in zip(labels, maps))
            + ")"
        )
    if len(maps) == 1:
        return maps[0], []
    res_e = float(np.median([m.res_e for m in maps]))
    res_n = float(np.median([m.res_n for m in maps]))
    anchor_e, anchor_n = maps[0].e0, maps[0].n0
    cols, rows_, misplaced = [], [], []
    for m in maps:
        c, mis_e = _snap(m.e0, m.res_e, m.z.shape[1], anchor_e, res_e)
        r, mis_n = _snap(m.n0, m.res_n, m.z.shape[0], anchor_n, res_n)
        misplaced.append(max(mis_e, mis_n))
        cols.append(c)
        rows_.append(r)
    if max(misplaced) > tol:
        offenders = sorted((k for k, mis in enumerate(misplaced) if mis > tol), key=lambda k: -misplaced[k])
        raise TanbenchError(
            "; ".join(
                f"{labels[k]}: tile does not sit on the mosaic grid (spacing {maps[k].res_e:.6g} x "
                f"{maps[k].res_n:.6g} against {res_e:.6g} x {res_n:.6g}, nodes up to "
                f"{misplaced[k]:.3g} cells off)"
                for k in offenders
            )
            + f"; the grid is anchored on {labels[0]}, tolerance {tol:g} cells"
        )
    worst = max(misplaced)
    c_min, r_min = min(cols), min(rows_)
    cols = [c - c_min for c in cols]
    rows_ = [r - r_min for r in rows_]
    nx = max(c + m.z.shape[1] for c, m in zip(cols, maps))
    ny = max(r + m.z.shape[0] for r, m in zip(rows_, maps))
    total = np.zeros((ny, nx))
    count = np.zeros((ny, nx))
    for m, c, r in zip(maps, cols, rows_):
        ok = np.isfinite(m.z)
        h, w = m.z.shape
        total[r:r + h, c:c + w] += np.where(ok, m.z, 0.0)
        count[r:r + h, c:c + w] += ok
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    e0 = anchor_e + c_min * res_e
    n0 = anchor_n + r_min * res_n
    meta = {k: v for k, v in maps[0].meta.items() if k in ("crs", "format")}
    meta.update(
        sources=[m.meta.get("source", lab) for m, lab in zip(maps, labels)],
        tile_offsets=[(r, c) for r, c in zip(rows_, cols)],
        max_misplacement_cells=worst,
        uncovered_nodes=int((count == 0).sum()),
    )
    joined = Map(z, e0, n0, res_e, res_n, name=f"mosaic of {len(maps)} tiles", meta=meta)
    seams = _seams(maps, labels, rows_, cols, e0, n0, res_e, res_n)
    return joined, seams


def find_holes(grid: Map, e, n, margin: float = 0.0) -> list[tuple[float, float]]:
    """NaN nodes that bilinear look-ups at points (e, n) would touch: [(e, n), ...].

    A look-up reads the four nodes of the cell holding the point (as the kernel in
    :mod:`tanbench.terrain.grid` does); ``margin`` metres widen that to every cell
    within a box of half-width ``margin`` around the point (for a sonar footprint, or an
    uncertainty around a track). Points whose box misses the grid altogether are not
    holes (check those with :meth:`Map.contains`). Holes are returned once each, south to
    north, west to east, so that a caller can reject a track with their locations or fill
    them on request; :func:`over_holes` says which points touch one.
    """
    bad = np.isnan(grid.z)
    _check_margin(margin)
    if not bad.any():
        return []
    keep, i_lo, i_hi, j_lo, j_hi = _look_up_boxes(grid, e, n, margin)
    if not keep.any():
        return []
    ny, nx = grid.z.shape
    # Cover each point's node box with a 2-D difference array, then integrate it.
    cover = np.zeros((ny + 1, nx + 1), dtype=np.int64)
    np.add.at(cover, (i_lo, j_lo), 1)
    np.add.at(cover, (i_lo, j_hi + 1), -1)
    np.add.at(cover, (i_hi + 1, j_lo), -1)
    np.add.at(cover, (i_hi + 1, j_hi + 1), 1)
    touched = cover.cumsum(axis=0).cumsum(axis=1)[:ny, :nx] > 0
    ii, jj = np.nonzero(touched & bad)
    return [(float(grid.e0 + j * grid.res_e), float(grid.n0 + i * grid.res_n))
            for i, j in zip(ii, jj)]


def over_holes(grid: Map, e, n, margin: float = 0.0) -> np.ndarray:
    """Per point (e, n), flattened: whether its look-ups (:func:`find_holes`' box, ``margin`` metres around
    the point) touch a NaN node."""
    _check_margin(margin)
    e, n = np.broadcast_arrays(np.asarray(e, dtype=float), np.asarray(n, dtype=float))
    out = np.zeros(e.size, dtype=bool)
    bad = np.isnan(grid.z)
    if not bad.any():
        return out
    keep, i_lo, i_hi, j_lo, j_hi = _look_up_boxes(grid, e, n, margin)
    ny, nx = grid.z.shape
    total = np.zeros((ny + 1, nx + 1), dtype=np.int64)  # NaN nodes south-west of each node, inclusive
    total[1:, 1:] = bad.cumsum(axis=0).cumsum(axis=1)
    count = total[i_hi + 1, j_hi + 1] - total[i_lo, j_hi + 1] - total[i_hi + 1, j_lo] + total[i_lo, j_lo]
    out[keep] = count > 0
    return out


def _check_margin(margin: float) -> None:
    if not (np.isfinite(margin) and margin >= 0):
        raise TanbenchError(f"find_holes: margin must be a non-negative number of metres, got {margin}")


def _look_up_boxes(grid: Map, e, n, margin: float):
    """Which points (e, n), flattened, have a box of half-width ``margin`` on the grid (``keep``), and the
    node rows ``i_lo..i_hi`` and columns ``j_lo..j_hi`` that look-ups in each kept box read."""
    e, n = np.broadcast_arrays(np.asarray(e, dtype=float), np.asarray(n, dtype=float))
    e, n = e.ravel(), n.ravel()
    ny, nx = grid.z.shape
    _, e0, n0, inv_re, inv_rn = grid.kernel_args()  # the look-up's own arithmetic (grid.bilinear_cell), so that
    fx_lo = (e - margin - e0) * inv_re  # a point on a node line falls in the cell the look-up reads
    fx_hi = (e + margin - e0) * inv_re
    fy_lo = (n - margin - n0) * inv_rn
    fy_hi = (n + margin - n0) * inv_rn
    keep = (np.isfinite(e) & np.isfinite(n) & (fx_hi >= 0) & (fx_lo <= nx - 1 + EDGE_TOL)
            & (fy_hi >= 0) & (fy_lo <= ny - 1 + EDGE_TOL))
    j_lo = np.clip(np.floor(fx_lo[keep]), 0, nx - 2).astype(np.int64)
    j_hi = np.clip(np.floor(fx_hi[keep]), 0, nx - 2).astype(np.int64) + 1
    i_lo = np.clip(np.floor(fy_lo[keep]), 0, ny - 2).astype(np.int64)
    i_hi = np.clip(np.floor(fy_hi[keep]), 0, ny - 2).astype(np.int64) + 1
    return keep, i_lo, i_hi, j_lo, j_hi


def fill_holes(grid: Map, method: str = "laplace") -> Map:
    """A copy of ``grid`` with its NaN nodes filled, for callers that ask for it.

    ``method='laplace'`` (default) solves Laplace's equation over the holes with the
    known nodes around them as boundary values (anisotropic spacing respected, no flux
    through the map edges): a smooth membrane, no terraces, exact for a plane.
    ``method='nearest'`` copies the nearest known node (in metres). The number of filled
    nodes and the method go to ``meta["filled_nodes"]`` and ``meta["fill_method"]``.
    """
    if method not in ("laplace", "nearest"):
        raise TanbenchError(f"fill_holes: unknown method {method!r}; use 'laplace' or 'nearest'")
    bad = np.isnan(grid.z)
    n_bad = int(bad.sum())
    if n_bad == 0:
        return grid
    if n_bad == bad.size:
        raise TanbenchError(f"{tile_label(grid, 0)}: cannot fill holes, the map has no valid node")
    if method == "nearest":
        from scipy.ndimage import distance_transform_edt

        _, (ii, jj) = distance_transform_edt(bad, sampling=(grid.res_n, grid.res_e),
                                             return_indices=True)
        z = grid.z[ii, jj]
    else:
        z = _laplace_fill(grid.z, bad, grid.res_e, grid.res_n)
    meta = dict(grid.meta)
    meta.update(filled_nodes=n_bad, fill_method=method)
    return Map(z, grid.e0, grid.n0, grid.res_e, grid.res_n, name=grid.name, meta=meta)


def _laplace_fill(z: np.ndarray, bad: np.ndarray, res_e: float, res_n: float) -> np.ndarray:
    """Harmonic fill: each hole node is the weighted mean of its 4 neighbours (weights
    1/res^2 per axis), known nodes fixed; edge nodes simply have fewer neighbours."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.linalg import spsolve

    ny, nx = z.shape
    index = -np.ones(z.shape, dtype=np.int64)
    ii, jj = np.nonzero(bad)
    index[ii, jj] = np.arange(ii.size)
    rows, cols, vals = [], [], []
    diag = np.zeros(ii.size)
    rhs = np.zeros(ii.size)
    for di, dj, w in ((1, 0, res_n ** -2), (-1, 0, res_n ** -2), (0, 1, res_e ** -2), (0, -1, res_e ** -2)):
        ni, nj = ii + di, jj + dj
        inside = (ni >= 0) & (ni < ny) & (nj >= 0) & (nj < nx)
        k = np.flatnonzero(inside)
        diag[k] += w
        neighbour = index[ni[k], nj[k]]
        unknown = neighbour >= 0
        rows.append(k[unknown])
        cols.append(neighbour[unknown])
        vals.append(np.full(int(unknown.sum()), -w))
        rhs[k[~unknown]] += w * z[ni[k[~unknown]], nj[k[~unknown]]]
    rows.append(np.arange(ii.size))
    cols.append(np.arange(ii.size))
    vals.append(diag)
    matrix = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                        shape=(ii.size, ii.size)).tocsr()
    out = z.copy()
    out[ii, jj] = spsolve(matrix, rhs)
    return out


# --------------------------------------------------------------------------------------
# Mosaic helpers
# --------------------------------------------------------------------------------------


def _snap(start: float, res: float, count: int, anchor: float, grid_res: float) -> tuple[int, float]:
    """Grid index of a tile's first node and its nodes' worst distance from the grid, in cells."""
    index = int(round((start - anchor) / grid_res))
    first = start - (anchor + index * grid_res)
    last = first + (count - 1) * (res - grid_res)
    return index, max(abs(first), abs(last)) / grid_res


def _seams(maps, labels, rows_, cols, e0, n0, res_e, res_n) -> list[dict]:
    """One entry per pair of tiles that overlap or share an edge (see :func:`mosaic`)."""
    seams = []
    boxes = [(r, r + m.z.shape[0], c, c + m.z.shape[1]) for m, r, c in zip(maps, rows_, cols)]
    for a in range(len(maps)):
        for b in range(a + 1, len(maps)):
            ra0, ra1, ca0, ca1 = boxes[a]
            rb0, rb1, cb0, cb1 = boxes[b]
            r0, r1 = max(ra0, rb0), min(ra1, rb1)
            c0, c1 = max(ca0, cb0), min(ca1, cb1)
            jump = None
            if r1 > r0 and c1 > c0:
                kind = "overlap"
                va = maps[a].z[r0 - ra0:r1 - ra0, c0 - ca0:c1 - ca0]
                vb = maps[b].z[r0 - rb0:r1 - rb0, c0 - cb0:c1 - cb0]
                step = vb - va
                rr, cc = np.meshgrid(np.arange(r0, r1), np.arange(c0, c1), indexing="ij")
                where_e, where_n = e0 + cc * res_e, n0 + rr * res_n
            elif r1 > r0 and (ca1 == cb0 or cb1 == ca0):
                kind = "east-west"
                west, east = (a, b) if ca1 == cb0 else (b, a)
                jump, step = _edge_step(maps[west].z[r0 - boxes[west][0]:r1 - boxes[west][0]].T,
                                        maps[east].z[r0 - boxes[east][0]:r1 - boxes[east][0]].T)
                where_e = np.full(r1 - r0, e0 + (boxes[east][2] - 0.5) * res_e)
                where_n = n0 + np.arange(r0, r1) * res_n
            elif c1 > c0 and (ra1 == rb0 or rb1 == ra0):
                kind = "north-south"
                south, north = (a, b) if ra1 == rb0 else (b, a)
                jump, step = _edge_step(maps[south].z[:, c0 - boxes[south][2]:c1 - boxes[south][2]],
                                        maps[north].z[:, c0 - boxes[north][2]:c1 - boxes[north][2]])
                where_e = e0 + np.arange(c0, c1) * res_e
                where_n = np.full(c1 - c0, n0 + (boxes[north][0] - 0.5) * res_n)
            else:
                continue
            step = np.abs(step).ravel()
            ok = np.isfinite(step)
            entry = {"tiles": (labels[a], labels[b]), "kind": kind, "pairs": int(ok.sum()),
                     "mean_abs_step": float("nan"), "max_abs_step": float("nan"),
                     "worst_at": (float("nan"), float("nan"))}
            if ok.any():
                worst = int(np.flatnonzero(ok)[np.argmax(step[ok])])
                entry.update(mean_abs_step=float(step[ok].mean()), max_abs_step=float(step[worst]),
                             worst_at=(float(np.ravel(where_e)[worst]), float(np.ravel(where_n)[worst])))
            if jump is not None:
                finite = np.abs(jump[np.isfinite(jump)])
                entry["mean_abs_jump"] = float(finite.mean()) if finite.size else float("nan")
            seams.append(entry)
    return seams


def _edge_step(low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jump across a join between grids stacked along axis 0 (``low`` first), and that
    jump minus the mean of the last slope inside each grid (0 for a smooth surface)."""
    jump = high[0] - low[-1]
    return jump, jump - 0.5 * ((low[-1] - low[-2]) + (high[1] - high[0]))


def tile_label(m: Map, k: int) -> str:
    """A map's source file, else its name, else ``tile k``."""
    return str(m.meta.get("source") or m.name or f"tile {k}")
