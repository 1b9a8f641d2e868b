"""Navigation maps derived from the truth, as the paper made its reference map.

Zhou et al. 2017 (Section 4.1) grid their multibeam data "using compression and a
smooth filter", and state that map levels are "corrected to within 0.4 m of the true
value". tanbench derives each navigation map from the (finer) truth the same way:

1. smooth: a Gaussian filter of one truth cell (removes sub-cell detail before decimation);
2. compress: block-average k x k truth nodes into one map node (k = resolution / truth
   spacing); for a truth spacing that does not divide the resolution (real maps), the
   truth is first resampled bilinearly to spacing resolution / k with k = ceil(ratio);
3. map-level error: i.i.d. Gaussian noise of ``map_error_m`` (0.4 m) on every node,
   drawn from a stream fixed by the terrain seed and the resolution, so a given map is
   the same fixed artefact in every run, like a real survey map. With
   ``terrain.map_error_correlation_m`` > 0 (a world fault) the same draws are smoothed
   into a spatially correlated field of the same std (:func:`map_error_field`).

The sonar sees the truth; the filters see only the derived map. The block averages
sit at block centres, so the map's origin is shifted by (k - 1) / 2 truth cells.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from tanbench.terrain.grid import Map, bilinear_numpy


def derive_navigation_map(truth: Map, resolution_m: float, map_error_m: float = 0.4,
                          seed: int = 0, correlation_m: float = 0.0) -> Map:
    """The navigation map at ``resolution_m`` metres derived from ``truth``."""
    ratio = resolution_m / truth.resolution
    if ratio < 1.0 - 1e-9:
        raise ValueError(
            f"map resolution {resolution_m} m is finer than the truth grid ({truth.resolution:g} m)"
        )
    k = max(1, int(round(ratio)))
    if abs(ratio - k) > 1e-6 or truth.res_e != truth.res_n:
        k = max(1, math.ceil(ratio - 1e-9))
        fine = _resample(truth, resolution_m / k)
    else:
        fine = truth
    z = fine.z
    if k > 1:
        # NaN-aware smoothing: holes stay holes rather than bleeding into neighbours
        holes = np.isnan(z)
        filled = np.where(holes, 0.0, z)
        num = ndimage.gaussian_filter(filled, sigma=1.0, mode="nearest")
        den = ndimage.gaussian_filter((~holes).astype(float), sigma=1.0, mode="nearest")
        z = np.where(holes, np.nan, num / np.maximum(den, 1e-12))
    ny, nx = (z.shape[0] // k), (z.shape[1] // k)
    if ny < 2 or nx < 2:
        raise ValueError(
            f"map resolution {resolution_m} m is coarser than the map extent allows "
            f"({truth.e_max - truth.e0:.0f} m x {truth.n_max - truth.n0:.0f} m)"
        )
    blocks = z[: ny * k, : nx * k].reshape(ny, k, nx, k).mean(axis=(1, 3))
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x3A9, int(round(resolution_m * 1000)))))
    blocks = blocks + map_error_m * map_error_field(rng.standard_normal(blocks.shape), correlation_m / (fine.res_e * k))
    shift = (k - 1) / 2.0
    return Map(z=blocks, e0=fine.e0 + shift * fine.res_e, n0=fine.n0 + shift * fine.res_n,
               res_e=fine.res_e * k, res_n=fine.res_n * k,
               name=f"{truth.name}@{resolution_m:g}m",
               meta={**truth.meta, "derived_from": truth.name, "resolution_m": resolution_m,
                     "map_error_m": map_error_m})


def map_error_field(white: np.ndarray, correlation_nodes: float) -> np.ndarray:
    """Unit-std map error: the white draws themselves (i.i.d. nodes) or, for a correlation
    length of ``correlation_nodes`` > 0 map cells, the draws smoothed by a Gaussian kernel of
    that std and rescaled to unit std (a stationary field with Gaussian correlation
    exp(-d^2 / (4 L^2)); a survey's levelling and tide errors are smooth over a swath)."""
    if correlation_nodes <= 0:
        return white
    field = ndimage.gaussian_filter(white, sigma=correlation_nodes, mode="wrap")
    return field / field.std()


def _resample(truth: Map, spacing: float) -> Map:
    """Bilinear resampling of ``truth`` onto a square grid of ``spacing`` metres."""
    e = np.arange(truth.e0, truth.e_max + 1e-9, spacing)
    n = np.arange(truth.n0, truth.n_max + 1e-9, spacing)
    ee, nn = np.meshgrid(e, n)
    z = bilinear_numpy(*truth.kernel_args(), ee, nn)
    return Map(z=z, e0=truth.e0, n0=truth.n0, res_e=spacing, res_n=spacing, name=truth.name,
               meta=truth.meta)
