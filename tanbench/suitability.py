"""Terrain suitability for TAN: where on a map does a ping tell the filter the most?

Per node of a navigation map, four measures (docs/model.md, section 9.3):

* **predicted position std after N pings** (``predicted_std_m``): the Fisher information
  J_ping of one ping of the sensor (``bounds.pcrb.ping_information``: beam geometry, the
  map's gradient at the footprints, range noise of std ``noise_m / sqrt(3)``) with the
  vehicle level at ``altitude_m`` above the node, averaged over headings (0, 22.5, 45
  and 67.5 deg: with the Janus DVL's 90-deg symmetry, every 22.5 deg); the N pings are
  spread over the window around the node (the vehicle moves; one nadir beam alone would
  only ever see one gradient direction), so J_ping is averaged over the window; then
  ``sqrt(trace((J_prior + N mean J_ping)^-1))`` with the filter's initial square as the
  prior (variance side^2 / 12 per axis). Small is good; a flat node keeps the prior's
  std. ``information_per_ping`` is ``trace(J_ping)`` at the node (1/m^2).
* **slope std** (``slope_std_deg``): the standard deviation of the slope angle over a
  square window of side ``window_m`` (default 50 m, about the DVL footprint spread at
  30 m altitude);
* **roughness** (``roughness_m``): the RMS of the elevations' residuals from the
  window's least-squares plane (relief that a plane does not explain);
* **terrain entropy** (``entropy``): the Shannon entropy of the window's absolute
  elevation deviations from their mean, normalised as a distribution, divided by the
  log of the number of nodes (0..1). Relief concentrated in a few nodes (a distinctive
  feature) gives low entropy; evenly spread deviations (noise-like relief or a tilted
  plane) give values near 1.

Windows shrink at the map edges and skip NaN nodes.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import ndimage

from tanbench.bounds.pcrb import ping_information, range_sensitivities
from tanbench.config import FilterSpec, Scenario, SensorSpec, TerrainSpec
from tanbench.errors import TanbenchError
from tanbench.plot import pyplot
from tanbench.sensors.multibeam import sensor_fan
from tanbench.sensors.sonar import altimeter_beam_vectors, dvl_beam_vectors
from tanbench.simulation import motion_plan
from tanbench.sweep import load_sweep
from tanbench.terrain import navigation_map, truth_map
from tanbench.terrain.grid import Map
from tanbench.terrain.stats import gradient, slope_deg
from tanbench.terrain.windows import window_stats, window_stats_numpy  # noqa: F401 - the numpy twin for the tests
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy
from tanbench.vehicle.trajectory import sample_path

HEADINGS_DEG = (0.0, 22.5, 45.0, 67.5)
MEASURES = ("predicted_std_m", "information_per_ping", "slope_std_deg", "roughness_m", "entropy")


@dataclass
class Suitability:
    """The measures as grids on the map's nodes (same shape as ``grid.z``)."""

    grid: Map
    layers: dict[str, np.ndarray]
    pings: int
    altitude_m: float
    sensor: str

    def along(self, e: np.ndarray, n: np.ndarray) -> dict[str, np.ndarray]:
        """Each measure interpolated (bilinearly) at points."""
        return {name: Map(z=v, e0=self.grid.e0, n0=self.grid.n0, res_e=self.grid.res_e,
                          res_n=self.grid.res_n).elevation(e, n)
                for name, v in self.layers.items()}


def ping_information_grid(grid: Map, beams_body: np.ndarray, altitude_m: float, range_std_m: float,
                          headings_deg=HEADINGS_DEG) -> np.ndarray:
    """J_ping (ny, nx, 2, 2) of one level ping at ``altitude_m`` over every node, mean over headings."""
    ee, nn = np.meshgrid(*grid.node_coords())
    info = np.zeros(grid.z.shape + (2, 2))
    for heading in headings_deg:
        yaw = -math.radians(heading)
        b_nav = beams_body @ dcm_body_to_nav_numpy(np.zeros(1), np.zeros(1), np.array([yaw]))[0].T  # (m, 3)
        r = altitude_m / -b_nav[:, 2]  # range to a level seafloor at the node's depth
        fe = ee[..., None] + r * b_nav[:, 0]
        fn = nn[..., None] + r * b_nav[:, 1]
        ge, gn = gradient(grid, fe, fn)
        sens = range_sensitivities(ge, gn, np.broadcast_to(b_nav, fe.shape + (3,)), np.broadcast_to(r, fe.shape))
        info += ping_information(sens, range_std_m, 2)
    info /= len(headings_deg)
    info[np.isnan(grid.z)] = np.nan
    return info


def predicted_std(info: np.ndarray, pings: int, prior_var_m2: float) -> np.ndarray:
    """sqrt(trace((I / prior_var + pings * info)^-1)) per node (closed-form 2 x 2 inverse)."""
    a = info[..., 0, 0] * pings + 1.0 / prior_var_m2
    d = info[..., 1, 1] * pings + 1.0 / prior_var_m2
    b = info[..., 0, 1] * pings
    return np.sqrt((a + d) / (a * d - b * b))


