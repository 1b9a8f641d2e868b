"""Built-in method ``ekf-dvl``: the iterated EKF with local terrain linearisation, SITAN (filters/ekf.py).

State [E, N, heading offset, z-gyro bias]. The textbook baseline: it converges when
started close and can fail from the paper's large initial error (both regimes are in
``configs/methods.yaml``). Its budget knob is ``iterations`` (Gauss-Newton passes per update).
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field

from tanbench.filters.ekf import ekf_settings
from tanbench.filters.ekf import run_ekf as ekf_driver
from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.registry import MethodRecord, register
from tanbench.navigation.increments import nav_at_updates
from tanbench.units import DEG_PER_H


class EkfOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    iterations: int = Field(3, ge=1, le=50, description="Gauss-Newton passes per update (the budget knob)")
    gate: float = Field(18.5, gt=0, description="reject an update whose NIS exceeds this (chi^2, 4 beams, 99.9 %)")
    heading_drift_deg_sqrt_s: float = Field(0.03, ge=0, description="heading random walk")


def run_ekf_dvl(ctx: MethodContext) -> MethodOutput:
    """The iterated EKF (SITAN) on the 4 DVL beams with slopes over the position uncertainty."""
    obs, nav, upd = ctx.obs, ctx.nav, ctx.updates.imu
    inc = ctx.increments()
    out = ekf_driver(nav_at_updates(nav, upd), inc, obs.dvl_beams, obs.dvl_ranges[ctx.updates.rows],
                     ctx.nmap.kernel_args(), ekf_settings(ctx.scenario, ctx.options))
    return MethodOutput(east=out["est_e"], north=out["est_n"], yaw=out["est_yaw"], var_e=out["var_e"],
                        var_n=out["var_n"], var_heading=out["var_yaw"] * (180.0 / math.pi) ** 2,
                        extra={"update_rejected": out["rejected"].astype(float),
                               "bias_z_deg_h": out["bias_z"] / DEG_PER_H})


def ekf_steps(scenario) -> float:
    o = EkfOptions(**(scenario.method_options or {}).get("ekf-dvl", {}))
    return o.iterations * scenario.planned_duration_s / scenario.sampling_time_s


EKF_DVL = register(MethodRecord(
    name="ekf-dvl", seed_id=7, builtin=True, run=run_ekf_dvl, states=("east", "north", "heading", "gyro_bias_z"),
    series=("update_rejected", "bias_z_deg_h"), options=EkfOptions, cost_ns=947.0, cost_units=ekf_steps,
    summary="an iterated extended Kalman filter with local terrain linearisation (SITAN), 4 DVL beams",
    color="tab:brown", linestyle=":"))
