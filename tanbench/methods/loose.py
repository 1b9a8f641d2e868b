"""Built-in method ``loose-dvl``: the loosely coupled position-only PF (filters/loose.py).

The beams are projected once per update with the navigation system's attitude; the
filter's converged estimate is fed back to the navigation system as a position fix.
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.registry import MethodRecord, register
from tanbench.methods.tight import divergence_bundle, resampling_bundle


def run_loose_dvl(ctx: MethodContext) -> MethodOutput:
    """The loosely coupled position-only particle filter feeding fixes to the navigation system."""
    from tanbench.filters.loose import LOOSE_COLS, init_loose, loose_filter_loop
    from tanbench.filters.params import LooseModel
    from tanbench.filters.rng import loop_rng
    from tanbench.filters.state import N_LOOSE
    from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

    sc, obs, nav, upd = ctx.scenario, ctx.obs, ctx.nav, ctx.updates.imu
    f = sc.filter
    T = sc.sampling_time_s
    half = f.initial_area_m / 2.0
    ranges = obs.dvl_ranges[ctx.updates.rows]
    c = dcm_body_to_nav_numpy(nav.pitch[upd], nav.roll[upd], nav.yaw[upd])  # (K, 3, 3)
    offsets = np.einsum("kij,bj->kbi", c, obs.dvl_beams) * ranges[:, :, None]
    d0 = np.ascontiguousarray(np.diff(nav.pos[upd, :2], axis=0))
    model = LooseModel(f.process_noise_velocity_mps * T,
                       math.radians(f.initial_std_heading_deg) if f.loose_heading_noise else 0.0,
                       f.measurement_noise_altitude_m, f.outside_map_sigma, f.loose_converged_std_m)
    rng = loop_rng(ctx.rng, f.random_numbers)
    x = np.empty((sc.particles, N_LOOSE))
    init_loose(x, rng, nav.pos[upd[0], 0], nav.pos[upd[0], 1], half)
    k = upd.size
    out_en, var, cov_en = np.empty((k, 2)), np.empty((k, 2)), np.empty(k)
    ess, reinit, fixed = np.empty(k), np.zeros(k, dtype=np.int64), np.zeros(k, dtype=np.int64)
    loose_filter_loop(x, rng, d0, np.ascontiguousarray(nav.pos[upd, :2]), nav.pos[upd, 2],
                      np.ascontiguousarray(offsets), ctx.nmap.kernel_args(), model,
                      resampling_bundle(f, LOOSE_COLS), divergence_bundle(f), half, out_en, var, cov_en, ess, reinit,
                      fixed)
    return MethodOutput(east=out_en[:, 0], north=out_en[:, 1], var_e=var[:, 0], var_n=var[:, 1], cov_en=cov_en,
                        ess=ess,
                        reinit=reinit.astype(bool), extra={"position_fix": fixed.astype(float)})


LOOSE_DVL = register(MethodRecord(
    name="loose-dvl", seed_id=3, builtin=True, run=run_loose_dvl, states=("east", "north"),
    series=("position_fix",),
    summary="a loosely coupled position-only particle filter feeding position fixes back to the navigation system",
    cost_ns=65.0, color="tab:purple", linestyle=":", bound=("dvl", "position")))
