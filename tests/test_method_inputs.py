"""What a method is given cannot be changed: by it for another method, nor for a later run.

Every array handed to a method (observations, navigation solution, map, updates) is
read-only, and each method gets its own copies of the objects holding them. A plug-in
that writes into its inputs fails its own run with one line naming it; a plug-in that
tries every other way to change them (attributes, options, the map's metadata, making an
array writeable again) changes nothing for tight-dvl after it in the same run, nor for the
runs after it in the same worker process.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sweep_support import cli, comparable, sweep_dict, write_sweep
from tanbench import results
from tanbench.errors import TanbenchError

WRITER = '''
def run(ctx):
    ctx.obs.dvl_ranges[:] += 50.0
    return {"east": ctx.nav.pos[ctx.updates.imu, 0], "north": ctx.nav.pos[ctx.updates.imu, 1]}
'''

MEDDLER = '''
import numpy as np

REFUSED = []


def attempt(what, change):
    try:
        change()
    except (ValueError, TypeError, AttributeError) as exc:
        REFUSED.append(what)


def run(ctx):
    obs, nav, nmap = ctx.obs, ctx.nav, ctx.nmap
    attempt("ranges", lambda: obs.dvl_ranges.__iadd__(50.0))
    attempt("map", lambda: nmap.z.__iadd__(40.0))
    attempt("nav", lambda: nav.pos.__setitem__((slice(None), 0), 0.0))
    attempt("ufunc out", lambda: np.add(obs.depth, 1.0, out=obs.depth))
    attempt("writeable again", lambda: nmap.z.setflags(write=True))
    attempt("a view's base", lambda: obs.gyro[::2].base.setflags(write=True))
    attempt("updates", lambda: ctx.updates.imu.__iadd__(1))
    obs.dt = 1.0  # its own copies: assignments stay in them
    nav.yaw = np.zeros(3)
    nmap.meta["map_error_m"] = 99.0
    for opts in ctx.scenario.method_options.values():
        opts.clear()
    assert len(REFUSED) == 7, REFUSED
    REFUSED.clear()
    upd = ctx.updates.imu
    return {"east": ctx.nav.pos[upd, 0], "north": ctx.nav.pos[upd, 1]}
'''


@pytest.fixture(scope="module")
def userland(tmp_path_factory):
    root = tmp_path_factory.mktemp("userland")
    (root / "plugs").mkdir()
    (root / "plugs" / "__init__.py").write_text("")
    (root / "plugs" / "writer.py").write_text(WRITER)
    (root / "plugs" / "meddler.py").write_text(MEDDLER)
    return root


def test_a_write_into_the_inputs_is_an_error_naming_the_method(userland, monkeypatch):
    from tanbench.config import Scenario
    from tanbench.methods import run_method
    from tanbench.simulation import simulate_vehicle

    monkeypatch.syspath_prepend(str(userland))
    sc = Scenario(duration_s=30, particles=60)
    vehicle = simulate_vehicle(sc, np.random.SeedSequence(1))
    ranges = vehicle.obs.dvl_ranges.copy()
    with pytest.raises(TanbenchError) as err:
        run_method(sc, "plugs.writer:run", vehicle, np.random.SeedSequence(2))
    message = str(err.value)
    assert message.startswith("method 'plugs.writer:run' tried to write into its inputs (ValueError: ")
    assert "read-only" in message and "(at writer.py:3)" in message and "\n" not in message
    np.testing.assert_array_equal(vehicle.obs.dvl_ranges, ranges)


def sweep_of(tmp_path, name, methods):
    data = sweep_dict(name=name, runs=2, methods=methods, tables={}, scenario={"method_options": {}})
    return write_sweep(tmp_path / f"{name}.yaml", data)


def test_no_method_changes_another_methods_or_a_later_runs_inputs(userland, tmp_path):
    """tight-dvl after the writer and the meddler, in one worker, equals tight-dvl alone."""
    alone = cli("run", sweep_of(tmp_path, "alone", ["tight-dvl"]), "--out", tmp_path / "alone", "--workers", 1,
                "-q")
    assert alone.returncode == 0, alone.stderr
    mixed = cli("run", sweep_of(tmp_path, "mixed", ["plugs.writer:run", "plugs.meddler:run", "tight-dvl"]),
                "--out", tmp_path / "mixed", "--workers", 1, "-q", extra_path=userland)
    assert mixed.returncode == 1, mixed.stderr  # the writer's runs failed
    runs = results.load(tmp_path / "mixed")
    writer = runs[runs["method"] == "plugs.writer:run"]
    assert (writer["status"] == "error").all()
    assert writer["error"].str.startswith("method 'plugs.writer:run' tried to write into its inputs").all()
    meddler = runs[runs["method"] == "plugs.meddler:run"]
    assert (meddler["status"] == "ok").all(), meddler["error"].tolist()
    keep = ["cell_id", "run", "method", "seed", "filter_seed", "status", "final_horizontal_error_m",
            "mean_horizontal_error_m", "final_heading_error_deg"]
    tight = comparable(runs[runs["method"] == "tight-dvl"])[keep].reset_index(drop=True)
    pd.testing.assert_frame_equal(tight, comparable(results.load(tmp_path / "alone"))[keep].reset_index(drop=True))


@pytest.mark.parametrize("world", ["synthetic", "monterey"])
def test_the_map_metadata_a_method_is_given_cannot_rebuild_the_truth(world):
    """The navigation map's metadata carried the truth's recipe (a synthetic terrain's layout and
    seed, the truth file's path, its name): with it a plug-in could rebuild the true terrain, which
    ``ctx.scenario.terrain`` withholds. A method is given only what a vehicle's own map carries."""
    import glob

    from tanbench.config import Scenario
    from tanbench.methods import method_context
    from tanbench.methods.api import NAVIGATION_MAP_META, NAVIGATION_MAP_NAME
    from tanbench.simulation import simulate_vehicle
    from tanbench.sweep import load_sweep
    from tanbench.terrain import navigation_map

    if world == "monterey":
        if not glob.glob("../shared/data/monterey/*.tif"):
            pytest.skip("the Monterey tiles of ../shared are not here")
        sc = load_sweep("configs/monterey.yaml").cells[0].scenario.model_copy(update={"particles": 60})
    else:
        sc = Scenario(duration_s=30, particles=60)
    full = navigation_map(sc.terrain, sc.map_resolution_m)
    assert {"seed", "path", "derived_from"} & set(full.meta)  # what there was to withhold
    ctx = method_context(sc, "tight-dvl", simulate_vehicle(sc, np.random.SeedSequence(1)), np.random.SeedSequence(2))
    assert set(ctx.nmap.meta) <= set(NAVIGATION_MAP_META)
    assert ctx.nmap.meta["map_error_m"] == full.meta["map_error_m"]
    assert ctx.nmap.name == NAVIGATION_MAP_NAME
    assert ctx.scenario.terrain is None
    assert full.name not in repr(ctx.nmap.meta)
