"""File terrains on a real Dask cluster: the client reads the map, the workers never do.

A `dask scheduler` and two `dask worker` processes run on 127.0.0.1, started in a
directory of their own (as on a cluster, where workers are other machines): a sweep whose
map is given by a relative path must give exactly the runs of local `--workers 2`.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from sweep_support import ROOT, assert_same_runs, cli, write_sweep

pytest.importorskip("distributed")
pytestmark = pytest.mark.slow  # each test starts CLI runs and workers: 15-70 s on 2 busy cores

DASK = Path(sys.executable).with_name("dask")
MONTEREY_CONFIG = ROOT / "configs" / "monterey.yaml"
MONTEREY_TILES = ROOT / ".." / "shared" / "data" / "monterey"
START_TIMEOUT_S = 90

MAP_SWEEP = {
    "name": "cluster-map",
    "seed": 4242,
    "runs": 2,
    "methods": ["tight-dvl", "loose-dvl"],
    "scenario": {
        "area": "custom", "particles": 80, "duration_s": 40,
        "terrain": {"kind": "file", "path": "maps/seafloor.npy", "origin": [0, 0], "resolution": 5.0},
        "trajectory": {"kind": "survey", "centre_en_m": [400, 400], "heading_deg": 0, "leg_length_m": 200,
                       "leg_spacing_m": 80, "legs": 2, "depth_m": 20},
    },
    "tables": {"maps": {"map_resolution_m": [10, 20]}},
}


def _worker_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    return env


def _stop(procs: list[subprocess.Popen]) -> None:
    """Terminate the processes this test started (each in its own session), then kill what is left."""
    for proc in procs:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
    deadline = time.monotonic() + 20
    for proc in procs:
        try:
            proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # the nanny's worker process too, if still there
        except ProcessLookupError:
            pass
        proc.wait()


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """The address of a scheduler with two single-threaded workers, all started in another directory."""
    if not DASK.exists():
        pytest.skip("the dask command is not installed next to this Python")
    from distributed import Client

    home = tmp_path_factory.mktemp("cluster-home")
    logs = home / "logs"
    logs.mkdir()
    scheduler_file = home / "scheduler.json"
    procs: list[subprocess.Popen] = []

    def start(name, *args):
        with open(logs / f"{name}.log", "w") as log:
            procs.append(subprocess.Popen([str(DASK), *args], cwd=home, env=_worker_env(), stdout=log,
                                          stderr=subprocess.STDOUT, start_new_session=True))

    try:
        start("scheduler", "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
              "--scheduler-file", str(scheduler_file))
        deadline = time.monotonic() + START_TIMEOUT_S
        while not scheduler_file.exists():
            assert procs[0].poll() is None, (logs / "scheduler.log").read_text()
            assert time.monotonic() < deadline, "the scheduler did not start"
            time.sleep(0.2)
        time.sleep(0.2)  # the file is written in one go, but give it a moment
        address = json.loads(scheduler_file.read_text())["address"]
        for k in range(2):
            start(f"worker-{k}", "worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--nworkers", "1",
                  "--no-dashboard", "--name", f"w{k}", "--local-directory", str(home / f"w{k}"))
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=START_TIMEOUT_S)
            cwds = client.run(os.getcwd)
        assert set(cwds.values()) == {str(home)}

        def add_worker(name):
            start(name, "worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--no-dashboard",
                  "--name", name, "--local-directory", str(home / name))
            return procs[-1]

        yield address, add_worker
    finally:
        _stop(procs)


def _runs(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "runs")


def _run_both_ways(sweep: Path, tmp_path: Path, address: str, cwd: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    local, dask = tmp_path / "local", tmp_path / "dask"
    proc = cli("run", sweep, "--out", local, "--workers", 2, "-q", cwd=cwd, timeout=600)
    assert proc.returncode == 0, proc.stderr
    proc = cli("run", sweep, "--out", dask, "--scheduler", address, "-q", cwd=cwd, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return _runs(local), _runs(dask)


def test_relative_map_path_on_a_cluster_matches_local_workers(cluster, tmp_path):
    """Workers in another directory get the client's map: every run ok, identical to local workers."""
    project = tmp_path / "project"
    (project / "maps").mkdir(parents=True)
    e = np.arange(0.0, 800.0 + 1e-9, 5.0)
    ee, nn = np.meshgrid(e, e)
    np.save(project / "maps" / "seafloor.npy",
            -70.0 + 6.0 * np.sin(ee / 45.0) * np.cos(nn / 65.0) + 2.5 * np.cos(ee / 19.0 + nn / 37.0))
    sweep = write_sweep(project / "sweep.yaml", MAP_SWEEP)
    local, dask = _run_both_ways(sweep.name, tmp_path, cluster[0], cwd=project)
    assert len(local) == 2 * 2 * 2 and (local["status"] == "ok").all(), local["error"].unique()
    assert_same_runs(local, dask)


@pytest.mark.skipif(not MONTEREY_TILES.is_dir(), reason="the Monterey tiles (../shared/data/monterey) are not here")
def test_monterey_on_a_cluster_matches_local_workers(cluster, tmp_path):
    """configs/monterey.yaml (shortened: 2 runs, 300 particles, 120 s) on the cluster and locally."""
    data = yaml.safe_load(MONTEREY_CONFIG.read_text())
    data["runs"] = 2
    data["scenario"].update(particles=300, duration_s=120)
    sweep = write_sweep(tmp_path / "monterey-short.yaml", data)
    local, dask = _run_both_ways(sweep, tmp_path, cluster[0], cwd=ROOT)
    assert len(local) == 2 * 2 * 3 and (local["status"] == "ok").all(), local["error"].unique()
    assert_same_runs(local, dask)


def test_a_worker_joining_later_gets_the_maps_and_they_go_with_the_sweep(cluster, tmp_path):
    """The maps reach a worker started after the executor opened; closing it removes them everywhere."""
    from distributed import Client

    from tanbench.config import TerrainSpec
    from tanbench.runner.executors import open_executor
    from tanbench.terrain import file_truth_maps, terrain_key

    def installed_terrain_keys() -> list[str]:  # defined here: the workers cannot import this module
        from tanbench.terrain import _INSTALLED

        return sorted(_INSTALLED)

    address, add_worker = cluster
    np.save(tmp_path / "flat.npy", np.full((20, 30), -40.0))
    spec = TerrainSpec(kind="file", path=str(tmp_path / "flat.npy"), origin=(0, 0), resolution=5.0)
    maps = file_truth_maps([spec])
    with Client(address, timeout="30s") as client:
        with open_executor(1, address, maps):
            late = add_worker("late")
            client.wait_for_workers(3, timeout=START_TIMEOUT_S)
            seen = client.run(installed_terrain_keys)
            assert len(seen) == 3 and all(keys == [terrain_key(spec)] for keys in seen.values()), seen
        assert all(keys == [] for keys in client.run(installed_terrain_keys).values())
        client.retire_workers([w for w, info in client.scheduler_info()["workers"].items()
                               if info.get("name") == "late"], close_workers=True)
    late.wait(timeout=60)
