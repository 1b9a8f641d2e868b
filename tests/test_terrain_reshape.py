"""File terrains reshaped into other test worlds (terrain/reshape.py; issue 24): resampling, depth
rescaling and transforms against the plain reference, and configs/relief.yaml's world equal to the
real-relief world R1 of examples/prototypes/worlds.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from tanbench.config import Scenario, TerrainSpec
from tanbench.terrain.grid import Map
from tanbench.terrain.reshape import reshape_terrain, reshape_terrain_numpy

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("transform", ["none", "transpose", "mirror-east"])
def test_reshape_matches_the_reference(transform):
    rng = np.random.default_rng(1)
    z = rng.normal(size=(23, 31)) * 10 - 100
    grid = Map(z, 5.0, -3.0, 8.3, 10.3)
    out = reshape_terrain(grid, 4.0, (-180.0, -60.0), transform)
    ref = reshape_terrain_numpy(z, 5.0, -3.0, 8.3, 10.3, 4.0, (-180.0, -60.0), transform)
    np.testing.assert_allclose(out.z, ref, rtol=1e-12, atol=1e-9)
    assert out.z.min() == pytest.approx(-180.0) and out.z.max() == pytest.approx(-60.0)
    assert (out.e0, out.n0, out.res_e, out.res_n) == (5.0, -3.0, 4.0, 4.0)
    assert reshape_terrain(grid, None, None, "none") is grid


def test_depth_range_must_be_ordered():
    with pytest.raises(ValidationError, match="low < high"):
        TerrainSpec(kind="file", path="x.npz", depth_range_m=(-60.0, -180.0))
    with pytest.raises(ValidationError):
        TerrainSpec(kind="synthetic", resample_m=8.0)  # a file setting on a synthetic terrain


def test_relief_config_is_the_prototype_world():
    import yaml

    from tanbench.terrain import truth_map
    from tanbench.terrain.files import read_tiles

    tiles = sorted((ROOT.parent / "shared" / "data" / "monterey").glob("MontereyBay.R_*.tif"))
    if not tiles:
        pytest.skip("the Monterey tiles are not here")
    sc = yaml.safe_load((ROOT / "configs" / "relief.yaml").read_text())["scenario"]
    spec = TerrainSpec(**{**sc["terrain"], "path": str(tiles[0].parent / "MontereyBay.R_*.tif")})
    m, _ = read_tiles(tiles, crs="epsg3857", rows="south_to_north")
    e = np.arange(0.0, m.e_max - m.e0 + 1e-9, 8.0)
    n = np.arange(0.0, m.n_max - m.n0 + 1e-9, 8.0)
    ee, nn = np.meshgrid(m.e0 + e, m.n0 + n)
    z = m.elevation(ee.ravel(), nn.ravel()).reshape(ee.shape)
    z = -180.0 + (z - z.min()) / (z.max() - z.min()) * 120.0  # worlds.build_relief, relief-r1
    np.testing.assert_array_equal(truth_map(spec).z, z)
    assert Scenario(**{**sc, "terrain": spec.model_dump()}).map_resolution_m == 24
