"""The Monterey Canyon example: real tiles read in place, the three methods run over them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tanbench.sweep import load_sweep

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "monterey"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"Monterey tiles not present at {DATA}")


@pytest.fixture()
def at_root(monkeypatch):
    """Run from the project root, as configs/monterey.yaml's relative paths expect."""
    monkeypatch.chdir(ROOT)


def test_monterey_sweep_validates_and_has_real_relief(at_root):
    """configs/monterey.yaml reads the four tiles; the track crosses the canyon."""
    from tanbench.runner.validate import validate_worlds
    from tanbench.simulation import motion_plan
    from tanbench.terrain import truth_map
    from tanbench.terrain.stats import track_statistics
    from tanbench.vehicle.trajectory import sample_path

    sweep = load_sweep(ROOT / "configs" / "monterey.yaml")
    validate_worlds(sweep)
    sc = sweep.cells[0].scenario
    truth = truth_map(sc.terrain)
    assert truth.meta["kind"] == "file" and len(truth.meta["path"]) == 4
    _, pos = sample_path(motion_plan(sc), 1.0)
    stats = track_statistics(truth, pos[:, :2])
    assert stats["depth_std_m"] > 20.0  # much rougher than the paper's area A (13.2 m)
    assert stats["off_map_points"] == 0


def test_monterey_one_short_run_per_method(at_root):
    """One shortened run of each method over the canyon finishes with finite errors."""
    from tanbench.methods.registry import builtin_names
    from tanbench.methods import run_method
    from tanbench.simulation import simulate_vehicle

    sc = load_sweep(ROOT / "configs" / "monterey.yaml").cells[0].scenario
    sensors = sc.sensors.model_copy(update={"multibeam_beams": 8})  # the multibeam methods take part too
    sc = sc.model_copy(update={"duration_s": 120.0, "particles": 500, "sensors": sensors})
    vehicle = simulate_vehicle(sc, np.random.SeedSequence(3))
    assert np.isfinite(vehicle.obs.dvl_ranges).mean() > 0.9
    for method in builtin_names():
        m = run_method(sc, method, vehicle, np.random.SeedSequence(4)).metrics
        assert np.isfinite(m["final_horizontal_error_m"])