def _window_nodes(grid: Map, window_m: float) -> tuple[int, int]:
    return (max(1, int(round(window_m / grid.res_n))) | 1, max(1, int(round(window_m / grid.res_e))) | 1)


def _nan_box_mean(v: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    ok = ~np.isnan(v)
    num = ndimage.uniform_filter(np.where(ok, v, 0.0), size=size, mode="constant")
    den = ndimage.uniform_filter(ok.astype(float), size=size, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 1e-12, num / den, np.nan)


def slope_std(grid: Map, window_m: float) -> np.ndarray:
    """Std of the slope angle (deg) over the window around each node."""
    ee, nn = np.meshgrid(*grid.node_coords())
    s = slope_deg(grid, ee, nn)
    size = _window_nodes(grid, window_m)
    m1, m2 = _nan_box_mean(s, size), _nan_box_mean(s * s, size)
    return np.sqrt(np.maximum(m2 - m1 * m1, 0.0))


def roughness(grid: Map, window_m: float) -> np.ndarray:
    """RMS residual (m) of the window's elevations about their least-squares plane."""
    return window_stats(grid.z, *_window_nodes(grid, window_m))[0]


def entropy(grid: Map, window_m: float) -> np.ndarray:
    """Normalised Shannon entropy of the window's absolute elevation deviations (0..1)."""
    return window_stats(grid.z, *_window_nodes(grid, window_m))[1]


def suitability(grid: Map, beams_body: np.ndarray, altitude_m: float, range_std_m: float, pings: int,
                initial_area_m: float, window_m: float = 50.0, sensor: str = "dvl") -> Suitability:
    """Every measure of the module docstring on ``grid``'s nodes."""
    info = ping_information_grid(grid, beams_body, altitude_m, range_std_m)
    size = _window_nodes(grid, window_m)
    # the N pings are spread over the window around the node (the vehicle moves): mean J_ping there
    spread = np.stack([np.stack([_nan_box_mean(info[..., i, j], size) for j in range(2)], -1) for i in range(2)], -2)
    spread[np.isnan(grid.z)] = np.nan
    rough, ent = window_stats(grid.z, *size)
    layers = {
        "predicted_std_m": predicted_std(spread, pings, initial_area_m**2 / 12.0),
        "information_per_ping": info[..., 0, 0] + info[..., 1, 1],
        "slope_std_deg": slope_std(grid, window_m),
        "roughness_m": rough,
        "entropy": ent,
    }
    return Suitability(grid=grid, layers=layers, pings=pings, altitude_m=altitude_m, sensor=sensor)


def write_geotiff(values: np.ndarray, grid: Map, path) -> None:
    """One band of ``values`` on ``grid``'s nodes as a metric GeoTIFF (PixelIsPoint, north up)."""
    try:
        import tifffile
    except ImportError:
        raise TanbenchError("writing GeoTIFF needs tifffile: pip install 'tanbench[maps]'") from None
    geokeys = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 2, 3076, 0, 1, 9001]
    extratags = [
        (33550, "d", 3, (grid.res_e, grid.res_n, 0.0), True),
        (33922, "d", 6, (0.0, 0.0, 0.0, grid.e0, grid.n_max, 0.0), True),
        (34735, "H", len(geokeys), geokeys, True),
    ]
    tifffile.imwrite(path, np.ascontiguousarray(values[::-1].astype(np.float32)), extratags=extratags)


# ---- orchestration: maps and tracks from a bathymetry file or a sweep ------------------------
DEFAULT_ALTITUDE_M = 30.0


@dataclass
class Source:
    """One navigation map and the tracks over it, with the scenario numbers a ping needs."""

    label: str
    grid: Map
    altitude_m: float
    noise_m: float
    initial_area_m: float
    tracks: list[tuple[str, np.ndarray]]  # (label, (k, 2) east/north at 1 Hz)


def sources_from(target, altitude_m: float | None = None, noise_m: float | None = None) -> list[Source]:
    """A bathymetry file (the file's grid is the map) or a sweep YAML (each terrain's map and tracks)."""
    target = Path(target)
    if not target.exists():
        raise TanbenchError(f"{target}: no such map or sweep file")
    if target.suffix.lower() in (".yaml", ".yml"):
        return _sweep_sources(target, altitude_m, noise_m)
    grid = truth_map(TerrainSpec(kind="file", path=str(target)))
    return [Source(label=target.stem, grid=grid, altitude_m=altitude_m or DEFAULT_ALTITUDE_M,
                   noise_m=Scenario().noise_m if noise_m is None else noise_m,
                   initial_area_m=FilterSpec().initial_area_m, tracks=[])]


