"""File terrains reshaped into other test worlds (terrain/reshape.py; issue 24): resampling, depth
rescaling and transforms against the plain reference, and configs/relief.yaml's world equal to the
real-relief world R1 of examples/prototypes/worlds.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pydantic import ValidationError

from tanbench.config import Scenario, TerrainSpec
from tanbench.errors import TanbenchError
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


def test_resampled_shape_is_the_grid_reshape_builds():
    """The node counts the size check uses are np.arange's, for spacings on and off the grid's."""
    from tanbench.terrain.reshape import resampled_shape

    rng = np.random.default_rng(4)
    for _ in range(500):
        ny, nx = rng.integers(2, 200, 2)
        grid = Map(np.zeros((ny, nx)), *rng.uniform(-1e4, 1e4, 2), *rng.uniform(0.1, 20.0, 2))
        for r in (grid.res_e, grid.res_n, 3 * grid.res_e, float(rng.uniform(0.05, 50.0))):
            e = np.arange(0.0, grid.e_max - grid.e0 + 1e-9, r)
            n = np.arange(0.0, grid.n_max - grid.n0 + 1e-9, r)
            assert resampled_shape(grid, r) == (n.size, e.size)


def test_resample_too_fine_is_refused_naming_resample_m_before_allocating(monkeypatch):
    """1 cm nodes over 1 km: 1e10 nodes; refused with the setting named and the finest spacing that fits,
    before any array of that size exists (np.meshgrid must not be reached)."""
    from tanbench.terrain import reshape

    def no_meshgrid(*args, **kwargs):
        raise AssertionError("the resampled grid was allocated")

    monkeypatch.setattr(reshape.np, "meshgrid", no_meshgrid)
    grid = Map(np.zeros((201, 201)), 0.0, 0.0, 5.0, 5.0)
    for memory, limit in ((None, "2.15e+09 that a map may have"),
                          (64e9, "1e+09 that fit in half of this machine's 64 GB")):
        monkeypatch.setattr(reshape, "physical_memory", lambda: memory)
        with pytest.raises(TanbenchError) as info:
            reshape_terrain(grid, 0.01, None, "none")
        msg = str(info.value)
        assert msg.startswith("terrain.resample_m (0.01 m) resamples the 1000 x 1000 m grid onto 100001 x 100001 "
                              "nodes (1e+10), more than the " + limit), msg
        finest = float(msg.rsplit("at least ", 1)[1].split(" m")[0])
        ny, nx = reshape.resampled_shape(grid, finest)
        assert ny * nx <= (2**31 - 1 if memory is None else memory / 2 / reshape.BYTES_PER_RESAMPLED_NODE)
        assert "sensors" not in msg and "\n" not in msg


def test_resample_coarser_than_the_grid_is_refused():
    grid = Map(np.zeros((21, 41)), 0.0, 0.0, 5.0, 5.0)  # 200 x 100 m
    with pytest.raises(TanbenchError, match=r"terrain.resample_m \(150 m\) resamples the 200 x 100 m grid onto "
                                            r"2 x 1 nodes; a map needs at least 2 x 2: use a resample_m of at most "
                                            r"100 m"):
        reshape_terrain(grid, 150.0, None, "none")
    assert reshape_terrain(grid, 100.0, None, "none").shape == (2, 3)
