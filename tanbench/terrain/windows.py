"""Per-node statistics over a square window of a grid (terrain suitability's roughness and entropy).

A jitted kernel with its plain-numpy twin; :mod:`tanbench.suitability` turns them into
maps. Kept apart from the suitability analysis so that the kernel cache (keyed on the
sources compiled kernels can hold, :mod:`tanbench.kernel_cache`) does not follow that
analysis' imports.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True)
def window_stats(z, wy, wx):
    """(plane-residual RMS, normalised deviation entropy) over a wy x wx window per node.

    Windows are clipped at the edges; NaN nodes are skipped; fewer than 3 valid nodes
    give NaN.
    """
    ny, nx = z.shape
    rough = np.full((ny, nx), np.nan)
    ent = np.full((ny, nx), np.nan)
    hy, hx = wy // 2, wx // 2
    vals = np.empty(wy * wx)
    for i in range(ny):
        for j in range(nx):
            if z[i, j] != z[i, j]:
                continue
            # least squares z = c + a x + b y about the window's own centroid
            n = 0
            sx = sy = sz = 0.0
            for di in range(-hy, hy + 1):
                for dj in range(-hx, hx + 1):
                    ii, jj = i + di, j + dj
                    if 0 <= ii < ny and 0 <= jj < nx and z[ii, jj] == z[ii, jj]:
                        vals[n] = z[ii, jj]
                        n += 1
                        sx += dj
                        sy += di
                        sz += z[ii, jj]
            if n < 3:
                continue
            mx, my, mz = sx / n, sy / n, sz / n
            sxx = syy = sxy = sxz = syz = 0.0
            k = 0
            for di in range(-hy, hy + 1):
                for dj in range(-hx, hx + 1):
                    ii, jj = i + di, j + dj
                    if 0 <= ii < ny and 0 <= jj < nx and z[ii, jj] == z[ii, jj]:
                        x, y, v = dj - mx, di - my, vals[k] - mz
                        sxx += x * x
                        syy += y * y
                        sxy += x * y
                        sxz += x * v
                        syz += y * v
                        k += 1
            det = sxx * syy - sxy * sxy
            a = (sxz * syy - syz * sxy) / det if det > 0 else 0.0
            b = (syz * sxx - sxz * sxy) / det if det > 0 else 0.0
            res2 = 0.0
            dev_sum = 0.0
            k = 0
            for di in range(-hy, hy + 1):
                for dj in range(-hx, hx + 1):
                    ii, jj = i + di, j + dj
                    if 0 <= ii < ny and 0 <= jj < nx and z[ii, jj] == z[ii, jj]:
                        v = vals[k] - mz
                        r = v - a * (dj - mx) - b * (di - my)
                        res2 += r * r
                        dev_sum += abs(v)
                        k += 1
            rough[i, j] = math.sqrt(res2 / n)
            if dev_sum <= 0.0:
                ent[i, j] = 0.0
                continue
            h = 0.0
            for q in range(n):
                p = abs(vals[q] - mz) / dev_sum
                if p > 0.0:
                    h -= p * math.log(p)
            ent[i, j] = h / math.log(n)
    return rough, ent


def window_stats_numpy(z: np.ndarray, wy: int, wx: int) -> tuple[np.ndarray, np.ndarray]:
    """Plain-numpy reference of :func:`window_stats` (a loop of least-squares solves)."""
    ny, nx = z.shape
    rough = np.full((ny, nx), np.nan)
    ent = np.full((ny, nx), np.nan)
    hy, hx = wy // 2, wx // 2
    for i in range(ny):
        for j in range(nx):
            if np.isnan(z[i, j]):
                continue
            i0, i1, j0, j1 = max(0, i - hy), min(ny, i + hy + 1), max(0, j - hx), min(nx, j + hx + 1)
            yy, xx = np.mgrid[i0 - i:i1 - i, j0 - j:j1 - j]
            w = z[i0:i1, j0:j1]
            ok = ~np.isnan(w)
            if ok.sum() < 3:
                continue
            v = w[ok]
            A = np.column_stack([np.ones(v.size), xx[ok], yy[ok]])
            coef, *_ = np.linalg.lstsq(A, v, rcond=None)
            rough[i, j] = np.sqrt(np.mean((v - A @ coef) ** 2))
            dev = np.abs(v - v.mean())
            if dev.sum() <= 0:
                ent[i, j] = 0.0
                continue
            p = dev / dev.sum()
            p = p[p > 0]
            ent[i, j] = -(p * np.log(p)).sum() / np.log(v.size)
    return rough, ent
