"""Terrain: the true seafloor the sonar sees and the navigation maps the filters see.

``truth_map(spec)`` and ``navigation_map(spec, resolution_m)`` are cached per process,
keyed by the normalised terrain spec, so a sweep synthesises or reads each seafloor
and derives each map once per worker, not once per run.
"""

from __future__ import annotations

import json
from functools import lru_cache

from tanbench.terrain.grid import Map

__all__ = ["Map", "truth_map", "navigation_map"]


def _key(spec) -> str:
    return json.dumps(spec.resolved().model_dump(mode="json"), sort_keys=True)


def truth_map(spec) -> Map:
    """The true seafloor for a :class:`tanbench.config.TerrainSpec`."""
    return _truth_cached(_key(spec))


def navigation_map(spec, resolution_m: float) -> Map:
    """The navigation map at ``resolution_m`` derived from :func:`truth_map` (cached)."""
    return _navigation_cached(_key(spec), float(resolution_m))


@lru_cache(maxsize=8)
def _truth_cached(key: str) -> Map:
    from tanbench.config import TerrainSpec

    spec = TerrainSpec(**json.loads(key))
    if spec.kind == "synthetic":
        from tanbench.terrain.layouts import layout
        from tanbench.terrain.synthetic import synthesize

        return synthesize(layout(spec.layout), spec.seed, spec.truth_resolution_m)
    from tanbench.terrain.files import load_file_terrain

    return load_file_terrain(spec)


@lru_cache(maxsize=16)
def _navigation_cached(key: str, resolution_m: float) -> Map:
    from tanbench.config import TerrainSpec
    from tanbench.terrain.derive import derive_navigation_map

    spec = TerrainSpec(**json.loads(key))
    return derive_navigation_map(_truth_cached(key), resolution_m, spec.map_error_m, spec.seed)
