"""Built-in method ``tercom-dvl``: batch profile correlation (filters/tercom.py).

The last ``profile_pings`` updates' DVL footprints are matched (MSD or MAD, mean removed)
over a search window in position and heading around the corrected navigation solution;
accepted matches are fixes of that solution. Its budget knob is ``profile_pings``.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from tanbench.filters.tercom import run_tercom as tercom_driver
from tanbench.filters.tercom import tercom_settings
from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.registry import MethodRecord, register
from tanbench.navigation.increments import nav_at_updates


class TercomOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    profile_pings: int = Field(30, ge=2, le=1000, description="updates in the matched profile (the budget knob)")
    interval: int = Field(10, ge=1, description="updates between matches")
    metric: Literal["msd", "mad"] = Field("msd", description="mean squared or mean absolute difference")
    headings: int = Field(9, ge=1, le=91, description="heading candidates of a match (1 = position only)")
    window_max_m: float = Field(150.0, gt=0, description="largest half-width of the search window")
    fix_std_m: float = Field(10.0, gt=0, description="a match is a fix only if its likelihood std is below this")
    heading_drift_deg_sqrt_s: float = Field(0.03, ge=0, description="heading random walk of the corrected solution")


def run_tercom_dvl(ctx: MethodContext) -> MethodOutput:
    """TERCOM: the last N pings' DVL profile matched against the map; fixes correct the navigation solution."""
    obs = ctx.obs
    out = tercom_driver(nav_at_updates(ctx.nav, ctx.updates.imu), obs.dvl_beams, obs.dvl_ranges[ctx.updates.rows],
                        ctx.nmap.kernel_args(), tercom_settings(ctx.scenario, ctx.options))
    return MethodOutput(east=out["est_e"], north=out["est_n"], yaw=out["est_yaw"], var_e=out["var_e"],
                        var_n=out["var_n"], var_heading=out["var_yaw"] * (180.0 / math.pi) ** 2,
                        extra={"position_fix": out["fixes"].astype(float)})


def profile_matches(scenario) -> float:
    """Cost units: profile points x coarse candidates per match x matches (a 7 x 7 window, 4 beams)."""
    o = TercomOptions(**(scenario.method_options or {}).get("tercom-dvl", {}))
    matches = scenario.planned_duration_s / scenario.sampling_time_s / o.interval
    return matches * o.profile_pings * 4 * o.headings * 49


TERCOM_DVL = register(MethodRecord(
    name="tercom-dvl", seed_id=8, builtin=True, run=run_tercom_dvl, states=("east", "north", "heading"),
    series=("position_fix",), options=TercomOptions, cost_ns=14.5, cost_units=profile_matches,
    summary="TERCOM: batch MSD/MAD correlation of the last N pings' DVL profile over a position-heading window; "
            "fixes correct the navigation solution",
    color="tab:gray", linestyle="-."))
