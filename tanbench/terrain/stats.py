"""Terrain roughness along a track: what decides whether TAN can work there.

For the nadir points of a track: the mean, standard deviation, min and max of the
seafloor depth (the paper's "bathymetric measurement values", Section 4.2), the mean
seafloor slope (the gradient of the bilinear truth), and the RMS difference between
navigation maps and the truth along the track (how much of the relief a map keeps).
A flat track (small depth std and slope, like the paper's area B) is not an error,
but it tells a user why a filter may not converge there.
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.terrain.grid import Map


def gradient(grid: Map, e: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(dz/de, dz/dn) of the bilinear surface at points, by central differences of half a cell.

    Exact on a plane; NaN where a difference point leaves the grid.
    """
    e = np.asarray(e, dtype=float)
    n = np.asarray(n, dtype=float)
    he, hn = grid.res_e / 2.0, grid.res_n / 2.0
    dzde = (grid.elevation(e + he, n) - grid.elevation(e - he, n)) / (2 * he)
    dzdn = (grid.elevation(e, n + hn) - grid.elevation(e, n - hn)) / (2 * hn)
    return dzde, dzdn


def slope_deg(grid: Map, e: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Seafloor slope (degrees) at points, from :func:`gradient`."""
    dzde, dzdn = gradient(grid, e, n)
    return np.degrees(np.arctan(np.hypot(dzde, dzdn)))


def track_statistics(truth: Map, points: np.ndarray, maps: dict[float, Map] | None = None) -> dict:
    """Depth and roughness statistics of ``truth`` under ``points`` (k, 2)."""
    e, n = points[:, 0], points[:, 1]
    z = truth.elevation(e, n)
    stats = {
        "points": int(len(z)),
        "depth_mean_m": float(np.nanmean(z)),
        "depth_std_m": float(np.nanstd(z)),
        "depth_min_m": float(np.nanmin(z)),
        "depth_max_m": float(np.nanmax(z)),
        "mean_slope_deg": float(np.nanmean(slope_deg(truth, e, n))),
        "off_map_points": int(np.isnan(z).sum()),
    }
    for res, grid in (maps or {}).items():
        diff = grid.elevation(e, n) - z
        stats[f"map_rms_{res:g}m"] = float(math.sqrt(np.nanmean(diff**2)))
    return stats
