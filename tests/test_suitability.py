"""Terrain suitability: kernels against numpy, closed forms on planes, GeoTIFF round trip, CLI."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from tanbench.sensors.sonar import dvl_beam_vectors
from tanbench.terrain.grid import Map
from tanbench.suitability import (ping_information_grid, predicted_std, suitability, window_stats,
                                          window_stats_numpy, write_geotiff)

SEED = 1515


def plane(grad=(0.05, 0.0), noise=0.0, shape=(40, 50), res=10.0, seed=SEED) -> Map:
    rng = np.random.default_rng(seed)
    n, e = np.mgrid[0:shape[0], 0:shape[1]] * res
    return Map(z=-60 + grad[0] * e + grad[1] * n + noise * rng.standard_normal(shape), e0=0.0, n0=0.0,
               res_e=res, res_n=res, name="plane")


def test_window_stats_kernel_matches_numpy():
    z = plane(grad=(0.03, -0.02), noise=1.0, shape=(17, 23)).z.copy()
    z[4, 5] = np.nan
    got = window_stats(z, 5, 3)
    ref = window_stats_numpy(z, 5, 3)
    for g, r in zip(got, ref):
        np.testing.assert_allclose(g, r, rtol=1e-9, atol=1e-12, equal_nan=True)


def test_plane_has_no_roughness_and_flat_keeps_the_prior():
    tilted = suitability(plane(), dvl_beam_vectors(30, (0, 90, 180, 270)), 30.0, 0.5, 10, 150.0)
    assert np.nanmax(tilted.layers["roughness_m"]) < 1e-9
    assert np.nanmax(tilted.layers["slope_std_deg"]) < 1e-6
    flat = suitability(plane(grad=(0.0, 0.0)), dvl_beam_vectors(30, (0, 90, 180, 270)), 30.0, 0.5, 10, 150.0)
    np.testing.assert_allclose(flat.layers["predicted_std_m"], math.sqrt(2 * 150.0**2 / 12), rtol=1e-12)


def test_ping_information_on_a_plane_is_the_closed_form():
    """East-tilted plane, level DVL: J_EE = sum_i g^2 / (sigma^2 (b_u - g b_e)^2), mean over headings."""
    g, sigma, alt = 0.05, 0.5, 30.0
    grid = plane(grad=(g, 0.0))
    beams = dvl_beam_vectors(30, (0, 90, 180, 270))
    info = ping_information_grid(grid, beams, alt, sigma)
    t = math.radians(30)
    expect = 0.0
    headings = (0.0, 22.5, 45.0, 67.5)
    for h in headings:
        for az in (0, 90, 180, 270):
            b_e = math.sin(t) * math.sin(math.radians(h + az))  # compass azimuth of the beam
            expect += g**2 / (sigma**2 * (-math.cos(t) - g * b_e) ** 2)
    expect /= len(headings)
    inner = info[10:30, 10:40]
    np.testing.assert_allclose(inner[..., 0, 0], expect, rtol=1e-9)
    np.testing.assert_allclose(inner[..., 1, 1], 0.0, atol=1e-12)
    std = predicted_std(inner, 10, 150.0**2 / 12)
    np.testing.assert_allclose(std, np.sqrt(1 / (12 / 150**2 + 10 * expect) + 150**2 / 12), rtol=1e-9)


def test_geotiff_round_trip(tmp_path):
    pytest.importorskip("tifffile")
    from tanbench.terrain.files import read_grid

    grid = plane(grad=(0.02, 0.01), noise=0.3, shape=(12, 15), res=5.0)
    grid = Map(z=grid.z, e0=100.0, n0=200.0, res_e=5.0, res_n=5.0)
    path = tmp_path / "z.tif"
    write_geotiff(grid.z, grid, path)
    back = read_grid(path)
    np.testing.assert_allclose(back.z, grid.z.astype(np.float32), rtol=1e-6)
    assert (back.e0, back.n0, back.res_e, back.res_n) == (100.0, 200.0, 5.0, 5.0)


def test_area_a_gives_more_information_than_area_b():
    from tanbench.config import Scenario
    from tanbench.simulation import motion_plan
    from tanbench.terrain import navigation_map
    from tanbench.suitability import track_summary
    from tanbench.vehicle.trajectory import sample_path

    sc = Scenario(area="A")
    result = suitability(navigation_map(sc.terrain, 10.0), dvl_beam_vectors(30, (0, 90, 180, 270)), 40.0,
                         1 / math.sqrt(3), 10, 150.0)
    tracks = [(area, sample_path(motion_plan(Scenario(area=area)), 5.0)[1][:, :2]) for area in "AB"]
    a, b = track_summary(result, tracks)
    assert a["mean_information_per_ping"] > 5 * b["mean_information_per_ping"]
    assert a["mean_predicted_std_m"] < b["mean_predicted_std_m"]


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "tanbench.cli", *args], capture_output=True, text=True, cwd=cwd)


@pytest.mark.parametrize("args, message", [
    (["nonexistent.tif"], "no such map or sweep file"),
    (["configs/quick.yaml", "--sensor", "usbl"], "--sensor must be dvl or sbe"),
])
def test_cli_bad_input(args, message, tmp_path):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    res = _cli("terrain", "suitability", *args, "--out", str(tmp_path / "o"), cwd=root)
    assert res.returncode == 2, res.stderr
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("error: ") and message in res.stderr


def test_cli_map_file(tmp_path):
    pytest.importorskip("tifffile")
    pytest.importorskip("matplotlib")
    grid = plane(grad=(0.03, 0.01), noise=0.5, shape=(30, 40))
    src = tmp_path / "map.tif"
    write_geotiff(grid.z, grid, src)
    res = _cli("terrain", "suitability", str(src), "--out", str(tmp_path / "o"), "--sensor", "sbe")
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "o" / "map-sbe.png").exists()
    assert (tmp_path / "o" / "map-sbe-predicted_std_m.tif").exists()
    res = _cli("terrain", "suitability", str(src), "--track", "--out", str(tmp_path / "o"))
    assert res.returncode == 2 and "needs a sweep file" in res.stderr
