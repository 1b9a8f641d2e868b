"""File terrains: a format registered from outside the package, and the content identity of map files.

The toy format (``toy_grid.py``, beside this file) is unknown to tanbench: registering it
must be all it takes to read its files through ``terrain: {kind: file}`` (by suffix or by
``format:``), in this process and, through the maps the client ships, in worker processes
that never import it; and as an installed plug-in (an entry point), in the CLI.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from tanbench.config import TerrainSpec
from tanbench.errors import TanbenchError
from tanbench.terrain import truth_map
from tanbench.terrain.files import terrain_content_hash
from tanbench.terrain.formats import FORMATS, register_format
from sweep_support import cli
from toy_grid import SUFFIX, read_toy, write_toy

RES = 5.0
N = 161  # nodes per side: 0..800 m


def seafloor(e, n):
    return -70.0 + 6.0 * np.sin(e / 45.0) * np.cos(n / 65.0) + 2.5 * np.cos(e / 19.0 + n / 37.0)


@pytest.fixture
def toy_format():
    register_format("toy", (SUFFIX,), read_toy, aliases=("toy-grid",))
    yield
    FORMATS.pop("toy")


@pytest.fixture
def grid():
    e = np.arange(N) * RES
    return seafloor(e[None, :], e[:, None])


def test_a_registered_format_reads_through_file_terrains(tmp_path, toy_format, grid):
    """By suffix, and by `format:` (name or alias) for a file with another suffix."""
    write_toy(tmp_path / "sea.toygrid", grid, e0=100.0, n0=-50.0)
    m = truth_map(TerrainSpec(kind="file", path=str(tmp_path / "sea.toygrid")))
    assert m.shape == (N, N) and (m.e0, m.n0, m.res_e, m.res_n) == (100.0, -50.0, RES, RES)
    np.testing.assert_array_equal(m.z, grid)  # the values round-trip exactly, row 0 south
    j, i = np.array([0, 7, 160]), np.array([3, 150, 160])
    np.testing.assert_array_equal(m.elevation(100.0 + RES * j, -50.0 + RES * i), seafloor(RES * j, RES * i))
    assert m.meta["format"] == "toy" and m.meta["kind"] == "file"

    shutil.copy(tmp_path / "sea.toygrid", tmp_path / "sea.txt")
    by_alias = truth_map(TerrainSpec(kind="file", path=str(tmp_path / "sea.txt"), format="toy-grid"))
    np.testing.assert_array_equal(by_alias.z, m.z)
    assert by_alias.meta["format"] == "toy"


def test_unknown_format_names_the_registered_ones(tmp_path, toy_format):
    (tmp_path / "x.grd").write_text("")
    with pytest.raises(TanbenchError, match=r"x.grd: unknown grid format 'surfer'; known formats: geotiff .*toy \(.toygrid\)"):
        truth_map(TerrainSpec(kind="file", path=str(tmp_path / "x.grd"), format="surfer"))


def test_a_suffix_belongs_to_one_format():
    with pytest.raises(TanbenchError, match="suffix '.tif' is already read as 'geotiff'"):
        register_format("other-tiff", (".tif",), read_toy)
    assert "other-tiff" not in FORMATS


def toy_sweep(path, map_path, runs=1) -> Path:
    """A short sweep over a toy-format map around a survey track."""
    data = {
        "name": "toy", "seed": 5, "runs": runs, "methods": ["tight-dvl"],
        "scenario": {
            "area": "custom", "particles": 60, "duration_s": 30,
            "terrain": {"kind": "file", "path": str(map_path)},
            "trajectory": {"kind": "survey", "centre_en_m": [400, 400], "heading_deg": 0, "leg_length_m": 200,
                           "leg_spacing_m": 80, "legs": 2, "depth_m": 20},
        },
    }
    path.write_text(yaml.safe_dump(data))
    return path


def test_workers_run_a_sweep_on_a_format_they_never_imported(tmp_path, toy_format, grid, monkeypatch):
    """The worker process (spawned, without the toy format) gets the map from the client: runs are ok."""
    import multiprocessing

    from tanbench.runner import executors
    from tanbench.runner.engine import run_sweep
    from tanbench.sweep import load_sweep

    # spawned, whatever this process is (a forked worker would have the format this process registered)
    monkeypatch.setattr(executors, "local_context", lambda: multiprocessing.get_context("spawn"))

    write_toy(tmp_path / "sea.toygrid", grid)
    toy_sweep(tmp_path / "toy.yaml", tmp_path / "sea.toygrid")
    report = run_sweep(load_sweep(tmp_path / "toy.yaml"), tmp_path / "out", workers=1, progress=False,
                       echo=lambda *a: None)
    runs = pd.read_parquet(tmp_path / "out" / "runs")
    assert report.failed_rows == 0 and len(runs) == 1, report.errors
    assert runs["status"].tolist() == ["ok"] and np.isfinite(runs["final_horizontal_error_m"]).all()


@pytest.mark.slow
def test_an_installed_format_plug_in_works_in_the_cli(tmp_path, grid):
    """A module named under the `tanbench.formats` entry points is all `tanbench run` needs."""
    plugins = tmp_path / "site"
    (plugins / "toy_plugin-0.1.dist-info").mkdir(parents=True)
    (plugins / "toy_plugin-0.1.dist-info" / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-plugin\nVersion: 0.1\n")
    (plugins / "toy_plugin-0.1.dist-info" / "entry_points.txt").write_text("[tanbench.formats]\ntoy = toy_plugin\n")
    (plugins / "toy_plugin.py").write_text(
        "from tanbench.terrain.formats import register_format\n"
        "from toy_grid import SUFFIX, read_toy\n"
        "register_format('toy', (SUFFIX,), read_toy)\n")
    path = os.pathsep.join([str(plugins), str(Path(__file__).parent)])
    write_toy(tmp_path / "sea.toygrid", grid)
    sweep = toy_sweep(tmp_path / "toy.yaml", tmp_path / "sea.toygrid")
    proc = cli("run", sweep, "--out", tmp_path / "out", "--workers", 1, "-q", extra_path=path)
    assert proc.returncode == 0, proc.stderr
    runs = pd.read_parquet(tmp_path / "out" / "runs")
    assert runs["status"].tolist() == ["ok"], runs["error"].tolist()

    proc = cli("validate", sweep)  # without the plug-in: one line naming the known formats
    assert proc.returncode == 2 and "sea.toygrid: cannot tell the grid format from the extension '.toygrid'" in proc.stderr
    (plugins / "toy_plugin.py").write_text("raise RuntimeError('broken on purpose')\n")
    proc = cli("validate", sweep, extra_path=path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert "grid format plug-in 'toy' (toy_plugin) does not load: RuntimeError: broken on purpose" in proc.stderr


def test_content_hash_follows_the_bytes_not_the_names(tmp_path, grid):
    """Same content, same hash (also under another name); an edit changes it, and so does tile order."""
    np.save(tmp_path / "a.npy", grid)
    spec = TerrainSpec(kind="file", path=str(tmp_path / "a.npy"), origin=(0, 0), resolution=RES)
    first = terrain_content_hash(spec)
    assert len(first) == 64 and int(first, 16) >= 0
    assert terrain_content_hash(spec) == first

    shutil.copy(tmp_path / "a.npy", tmp_path / "b.npy")
    assert terrain_content_hash(spec.model_copy(update={"path": str(tmp_path / "b.npy")})) == first

    edited = grid.copy()
    edited[80, 80] += 0.01
    np.save(tmp_path / "a.npy", edited)
    stat = os.stat(tmp_path / "a.npy")
    os.utime(tmp_path / "a.npy", ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000))  # a later edit
    assert terrain_content_hash(spec) not in (first, None)

    np.save(tmp_path / "a.npy", grid)
    os.utime(tmp_path / "a.npy", ns=(stat.st_atime_ns, stat.st_mtime_ns + 2_000_000))
    assert terrain_content_hash(spec) == first  # the content is back

    np.save(tmp_path / "c.npy", edited)
    pair = terrain_content_hash(spec.model_copy(update={"path": [str(tmp_path / "a.npy"), str(tmp_path / "c.npy")]}))
    swapped = terrain_content_hash(spec.model_copy(update={"path": [str(tmp_path / "c.npy"), str(tmp_path / "a.npy")]}))
    assert len({pair, swapped, first}) == 3
    glob_spec = spec.model_copy(update={"path": str(tmp_path / "[ac].npy")})
    assert terrain_content_hash(glob_spec) == pair  # a glob's matches in sorted order


def test_content_hash_of_a_synthetic_terrain_is_none():
    assert terrain_content_hash(TerrainSpec()) is None


@pytest.mark.skipif(not (Path(__file__).resolve().parents[1].parent / "shared" / "data" / "monterey").is_dir(),
                    reason="the Monterey tiles (../shared/data/monterey) are not here")
def test_terrain_info_places_a_lonlat_map_on_the_globe():
    """``tanbench terrain info`` of the Monterey tiles (Web Mercator, projected to the local frame): the extent in
    metres and the lon/lat of the south-west and north-east nodes, from the map's own projection."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-m", "tanbench", "terrain", "info",
                           "../shared/data/monterey/MontereyBay.R_*.tif"], cwd=root, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    line = proc.stdout.splitlines()[0]
    assert "227 x 227 nodes" in line and "frame local" in line
    assert "E 0.0, N 0.0 m is lon -121.82546, lat 36.78954" in line
