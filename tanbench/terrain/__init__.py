"""Terrain: the true seafloor the sonar sees and the navigation maps the filters see.

``truth_map(spec)`` and ``navigation_map(spec, resolution_m)`` are cached per process,
keyed by the normalised terrain spec, so a sweep synthesises or reads each seafloor
and derives each map once per worker, not once per run; a synthetic seafloor is also
stored on disk (:mod:`tanbench.terrain.seafloor_cache`), so it is synthesised once per
machine and code version.

Workers never read map files: the process that runs a sweep reads each file terrain
once (:func:`file_truth_maps`) and ships the maps to its workers, which install them
with :func:`install_truth_maps`; ``truth_map`` then returns the installed map.
"""

from __future__ import annotations

import json
from functools import lru_cache

from tanbench.terrain import seafloor_cache
from tanbench.terrain.grid import Map
from tanbench.terrain.layouts import layout
from tanbench.terrain.synthetic import synthesize, with_roughness
from tanbench.config import TerrainSpec
from tanbench.terrain.derive import derive_navigation_map
from tanbench.terrain.files import load_file_terrain

__all__ = ["Map", "truth_map", "navigation_map", "file_truth_maps", "sweep_truth_maps", "install_truth_maps"]

# truth maps shipped to this process, by terrain key (see install_truth_maps)
_INSTALLED: dict[str, Map] = {}


def truth_map(spec) -> Map:
    """The true seafloor for a :class:`tanbench.config.TerrainSpec`."""
    return _truth(terrain_key(spec))


def navigation_map(spec, resolution_m: float) -> Map:
    """The navigation map at ``resolution_m`` derived from :func:`truth_map` (cached)."""
    return _navigation_cached(terrain_key(spec), float(resolution_m))


def file_truth_maps(specs) -> dict[str, Map]:
    """The truth maps of the file terrains among ``specs``, by terrain key, read here (once)."""
    return {terrain_key(spec): truth_map(spec) for spec in specs if spec.kind == "file"}


def sweep_truth_maps(specs) -> dict[str, Map]:
    """The truth maps of every terrain among ``specs`` (file or synthetic), by terrain key:
    what a sweep's workers are given so that none synthesises a seafloor again."""
    return {terrain_key(spec): truth_map(spec) for spec in specs}


def install_truth_maps(maps: dict[str, Map]) -> None:
    """Use these truth maps (from :func:`file_truth_maps` in another process) in this one.

    Navigation maps derived earlier are dropped, so none outlives the map it came from.
    """
    _INSTALLED.update(maps)
    _navigation_cached.cache_clear()


def uninstall_truth_maps(maps: dict[str, Map]) -> None:
    """Stop using these installed truth maps (those not replaced since)."""
    for key, grid in maps.items():
        if _INSTALLED.get(key) is grid:
            del _INSTALLED[key]
    _navigation_cached.cache_clear()


def terrain_key(spec) -> str:
    """The key a terrain spec's maps are cached by: its resolved spec as sorted JSON."""
    return json.dumps(spec.resolved().model_dump(mode="json"), sort_keys=True)


def synthesise_seafloor(spec) -> Map:
    """The synthetic seafloor of ``spec`` synthesised here (no cache, no store)."""
    resolved = spec.resolved()
    shape = with_roughness(layout(resolved.layout), resolved.region_hurst, resolved.region_corner_m)
    return synthesize(shape, resolved.seed, resolved.truth_resolution_m)


def clear_truth_maps() -> None:
    """Forget the truth maps built in this process (installed ones stay): the next one is read or built again."""
    _truth_cached.cache_clear()


def _truth(key: str) -> Map:
    installed = _INSTALLED.get(key)
    return installed if installed is not None else _truth_cached(key)


@lru_cache(maxsize=8)
def _truth_cached(key: str) -> Map:
    spec = TerrainSpec(**json.loads(key))
    if spec.kind == "synthetic":
        stored = seafloor_cache.load(key)
        if stored is not None:
            return stored
        grid = synthesise_seafloor(spec)
        seafloor_cache.store(key, grid)
        return grid
    return load_file_terrain(spec)


@lru_cache(maxsize=16)
def _navigation_cached(key: str, resolution_m: float) -> Map:
    spec = TerrainSpec(**json.loads(key))
    return derive_navigation_map(_truth(key), resolution_m, spec.map_error_m, spec.seed,
                                 spec.map_error_correlation_m)
