"""The field's other estimators (issue 14) end to end on simulated runs, through their plain-array drivers.

Thresholds were fixed before the runs were looked at (docs/methods.md, "Estimators").
"""

from __future__ import annotations

import numpy as np
import pytest

from tanbench.config import Scenario
from tanbench.filters import mpf
from tanbench.methods import update_indices
from tanbench.methods.mpf import MpfOptions
from tanbench.navigation.increments import NavAtUpdates, compute_increments
from tanbench.simulation import simulate_vehicle
from tanbench.terrain import navigation_map

SEED = 141414


@pytest.mark.parametrize("run", [0, 1])
def test_mpf_estimates_a_depth_bias(run):
    """A 3 m depth (tide) bias added to the navigation system's up coordinate: the MPF's per-particle
    Kalman filters find it (within 0.6 m after 400 s) and the position stays within 10 m."""
    sc = Scenario(duration_s=400.0)
    nmap = navigation_map(sc.terrain, sc.map_resolution_m)
    v = simulate_vehicle(sc, np.random.SeedSequence([SEED, run]))
    updates = update_indices(sc, v.obs)
    rows, upd = updates.rows, updates.imu
    nav = v.obs.nav
    inc = compute_increments(v.obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    tide = NavAtUpdates(nav.pos[upd, :2], nav.pos[upd, 2] + 3.0, nav.pitch[upd], nav.roll[upd], nav.yaw[upd])
    settings = mpf.mpf_settings(sc.model_copy(update={"particles": 500}), MpfOptions())
    out = mpf.run_mpf(tide, inc, v.obs.dvl_beams, v.obs.dvl_ranges[rows], nmap.kernel_args(),
                      np.random.default_rng([SEED, run]), settings)
    assert out["depth_bias_m"][-1] == pytest.approx(3.0, abs=0.6)
    err = np.hypot(out["est_e"][-1] - v.truth.pos[upd[-1], 0], out["est_n"][-1] - v.truth.pos[upd[-1], 1])
    assert err < 10.0
