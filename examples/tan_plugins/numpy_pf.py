"""A small position-only particle filter in plain numpy, written against tanbench's plug-in API.

Per update: move the particles by the navigation system's displacement plus noise
(velocity noise, and the cross-track error a heading uncertainty causes), weight them by
the DVL beams' terrain altitude innovations against the navigation map (beams projected
with the navigation attitude), estimate, and resample systematically when the effective
sample size falls below half the particles. It has its own options (``particles_cap``,
``jitter_m``), validated by tanbench from ``method_options``.
"""

import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from tanbench.methods import MethodOutput, MethodRecord
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy


class Options(BaseModel):
    model_config = ConfigDict(extra="forbid")

    particles_cap: int = Field(1000, gt=0, description="at most this many particles (of the scenario's)")
    jitter_m: float = Field(1.0, ge=0, description="position jitter after resampling, m")


def run(ctx):
    """A small numpy position-only particle filter over the DVL beams."""
    opts, f, rng = ctx.options, ctx.scenario.filter, ctx.rng
    nav, upd, rows = ctx.nav, ctx.updates.imu, ctx.updates.rows
    m = min(ctx.scenario.particles, opts.particles_cap)
    half = f.initial_area_m / 2.0
    sigma = f.measurement_noise_altitude_m
    heading_std = math.radians(f.initial_std_heading_deg)
    x = nav.pos[upd[0], :2] + rng.uniform(-half, half, (m, 2))
    logw = np.zeros(m)
    k = upd.size
    est, var, ess_out = np.empty((k, 2)), np.empty((k, 2)), np.empty(k)
    dcm = dcm_body_to_nav_numpy(nav.pitch[upd], nav.roll[upd], nav.yaw[upd])
    offsets = np.einsum("kij,bj->kbi", dcm, ctx.obs.dvl_beams) * ctx.obs.dvl_ranges[rows][:, :, None]
    for i in range(k):
        if i > 0:
            d = nav.pos[upd[i], :2] - nav.pos[upd[i - 1], :2]
            cross = np.array([-d[1], d[0]])
            x += d + f.process_noise_velocity_mps * ctx.scenario.sampling_time_s * rng.standard_normal((m, 2))
            x += np.outer(heading_std * rng.standard_normal(m), cross)
        for off in offsets[i]:
            if np.isnan(off).any():
                continue
            floor = ctx.nmap.elevation(x[:, 0] + off[0], x[:, 1] + off[1])
            innov = np.where(np.isnan(floor), f.outside_map_sigma * sigma, nav.pos[upd[i], 2] + off[2] - floor)
            logw -= 0.5 * (innov / sigma) ** 2
        w = np.exp(logw - logw.max())
        w /= w.sum()
        est[i] = w @ x
        var[i] = w @ (x - est[i]) ** 2
        ess_out[i] = 1.0 / np.sum(w ** 2)
        logw -= logw.max()
        if ess_out[i] < 0.5 * m:
            positions = (rng.random() + np.arange(m)) / m
            idx = np.minimum(np.searchsorted(np.cumsum(w), positions), m - 1)
            x = x[idx] + opts.jitter_m * rng.standard_normal((m, 2))
            logw[:] = 0.0
    return MethodOutput(east=est[:, 0], north=est[:, 1], var_e=var[:, 0], var_n=var[:, 1], ess=ess_out)


METHOD = MethodRecord(name="numpy-pf", seed_id=0, run=run, options=Options, summary=run.__doc__,
                      states=("east", "north"), cost_ns=2000.0, color="tab:pink", linestyle="-")