def _sweep_sources(path, altitude_m, noise_m) -> list[Source]:
    sweep = load_sweep(path)
    out: dict[str, Source] = {}
    seen_worlds: set[tuple[str, str]] = set()
    altitudes: dict[str, list[np.ndarray]] = {}
    for cell in sweep.cells:
        sc = cell.scenario
        key = json.dumps([sc.terrain.model_dump(mode="json"), sc.map_resolution_m], sort_keys=True)
        if key not in out:
            label = f"{sweep.name}-{_terrain_label(sc)}-{sc.map_resolution_m:g}m"
            out[key] = Source(label=label, grid=navigation_map(sc.terrain, sc.map_resolution_m),
                              altitude_m=altitude_m or 0.0, noise_m=sc.noise_m if noise_m is None else noise_m,
                              initial_area_m=sc.filter.initial_area_m, tracks=[])
            altitudes[key] = []
        world = sc.world_key()
        if (key, world) in seen_worlds:
            continue
        seen_worlds.add((key, world))
        _, pos = sample_path(motion_plan(sc), 1.0)
        floor = truth_map(sc.terrain).elevation(pos[:, 0], pos[:, 1])
        altitudes[key].append(pos[:, 2] - floor)
        out[key].tracks.append((f"area {sc.area}" if sc.area != "custom" else "survey", pos[:, :2]))
    for key, src in out.items():
        if altitude_m is None:
            src.altitude_m = float(np.nanmedian(np.concatenate(altitudes[key])))
    return list(out.values())


def _terrain_label(sc) -> str:
    t = sc.terrain
    return f"{t.layout}-seed{t.seed}" if t.kind == "synthetic" else "file"


def sensor_beams(sensor: str, scenario=None, sensors=None) -> np.ndarray:
    """Body-frame beams of ``dvl`` (the scenario's Janus geometry), ``sbe`` or ``mbe`` (the multibeam's fan
    of ``sensors``, a ``SensorSpec``, or the scenario's)."""
    s = sensors if sensors is not None else scenario.sensors if scenario is not None else SensorSpec()
    if sensor == "mbe":
        return sensor_fan(s)[1]
    return dvl_beam_vectors(s.beam_tilt_deg, s.beam_azimuths_deg) if sensor == "dvl" else altimeter_beam_vectors()


def track_summary(result: Suitability, tracks) -> list[dict]:
    """Mean of each measure along each track (1 Hz points; NaN points left out)."""
    rows = []
    for label, pos in tracks:
        vals = result.along(pos[:, 0], pos[:, 1])
        rows.append({"track": label, "points": int(pos.shape[0]),
                     **{f"mean_{k}": _nan_mean(v) for k, v in vals.items()}})
    return rows


def _nan_mean(v: np.ndarray) -> float:
    """Mean of the values that are not NaN; NaN (no warning) where every value is."""
    v = v[~np.isnan(v)]
    return float(v.mean()) if v.size else float("nan")


def plot_suitability(result: Suitability, tracks, path) -> None:
    """A PNG of the predicted std and the classical measures, with the tracks drawn."""
    import matplotlib
    plt = pyplot()
    g = result.grid
    extent = (g.e0 - g.res_e / 2, g.e_max + g.res_e / 2, g.n0 - g.res_n / 2, g.n_max + g.res_n / 2)
    panels = [("predicted_std_m", f"predicted position std after {result.pings} pings (m)", "viridis_r"),
              ("slope_std_deg", "slope std (deg)", "magma"), ("roughness_m", "roughness (m)", "magma"),
              ("entropy", "terrain entropy", "cividis")]
    aspect = (extent[3] - extent[2]) / max(extent[1] - extent[0], 1e-9)
    fig, axes = plt.subplots(2, 2, figsize=(11, 2 * 5.5 * aspect + 1.5), squeeze=False)
    for ax, (name, title, cmap) in zip(axes.ravel(), panels):
        v = result.layers[name]
        shown = v[np.isfinite(v)]  # the colour scale's values; a layer may have none (a 2 x 2 map has no slope)
        if not shown.size:
            im = None
            ax.set_xlim(extent[:2])
            ax.set_ylim(extent[2:])
            ax.text(0.5, 0.5, "undefined on this map", transform=ax.transAxes, ha="center", va="center", fontsize=8)
        elif name == "predicted_std_m":
            im = ax.imshow(v, origin="lower", extent=extent, cmap=cmap,
                           norm=matplotlib.colors.LogNorm(vmin=max(shown.min(), 1e-3), vmax=shown.max()))
        else:
            im = ax.imshow(v, origin="lower", extent=extent, cmap=cmap, vmax=np.percentile(shown, 99))
        for label, pos in tracks:
            ax.plot(pos[:, 0], pos[:, 1], lw=0.9, color="white")
            ax.plot(pos[:, 0], pos[:, 1], lw=0.5, color="red", label=label)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("east (m)", fontsize=8)
        ax.set_ylabel("north (m)", fontsize=8)
        ax.tick_params(labelsize=7)
        if im is not None:
            fig.colorbar(im, ax=ax, shrink=0.8)
    fig.suptitle(f"{g.name}: {result.sensor.upper()} at {result.altitude_m:.0f} m altitude", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
