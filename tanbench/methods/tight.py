"""Built-in methods ``tight-dvl`` and ``tight-sbe``: the paper's tightly coupled 8-state PF.

Set-up of the jitted loop in :mod:`tanbench.filters.tight` from the run's observations: the
navigation solution at the updates (:func:`tight_track`), the initial cloud around it
(:func:`tight_start`); the loop's settings come from the spec through
:func:`tanbench.filters.tight.tight_settings`.
"""

from __future__ import annotations

import numpy as np

from tanbench.filters.cloud import gaussian_horizontal
from tanbench.filters.likelihood import likelihood_grid
from tanbench.filters.relocalise import global_search_of
from tanbench.filters.rng import loop_rng
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.tight import (TightSettings, TightTrack, init_tight, new_tight_outputs, tight_filter_loop,
                                    tight_settings)
from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.registry import MethodRecord, particle_steps, register
from tanbench.navigation.increments import N_EULER, compute_euler_inputs
from tanbench.units import DEG_PER_H

TIGHT_STATES = ("east", "north", "up", "pitch", "roll", "heading", "gyro_bias_x", "gyro_bias_z")
TIGHT_SERIES = ("var_pitch", "var_roll", "var_bias_x", "var_bias_z", "bias_x_deg_h", "bias_z_deg_h", "healthy")


# the Euler inputs' averaging window per propagation reading, seconds (0: the one IMU sample at the update;
# euler-interval-start: the one sample at the interval's start)
EULER_WINDOW_S = {"euler-last-second": 1.0, "euler-last-sample": 0.0, "euler-interval-start": 0.0}


# the tight loop's cost with progressive correction (filter.tempering_ess above 0) over its cost without: the median
# filter wall time of each cell of results/tempering over its untempered twin was 1.45-1.76 (docs/filters.md 22.1)
TEMPERING_COST = 1.6


def tempering_cost(scenario) -> float:
    """The factor on a tight PF's cost units for ``filter.tempering_ess`` (the plan's estimate)."""
    return TEMPERING_COST if scenario.filter.tempering_ess > 0.0 else 1.0


def tight_particle_steps(scenario) -> float:
    """Cost units of tight-dvl and tight-sbe: particles x updates, times :func:`tempering_cost`."""
    return particle_steps(scenario) * tempering_cost(scenario)


def euler_inputs_of(ctx: MethodContext) -> np.ndarray:
    """The (K-1, 4) Euler-step inputs of ``filter.propagation`` (zeros for ``exact``)."""
    f, obs, nav, upd = ctx.scenario.filter, ctx.obs, ctx.nav, ctx.updates.imu
    if f.propagation == "exact":
        return np.zeros((max(upd.size - 1, 0), N_EULER))
    window = max(1, int(round(EULER_WINDOW_S[f.propagation] / obs.dt)))
    if f.propagation == "euler-interval-start":
        # interval m runs from upd[m] to upd[m+1]; its inputs are the one sample at upd[m]
        upd = np.concatenate([upd[:1], upd[:-1] + 1])
    return compute_euler_inputs(obs.gyro, obs.dvl_velocity, nav.pitch, nav.roll, nav.yaw, obs.latitude_rad,
                                upd, window)


def tight_track(ctx: MethodContext) -> TightTrack:
    """The navigation solution at the run's updates, as the tight loop reads it."""
    nav, upd = ctx.nav, ctx.updates.imu
    return TightTrack(ctx.increments(), nav.yaw[upd], nav.pitch[upd], nav.roll[upd], nav.pos[upd, 2], euler_inputs_of(ctx))


def tight_start(ctx: MethodContext, settings: TightSettings):
    """The loop's random numbers and its initial cloud (8, M) around the navigation solution at the first update."""
    sc, nav = ctx.scenario, ctx.nav
    rng = loop_rng(ctx.rng, sc.filter.random_numbers)
    x = np.empty((N_TIGHT, sc.particles))  # a column per particle
    k0 = ctx.updates.imu[0]
    init_tight(x, rng, nav.pos[k0, 0], nav.pos[k0, 1], nav.pos[k0, 2], nav.pitch[k0], nav.roll[k0],
               nav.yaw[k0], settings.prior)
    if settings.readings.cloud_std > 0.0:
        gaussian_horizontal(x, rng, nav.pos[k0, 0], nav.pos[k0, 1], settings.readings.cloud_std)
    return x, rng


def run_tight(ctx: MethodContext, sensor: str, sonar=None) -> MethodOutput:
    """The tight PF weighted by ``sensor``'s beams ("dvl", "sbe"), or by ``sonar`` = (beams (m, 3),
    ranges at the updates (K, m)) when given (the multibeam methods, methods/multibeam.py)."""
    sc, obs = ctx.scenario, ctx.obs
    beams = obs.dvl_beams if sensor == "dvl" else obs.sbe_beams
    ranges = (obs.dvl_ranges if sensor == "dvl" else obs.sbe_ranges)[ctx.updates.rows]
    if sonar is not None:
        beams, ranges = sonar
    settings = tight_settings(sc, ctx.nmap, beams.shape[0])
    x, rng = tight_start(ctx, settings)
    out = new_tight_outputs(ctx.updates.imu.size)
    tight_filter_loop(x, rng, tight_track(ctx), np.ascontiguousarray(ranges), np.ascontiguousarray(beams),
                      likelihood_grid(sc.filter, ctx.nmap), settings, out,
                      global_search_of(sc.filter, ctx.nav.pos[ctx.updates.imu, :2]))
    est, var = out.est, out.var
    return MethodOutput(
        east=est[:, E], north=est[:, N], up=est[:, U], yaw=est[:, YAW],
        var_e=var[:, E], var_n=var[:, N], cov_en=out.cov_en, var_u=var[:, U],
        var_heading=np.degrees(np.sqrt(var[:, YAW])) ** 2, ess=out.ess, reinit=out.reinit.astype(bool),
        extra={"var_pitch": var[:, PITCH], "var_roll": var[:, ROLL], "var_yaw": var[:, YAW],
               "var_bias_x": var[:, BX], "var_bias_z": var[:, BZ],
               "bias_x_deg_h": est[:, BX] / DEG_PER_H, "bias_z_deg_h": est[:, BZ] / DEG_PER_H,
               "healthy": out.healthy.astype(float)})


def run_tight_dvl(ctx: MethodContext) -> MethodOutput:
    """The tightly coupled 8-state PF weighted by the 4 DVL beams."""
    return run_tight(ctx, "dvl")


def run_tight_sbe(ctx: MethodContext) -> MethodOutput:
    """The tightly coupled 8-state PF weighted by the single altimeter beam."""
    return run_tight(ctx, "sbe")


TIGHT_DVL = register(MethodRecord(
    name="tight-dvl", seed_id=1, builtin=True, run=run_tight_dvl, states=TIGHT_STATES,
    series=TIGHT_SERIES + ("var_yaw",),
    summary="the paper's tightly coupled 8-state particle filter (position, attitude, two gyro biases), "
            "weighted by the 4 DVL beams",
    cost_ns=41.6, cost_units=tight_particle_steps, color="tab:red", linestyle="--", bound=("dvl", "full")))
TIGHT_SBE = register(MethodRecord(
    name="tight-sbe", seed_id=2, builtin=True, run=run_tight_sbe, states=TIGHT_STATES,
    series=TIGHT_SERIES + ("var_yaw",),
    summary="the same 8-state particle filter weighted by the single-beam altimeter",
    cost_ns=30.1, cost_units=tight_particle_steps, color="tab:blue", linestyle="-.", bound=("sbe", "full")))
