"""Built-in method ``mpf-dvl``: the marginalized (Rao-Blackwellised) particle filter (filters/mpf.py).

Particles carry position and yaw; a Kalman filter per particle carries the depth (tide)
bias and the z-gyro bias (the split and why it is valid: ``filters/mpf.py``). Its
budget knob is ``particles``, as for the particle filters.
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field

from tanbench.filters.mpf import mpf_settings
from tanbench.filters.mpf import run_mpf as mpf_driver
from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.registry import MethodRecord, register
from tanbench.navigation.increments import nav_at_updates
from tanbench.units import DEG_PER_H


class MpfOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    initial_std_depth_bias_m: float = Field(2.0, ge=0, description="prior std of the depth (tide) bias")
    depth_bias_walk_m_sqrt_s: float = Field(0.001, ge=0, description="random walk of the depth bias")


def run_mpf_dvl(ctx: MethodContext) -> MethodOutput:
    """The marginalized PF: particles for position and yaw, a KF per particle for depth and z-gyro biases."""
    obs, upd = ctx.obs, ctx.updates.imu
    inc = ctx.increments()
    out = mpf_driver(nav_at_updates(ctx.nav, upd), inc, obs.dvl_beams, obs.dvl_ranges[ctx.updates.rows],
                     ctx.nmap.kernel_args(), ctx.rng, mpf_settings(ctx.scenario, ctx.options))
    return MethodOutput(east=out["est_e"], north=out["est_n"], yaw=out["est_yaw"], var_e=out["var_e"],
                        var_n=out["var_n"], var_heading=out["var_yaw"] * (180.0 / math.pi) ** 2, ess=out["ess"],
                        reinit=out["reinit"].astype(bool),
                        extra={"depth_bias_m": out["depth_bias_m"], "var_depth_bias": out["var_depth_bias"],
                               "bias_z_deg_h": out["bias_z"] / DEG_PER_H,
                               "var_bias_z": out["var_bias_z"]})


MPF_DVL = register(MethodRecord(
    name="mpf-dvl", seed_id=6, builtin=True, run=run_mpf_dvl,
    states=("east", "north", "heading", "depth_bias", "gyro_bias_z"),
    series=("depth_bias_m", "var_depth_bias", "bias_z_deg_h", "var_bias_z"), options=MpfOptions, cost_ns=86.5,
    summary="a marginalized particle filter: particles for position and yaw, a Kalman filter per particle for "
            "the depth (tide) bias and the z-gyro bias, weighted by the 4 DVL beams",
    color="tab:orange", linestyle="--"))
