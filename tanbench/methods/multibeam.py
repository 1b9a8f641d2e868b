"""Built-in methods ``tight-mbe`` and ``pmf-mbe``: the tight PF and the point-mass filter weighted
by the multibeam swath (sensors/multibeam.py, docs/multibeam.md).

They are ``tight-dvl`` and ``pmf-dvl`` with the multibeam's beams in place of the DVL's:
the same loops, the same likelihood kernels (which loop over any number of beams, skipping
beams without a range) and the same settings (``filter.measurement_noise_altitude_m`` is
the per-beam std the likelihood charges). A method is given the nominal fan and the
measured ranges at its updates (never the truth, nor the beams' pointing errors). The
swath can be thinned (``beams_used``, ``selection``; :mod:`tanbench.filters.swath`), which
divides the likelihood's cost by about N / beams_used.
"""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from tanbench.errors import TanbenchError
from tanbench.filters.beams import nav_frame_offsets
from tanbench.filters.swath import beam_information, every_kth, most_informative
from tanbench.methods.api import MethodContext, MethodOutput
from tanbench.methods.pmf import PmfOptions, grid_steps, run_pmf
from tanbench.methods.registry import MethodRecord, register
from tanbench.methods.tight import TIGHT_SERIES, TIGHT_STATES, run_tight, tempering_cost
from tanbench.options import MULTIBEAM_SELECTION, choices


class SwathOptions(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    beams_used: int = Field(0, ge=0, le=1024, description="beams of the swath the filter weighs by (0: all)")
    selection: choices(MULTIBEAM_SELECTION) = Field(
        "every-kth", description="how beams_used are chosen: every k-th beam of the fan, or per update the most "
                                 "informative (largest range sensitivity to position on the navigation map)")


class PmfSwathOptions(PmfOptions, SwathOptions):
    """The point-mass filter's options and the swath's."""


def swath(ctx: MethodContext):
    """(beams (m, 3), ranges at the updates (K, m)) of the multibeam, thinned as ``ctx.options`` say."""
    obs, o = ctx.obs, ctx.options
    if obs.mbe_beams is None or obs.mbe_ranges is None or obs.mbe_beams.shape[0] == 0:
        raise TanbenchError(f"method {ctx.name!r} needs a multibeam: set sensors.multibeam_beams > 0 (or give the "
                            f"log a multibeam table)")
    beams, ranges = obs.mbe_beams, obs.mbe_ranges[ctx.updates.rows]
    if o.selection == "every-kth":
        keep = every_kth(beams.shape[0], o.beams_used)
        return np.ascontiguousarray(beams[keep]), np.ascontiguousarray(ranges[:, keep])
    nav, upd = ctx.nav, ctx.updates.imu
    offsets = nav_frame_offsets(nav.pitch[upd], nav.roll[upd], nav.yaw[upd], beams, ranges)
    info = np.empty(ranges.shape)
    beam_information(offsets, np.ascontiguousarray(nav.pos[upd, :2]), *ctx.nmap.kernel_args(), info)
    return np.ascontiguousarray(beams), np.ascontiguousarray(most_informative(info, ranges, o.beams_used))


def run_tight_mbe(ctx: MethodContext) -> MethodOutput:
    """The tightly coupled 8-state PF weighted by the multibeam swath."""
    return run_tight(ctx, "mbe", swath(ctx))


def run_pmf_mbe(ctx: MethodContext) -> MethodOutput:
    """The point-mass filter (position x heading bank) weighted by the multibeam swath."""
    return run_pmf(ctx, "mbe", swath(ctx))


def beams_weighed(scenario, name: str) -> int:
    """The beams a multibeam method weighs by at most (for its cost estimate)."""
    used = int((scenario.method_options or {}).get(name, {}).get("beams_used", 0))
    n = scenario.sensors.multibeam_beams
    return min(used, n) if used else n


def particle_beam_steps(scenario) -> float:
    """Cost units of tight-mbe: particles x beams used x updates (times the tight loop's :func:`tempering_cost`)."""
    duration = scenario.duration_s or 1190.0
    return (scenario.particles * max(beams_weighed(scenario, "tight-mbe"), 1) * duration / scenario.sampling_time_s
            * tempering_cost(scenario))


def pmf_beam_steps(scenario) -> float:
    """Cost units of pmf-mbe: pmf-dvl's grid steps per beam x beams used."""
    own = (scenario.method_options or {}).get("pmf-mbe", {})
    grid_only = scenario.model_copy(update={"method_options": {
        "pmf-mbe": {k: v for k, v in own.items() if k in PmfOptions.model_fields}}})
    return grid_steps("pmf-mbe")(grid_only) * max(beams_weighed(scenario, "pmf-mbe"), 1) / 4.0


TIGHT_MBE = register(MethodRecord(
    name="tight-mbe", seed_id=28, builtin=True, run=run_tight_mbe, states=TIGHT_STATES,
    series=TIGHT_SERIES + ("var_yaw",), options=SwathOptions, cost_ns=4.2, cost_units=particle_beam_steps,
    summary="the paper's tightly coupled 8-state particle filter weighted by the multibeam swath "
            "(sensors.multibeam_*)",
    color="tab:purple", linestyle="--", bound=("mbe", "full")))
PMF_MBE = register(MethodRecord(
    name="pmf-mbe", seed_id=29, builtin=True, run=run_pmf_mbe, states=("east", "north", "heading"),
    series=("live_slices",), options=PmfSwathOptions, cost_ns=4.7, cost_units=pmf_beam_steps,
    summary="the point-mass filter (position x heading bank) weighted by the multibeam swath",
    color="tab:brown", linestyle="-"))
