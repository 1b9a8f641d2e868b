"""Synthetic seafloor by spectral (fractal) synthesis, calibrated to track statistics.

The paper's reference map (real multibeam data) is not available, so tanbench
synthesises a stand-in with the reported character: Gaussian random fields with a
von Karman power spectrum

    P(k) ~ (k^2 + k0^2)^-(H + 1),    k0 = 2 pi / corner_m,

(self-affine with Hurst exponent H below the corner wavelength, flat above it; the
standard statistical model of seafloor morphology, e.g. Goff & Jordan 1988), blended
between regions with smooth masks. Each region's amplitude and offset are set so that
the seafloor under a calibration track has a prescribed mean and standard deviation
(the paper's "bathymetric measurement values"). Deterministic for a given seed; other
seeds give other seafloors with the same statistics along the calibration tracks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tanbench.terrain.grid import Map, bilinear_numpy


@dataclass(frozen=True)
class Region:
    """A rectangle of one terrain character, with a smooth ``taper_m`` border.

    ``hurst`` and ``corner_m`` shape the spectrum; if ``calibration`` (points (k, 2)
    in metres, with target ``mean_m`` and ``std_m``) is given, the region's offset and
    amplitude are solved so the seafloor at those points has exactly those statistics.
    ``peak_cap_sigma`` compresses crests above that many standard deviations
    (``c * tanh(f / c)``): real rough seafloors are skewed towards deep troughs rather
    than tall spikes, and it keeps a vehicle at the paper's depths clear of the bottom.
    """

    name: str
    e_range: tuple[float, float]
    n_range: tuple[float, float]
    hurst: float
    corner_m: float
    mean_m: float
    std_m: float
    taper_m: float = 150.0
    calibration: np.ndarray | None = None
    peak_cap_sigma: float | None = None


@dataclass(frozen=True)
class Layout:
    """A whole synthetic map: extent, background character, regions and global limits."""

    name: str
    e_range: tuple[float, float]
    n_range: tuple[float, float]
    background: Region
    regions: tuple[Region, ...]
    depth_limits_m: tuple[float, float]
    median_m: float | None = None
    shoal: tuple[float, float, float, float, float] | None = None  # (e, n, sigma_e, sigma_n, height)


def with_roughness(layout: Layout, hurst: dict | None = None, corner_m: dict | None = None) -> Layout:
    """``layout`` with the spectral exponent and/or corner length of named regions replaced.

    Names are the regions' (``background`` included); each region keeps its calibration,
    so the seafloor under the calibration track keeps its mean and standard deviation.
    """
    from dataclasses import replace

    hurst, corner_m = hurst or {}, corner_m or {}
    regions = (layout.background,) + layout.regions
    known = {r.name for r in regions}
    unknown = sorted((set(hurst) | set(corner_m)) - known)
    if unknown:
        raise ValueError(f"layout {layout.name!r} has no region {', '.join(map(repr, unknown))} "
                         f"(regions: {', '.join(sorted(known))})")
    new = [replace(r, hurst=float(hurst.get(r.name, r.hurst)), corner_m=float(corner_m.get(r.name, r.corner_m)))
           for r in regions]
    return replace(layout, background=new[0], regions=tuple(new[1:]))


def fractal_field(shape, res, hurst, corner_m, rng, pad=0.25) -> np.ndarray:
    """Zero-mean, unit-std Gaussian field with a von Karman spectrum on a (ny, nx) grid.

    Synthesised on a grid padded by ``pad`` on each side and cropped, so the
    periodicity of the FFT does not show at the edges.
    """
    ny, nx = shape
    py, px = int(ny * (1 + 2 * pad)), int(nx * (1 + 2 * pad))
    ky = 2 * np.pi * np.fft.fftfreq(py, d=res)
    kx = 2 * np.pi * np.fft.rfftfreq(px, d=res)
    k2 = ky[:, None] ** 2 + kx[None, :] ** 2
    k0 = 2 * np.pi / corner_m
    amplitude = (k2 + k0**2) ** (-(hurst + 1.0) / 2.0)
    amplitude[0, 0] = 0.0
    noise = rng.standard_normal((py, px))
    field = np.fft.irfft2(np.fft.rfft2(noise) * amplitude, s=(py, px))
    oy, ox = (py - ny) // 2, (px - nx) // 2
    field = field[oy:oy + ny, ox:ox + nx]
    field -= field.mean()
    return field / field.std()


def region_weight(e, n, region: Region) -> np.ndarray:
    """1 inside the region's rectangle, falling smoothly (smoothstep) to 0 over the taper."""
    def axis(x, lo, hi):
        d = np.maximum(lo - x, x - hi)
        u = np.clip(1.0 - d / region.taper_m, 0.0, 1.0)
        return np.where(d <= 0, 1.0, u * u * (3 - 2 * u))

    return axis(e, *region.e_range) * axis(n, *region.n_range)


def synthesize(layout: Layout, seed: int, res: float = 2.5) -> Map:
    """Build the truth seafloor of ``layout`` at ``res`` metres with random seed ``seed``."""
    e = np.arange(layout.e_range[0], layout.e_range[1] + res / 2, res)
    n = np.arange(layout.n_range[0], layout.n_range[1] + res / 2, res)
    ee, nn = np.meshgrid(e, n)
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x7E77A1,)))

    def sample(field, pts):
        return bilinear_numpy(field, e[0], n[0], 1 / res, 1 / res, pts[:, 0], pts[:, 1])

    parts = []
    for region in (layout.background,) + layout.regions:
        f = fractal_field(ee.shape, res, region.hurst, region.corner_m, rng)
        if region.peak_cap_sigma is not None:
            c = region.peak_cap_sigma
            f = np.where(f > 0, c * np.tanh(f / c), f)
        mean, amp = region.mean_m, region.std_m
        if region.calibration is not None:
            s = sample(f, region.calibration)
            amp = region.std_m / s.std()
            mean = region.mean_m - amp * s.mean()
        parts.append((region, mean + amp * f))

    z = parts[0][1].copy()
    if layout.shoal is not None:  # part of the background: regions keep their calibration
        se, sn, sig_e, sig_n, height = layout.shoal
        z = z + height * np.exp(-0.5 * (((ee - se) / sig_e) ** 2 + ((nn - sn) / sig_n) ** 2))
    for region, zr in parts[1:]:
        w = region_weight(ee, nn, region)
        z = (1 - w) * z + w * zr

    lo, hi = layout.depth_limits_m
    if layout.median_m is not None:
        # shift the background only (outside every region) so the map median hits the target
        outside = np.ones_like(z)
        for region in layout.regions:
            outside *= 1 - region_weight(ee, nn, region)
        a, b = -50.0, 50.0
        for _ in range(60):
            mid = 0.5 * (a + b)
            if np.median(np.clip(z + mid * outside, lo, hi)) < layout.median_m:
                a = mid
            else:
                b = mid
        z = z + 0.5 * (a + b) * outside
    z = np.clip(z, lo, hi)
    return Map(z=z, e0=float(e[0]), n0=float(n[0]), res_e=res, res_n=res,
               name=f"synthetic:{layout.name}:seed{seed}",
               meta={"kind": "synthetic", "layout": layout.name, "seed": seed})
