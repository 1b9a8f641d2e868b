"""Built-in methods ``pmf-dvl`` and ``pmf-sbe``: the point-mass filter (filters/pmf.py).

A grid Bayesian filter over horizontal position with a bank of heading hypotheses
(``headings`` slices; 1 = the position-only PMF), weighted by the 4 DVL beams or the
altimeter. Its budget knob is ``cells`` (grid nodes per side); the cost per update is
about cells^2 times the heading slices holding mass (all at first, two or three once
the heading has converged).
"""

from __future__ import annotations

import math

from pydantic import BaseModel, ConfigDict, Field

from tanbench.filters.pmf import pmf_settings
from tanbench.filters.pmf import run_pmf as pmf_driver
from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.registry import MethodRecord, register
from tanbench.navigation.increments import nav_at_updates


class PmfOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    cells: int = Field(32, ge=4, le=512, description="grid nodes per side (the budget knob); the initial grid "
                                                      "spans filter.initial_area_m")
    headings: int = Field(15, ge=1, le=181, description="heading slices (1 = position-only PMF)")
    heading_span_deg: float = Field(
        60.0, gt=0, le=180, description="slices span the nav heading +- 2.5 prior sigma, at most +- this")
    min_spacing_m: float = Field(0.5, gt=0, description="finest grid spacing as the posterior shrinks")
    heading_drift_deg_sqrt_s: float = Field(
        0.25, ge=0, description="heading random walk between slices (stands for the gyro-bias drift)")


def run_pmf(ctx: MethodContext, sensor: str, sonar=None) -> MethodOutput:
    """The PMF weighted by ``sensor``'s beams ("dvl", "sbe"), or by ``sonar`` = (beams (m, 3), ranges at
    the updates (K, m)) when given (the multibeam methods, methods/multibeam.py)."""
    obs, upd = ctx.obs, ctx.updates.imu
    beams = obs.dvl_beams if sensor == "dvl" else obs.sbe_beams
    ranges = (obs.dvl_ranges if sensor == "dvl" else obs.sbe_ranges)[ctx.updates.rows]
    if sonar is not None:
        beams, ranges = sonar
    out = pmf_driver(nav_at_updates(ctx.nav, upd), beams, ranges, ctx.nmap.kernel_args(),
                     pmf_settings(ctx.scenario, ctx.options))
    return MethodOutput(east=out["est_e"], north=out["est_n"], yaw=out["est_yaw"], var_e=out["var_e"],
                        var_n=out["var_n"], var_heading=out["var_yaw"] * (180.0 / math.pi) ** 2,
                        reinit=out["reinit"].astype(bool),
                        extra={"live_slices": out["live_slices"].astype(float)})


def run_pmf_dvl(ctx: MethodContext) -> MethodOutput:
    """The point-mass filter (position x heading bank) weighted by the 4 DVL beams."""
    return run_pmf(ctx, "dvl")


def run_pmf_sbe(ctx: MethodContext) -> MethodOutput:
    """The point-mass filter (position x heading bank) weighted by the single altimeter beam."""
    return run_pmf(ctx, "sbe")


def grid_steps(name: str):
    """Cost units of a PMF run: grid nodes x heading slices x updates, the slices counted as a
    quarter of the bank (most of them lose their mass within the first minutes)."""

    def units(scenario) -> float:
        o = PmfOptions(**(scenario.method_options or {}).get(name, {}))
        return o.cells**2 * max(1.0, o.headings / 4.0) * scenario.planned_duration_s / scenario.sampling_time_s

    return units


PMF_DVL = register(MethodRecord(
    name="pmf-dvl", seed_id=4, builtin=True, run=run_pmf_dvl, states=("east", "north", "heading"),
    series=("live_slices",), options=PmfOptions, cost_ns=27.3, cost_units=grid_steps("pmf-dvl"),
    summary="a point-mass (grid) filter over position with a bank of heading slices, weighted by the 4 DVL beams",
    color="tab:green", linestyle="-"))
PMF_SBE = register(MethodRecord(
    name="pmf-sbe", seed_id=5, builtin=True, run=run_pmf_sbe, states=("east", "north", "heading"),
    series=("live_slices",), options=PmfOptions, cost_ns=26.2, cost_units=grid_steps("pmf-sbe"),
    summary="the point-mass filter weighted by the single-beam altimeter",
    color="tab:olive", linestyle="-."))
