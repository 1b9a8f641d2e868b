"""Speed of the methods: whole runs, the two random-number streams, kernels against numpy references.

The bench scenario is the paper's: area A, the 10 m map, 4 DVL beams, 3000 particles,
a whole 1190 s run (1191 updates). For every registered method it reports

* ns per cost unit (particle-step for the particle filters: a run's filter time divided
  by updates x particles; grid cell, profile match or update for the others), by
  thread CPU time (what the method costs one core, robust on a loaded machine) and by
  wall time, and the whole run's wall time;
* for the built-in particle filters, the same with the other stream of
  ``filter.random_numbers`` (``numpy``);
* for every built-in method, one update step of its kernels against the same step of
  their plain-numpy references (the ratio numpy / jitted);
* a per-kernel breakdown (ns per particle) of a tight-dvl and a loose-dvl update on a
  mid-run cloud.

Figures depend on the machine and its load; nothing here is asserted by the tests.
``calibrated_cost_ns`` gives what ``MethodRecord.cost_ns`` (``tanbench plan``'s estimate)
should hold on this machine: thread CPU ns per cost unit of a whole ``run_method``.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time

import numpy as np
from tanbench import store
from tanbench.config import Scenario
from tanbench.filters import ekf, likelihood as L, mpf, pmf, tercom
from tanbench.filters.estimate import weighted_estimate, weighted_estimate_numpy
from tanbench.filters.likelihood import Likelihood, beam_vectors, likelihood_grid, likelihood_of
from tanbench.filters.propagate import DIST_PARTICLE, propagate_loose, propagate_loose_numpy, propagate_tight, propagate_tight_numpy
from tanbench.filters.resample import REG_LIU_WEST, SYSTEMATIC, add_log_weights, apply_resample, normalise_with_ess, normalize_log_weights, normalize_log_weights_numpy, regularise, resample_indices, resample_indices_numpy, shrink_jitter, shrink_jitter_numpy
from tanbench.filters.rng import FastRng, fill_normals
from tanbench.filters.trig import attitude_reference
from tanbench.methods import get, method_context, run_method
from tanbench.methods.registry import builtin_names, names
from tanbench.numpy_stream import Pcg64Stream
from tanbench.runner.engine import cell_columns, store_result
from tanbench.runner.plan import make_plan
from tanbench.runner.resume import ResumeState
from tanbench.runner.tasks import execute
from tanbench.sensors.multibeam import fan_angles_deg, fan_vectors, swath_ranges
from tanbench.simulation import noise_free_world, simulate_vehicle
from tanbench.sweep import parse_sweep
from tanbench.terrain import clear_truth_maps, seafloor_cache, synthesise_seafloor, terrain_key, truth_map
from tanbench.terrain.grid import interpolate_cells, node_grid
from tanbench.terrain.representation import filter_map_variance
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

BENCH_SEED = 2017
PARTICLE_FILTERS = ("tight-dvl", "tight-sbe", "loose-dvl")  # the ones that take filter.random_numbers


def _best(fn, n):
    """(min thread-CPU s, min wall s) of ``n`` calls after one warm-up call."""
    fn()
    cpu, wall = [], []
    for _ in range(n):
        t0, c0 = time.perf_counter(), time.thread_time()
        fn()
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - t0)
    return min(cpu), min(wall)


# the multibeam methods' bench sonar: a 64-beam, 120-degree fan (the rest of the bench run is unchanged)
MULTIBEAM_BENCH = {"multibeam_beams": 64, "multibeam_swath_deg": 120.0}


# the tight PF's measured options, benched beside its defaults (docs/filters.md sections 22 and 23)
OPTION_RUNS = ({"tempering_ess": 0.5}, {"kld_epsilon": 0.05})


def bench_scenario(particles: int, random_numbers: str | None = None, multibeam: bool = False,
                   options: dict | None = None):
    settings = dict(options or {})
    if random_numbers is not None:
        settings["random_numbers"] = random_numbers
    return Scenario(particles=particles, filter=settings, sensors=MULTIBEAM_BENCH if multibeam else {})


def run_figures(method: str, particles: int, repeats: int, random_numbers: str | None = None,
                options: dict | None = None) -> dict:
    """Whole-run figures of ``method``: ns per cost unit (CPU and wall), run wall, calibrated cost; ``options``
    are ``filter`` settings. A cost unit is the plan's: with tempering, ``TEMPERING_COST`` particle-steps (so a
    figure near the defaults' says the plan's factor holds), with an adaptive count, a particle-step of the most
    particles (so the figure falls with the count)."""
    scenario = bench_scenario(particles, random_numbers, multibeam=method.endswith("-mbe"), options=options)
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(BENCH_SEED))
    units = float(get(method).cost_units(scenario))
    run_method(scenario, method, vehicle, np.random.SeedSequence(1))  # compile / load the cache
    cpu, wall, filt, ess = [], [], [], None
    for r in range(repeats):
        t0, c0 = time.perf_counter(), time.thread_time()
        result = run_method(scenario, method, vehicle, np.random.SeedSequence(1 + r))
        cpu.append(time.thread_time() - c0)
        wall.append(time.perf_counter() - t0)
        filt.append(result.metrics.get("filter_wall_s", wall[-1]))
        if ess is None and "ess" in result.series:
            ess = np.asarray(result.series["ess"], dtype=float)
    return {
        "method": method, "random_numbers": scenario.filter.random_numbers, "stream": method in PARTICLE_FILTERS,
        "options": " ".join(f"{k}={v}" for k, v in (options or {}).items()),
        "cost_units": units,
        "ns_per_unit_cpu": round(min(cpu) / units * 1e9, 1),
        "ns_per_unit_wall": round(min(filt) / units * 1e9, 1),
        "run_wall_s": round(min(wall), 3),
        # (not for an option run: the ESS is read against the most particles, which neither the tempered ESS nor an
        # adaptive count's is)
        "resampled_fraction": None if ess is None or options else round(float(np.mean(ess < 0.5 * particles)), 3),
    }


def bench_state(particles: int) -> dict:
    """The bench run half-way and a converged-looking tight cloud (8, M) about the truth there:
    what the kernel breakdown and the reference steps work on."""
    scenario = bench_scenario(particles)
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(BENCH_SEED))
    ctx = method_context(scenario, "tight-dvl", vehicle, np.random.SeedSequence(1))
    obs, nav, upd = vehicle.obs, vehicle.obs.nav, ctx.updates.imu
    rng = np.random.default_rng(5)
    k = len(upd) // 2
    x0 = np.empty((8, particles))
    x0[0] = vehicle.truth.pos[upd[k], 0] + rng.uniform(-20, 20, particles)
    x0[1] = vehicle.truth.pos[upd[k], 1] + rng.uniform(-20, 20, particles)
    x0[2] = nav.pos[upd[k], 2]
    x0[3] = nav.pitch[upd[k]]
    x0[4] = nav.roll[upd[k]]
    # headings about the true one, as a converged cloud's: ~30 degrees off the navigation's
    x0[5] = vehicle.truth.yaw[upd[k]] + rng.normal(0, 0.02, particles)
    x0[6:] = rng.normal(0, 1e-4, (2, particles))
    inc = ctx.increments()
    yaw_off = float(np.mean(x0[5]) - nav.yaw[upd[k]])  # the cloud's heading offset, as the loop keeps it
    ranges = np.ascontiguousarray(obs.dvl_ranges[ctx.updates.rows[k + 1]])
    c = dcm_body_to_nav_numpy(np.array([nav.pitch[upd[k + 1]]]), np.array([nav.roll[upd[k + 1]]]),
                              np.array([nav.yaw[upd[k + 1]]]))[0]
    return dict(
        scenario=scenario, vehicle=vehicle, ctx=ctx, k=k, x0=x0, inc=inc[k], nav=nav, upd=upd, yaw_off=yaw_off,
        yaw0=float(nav.yaw[upd[k]]), lik=likelihood_of(scenario.filter), grid=likelihood_grid(scenario.filter, ctx.nmap),
        ranges=ranges, beams=np.ascontiguousarray(obs.dvl_beams), vec=beam_vectors(np.ascontiguousarray(obs.dvl_beams), ranges),
        att=attitude_reference(nav.pitch[upd[k + 1]], nav.roll[upd[k + 1]], nav.yaw[upd[k + 1]] + yaw_off),
        offsets=np.ascontiguousarray((obs.dvl_beams @ c.T) * ranges[:, None]), up=float(nav.pos[upd[k + 1], 2]),
        uni=rng.random(particles))


# the tight filter's bench settings: Table 2's noise per 1 s update (position with the DVL distance
# folded in, up, attitude) and the measurement model
SIGMAS = (0.0707, 0.01, math.radians(2.0 / 60.0))
SIG_U, OUTSIDE, SIG_D = 1.0, 5.0, 0.1


def kernel_breakdown(particles: int = 3000, reps: int = 30) -> dict:
    """ns per particle (thread CPU) of each pass of one tight-dvl and one loose-dvl update on a
    mid-run cloud (the loops run these passes over blocks of the cloud; here each runs on the
    whole cloud, so the figures leave out the blocks' cache benefit)."""
    s = bench_state(particles)
    m, x0, grid, lik, vec = particles, s["x0"], s["grid"], s["lik"], s["vec"]
    x, ll, w, logw = x0.copy(), np.empty(m), np.empty(m), np.zeros(m)
    idx, scratch, mean, v, cov = np.empty(m, dtype=np.int64), np.empty_like(x0), np.empty(8), np.empty(8), \
        np.empty((2, 2))
    noise, dist = np.empty((6, m)), np.zeros((2, m))
    work = L.work_block(L.new_likelihood_work(m, 4 * grid.grids), m)
    consts = L.beam_constants(SIG_U, SIG_D, OUTSIDE)
    su2, inv_d2, out2 = consts
    inv_nu, half_nu1, student = L._density_constants(lik)
    rows = np.array([0, 1, 5, 6, 7], dtype=np.int64)
    fast = FastRng.from_seed(np.random.SeedSequence(7)).state
    numpy_stream = Pcg64Stream(np.random.default_rng(7))

    def per(fn):
        return round(_best(fn, reps)[0] / m * 1e9, 1)

    t = {}
    t["random normals x6 (fast: xoshiro256++ lanes)"] = per(lambda: fill_normals(fast, noise))
    t["random normals x6 (numpy: PCG64 inline)"] = per(lambda: fill_normals(numpy_stream, noise))
    t["propagate (exact increments)"] = per(lambda: propagate_tight(x, s["inc"], s["yaw0"], noise, *SIGMAS,
                                                                    DIST_PARTICLE, dist, s["yaw_off"]))
    x[:] = x0
    t["attitude matrices (3 sin/cos)"] = per(lambda: L.attitude_matrices(x, 0, s["att"], work.dcm))
    beams = vec.shape[0]
    t[f"footprints and cells (x{beams} beams, in pairs)"] = beams / 2 * per(
        lambda: L.tight_footprint_pair(x, 0, work.dcm, vec, 0, grid, work.cell, work.tx, work.ty, work.pu))
    t[f"map values at the footprints (x{beams} beams, scalar)"] = beams * per(
        lambda: interpolate_cells(work.cell[0], work.tx[0], work.ty[0], grid.nodes, grid.grids, grid.nx, work.values))
    t[f"beam terms (x{beams} beams, in pairs)"] = beams / 2 * per(
        lambda: L.add_beam_term_pair(work.values, grid.grids, work.cell, work.pu, su2, out2, lik.mapaware, inv_nu,
                                     work))
    t["log-likelihoods (2 logs)"] = per(lambda: L.finish_loglik(work, lik.mapaware, student, half_nu1, dist, False,
                                                                inv_d2, ll))
    t[f"whole likelihood pass ({beams} beams, map-aware Student-t)"] = per(
        lambda: L.loglik_tight_pass(x, 0, vec, grid, lik, consts, s["att"], dist, False, work, ll))
    t["weights: log-weights, normalisation, ESS"] = per(lambda: normalise_with_ess(logw, add_log_weights(logw, ll), w))
    logw[:] = 0.0
    normalise_with_ess(logw, add_log_weights(logw, ll), w)
    t["estimate (8 states)"] = per(lambda: weighted_estimate(x, w, 5, s["yaw0"], mean, v, cov))
    t["resampling: indices (resampled updates only)"] = per(lambda: resample_indices(SYSTEMATIC, w, s["uni"], idx))
    t["resampling: copy (resampled updates only)"] = per(lambda: apply_resample(x, idx, scratch))
    x[:] = x0
    t["regularisation, 5 states (resampled updates only)"] = per(lambda: regularise(x, fast, REG_LIU_WEST, rows,
                                                                                     0.1, 8))
    x[:] = x0
    xl, lo = np.ascontiguousarray(x0[:2]), {}
    rows_l = L.used_offsets(s["offsets"])
    lo["random normals x3 (fast)"] = per(lambda: fill_normals(fast, noise[:3]))
    lo["propagate"] = per(lambda: propagate_loose(xl, 1.0, 0.5, noise[:3], 0.1, 0.5))
    xl[:] = x0[:2]
    lo[f"whole likelihood pass ({rows_l.shape[0]} beams, map-aware Student-t)"] = per(
        lambda: L.loglik_loose_pass(xl, 0, rows_l, s["up"], grid, lik, consts, work, ll))
    lo["estimate (2 states)"] = per(lambda: weighted_estimate(xl, w, -1, 0.0, mean[:2], v[:2], cov))
    return {"tight-dvl": t, "loose-dvl": lo}


def _pf_step(s, sensor: str, loose: bool):
    """One update of a particle filter's kernels, jitted and by their numpy references: (jit, numpy) callables."""
    m, lik, grid = s["x0"].shape[1], s["lik"], s["grid"]
    obs, nmap, f = s["vehicle"].obs, s["ctx"].nmap, s["scenario"].filter
    mvar = filter_map_variance(f, nmap)
    za = nmap.kernel_args()
    beams = np.ascontiguousarray(obs.dvl_beams if sensor == "dvl" else obs.sbe_beams)
    ranges = s["ranges"] if sensor == "dvl" else np.ascontiguousarray(obs.sbe_ranges[s["ctx"].updates.rows[s["k"] + 1]])
    x0 = np.ascontiguousarray(s["x0"][:2]) if loose else s["x0"]
    rows = np.array([0, 1], dtype=np.int64) if loose else np.array([0, 1, 5, 6, 7], dtype=np.int64)
    nnoise = 3 if loose else 6
    fast = FastRng.from_seed(np.random.SeedSequence(9)).state
    gen = np.random.default_rng(9)
    buf = dict(noise=np.empty((nnoise, m)), jitter=np.empty((rows.size, m)), dist=np.zeros((2, m)), ll=np.empty(m),
               w=np.empty(m), idx=np.empty(m, dtype=np.int64), scratch=np.empty_like(x0), mean=np.empty(x0.shape[0]),
               var=np.empty(x0.shape[0]), cov=np.empty((2, 2)))

    def jit():
        b = buf
        x = x0.copy()
        fill_normals(fast, b["noise"])
        if loose:
            propagate_loose(x, 1.0, 0.5, b["noise"], 0.1, 0.5)
            L.loglik_loose(x, s["offsets"], s["up"], grid, lik, SIG_U, OUTSIDE, b["ll"])
        else:
            propagate_tight(x, s["inc"], s["yaw0"], b["noise"], *SIGMAS, DIST_PARTICLE, b["dist"], s["yaw_off"])
            L.loglik_tight(x, beams, ranges, grid, lik, SIG_U, OUTSIDE, b["dist"], SIG_D, False, s["att"], b["ll"])
        normalize_log_weights(b["ll"], b["w"])
        weighted_estimate(x, b["w"], -1 if loose else 5, s["yaw0"], b["mean"], b["var"], b["cov"])
        resample_indices(SYSTEMATIC, b["w"], s["uni"], b["idx"])
        apply_resample(x, b["idx"], b["scratch"])
        fill_normals(fast, b["jitter"])
        shrink_jitter(x, rows, 0.1, b["jitter"])

    def numpy():
        noise = gen.standard_normal((nnoise, m))
        if loose:
            x = propagate_loose_numpy(x0, 1.0, 0.5, noise, 0.1, 0.5)
            ll, _ = L.loglik_loose_numpy(x, s["offsets"], s["up"], za, mvar, lik, SIG_U, OUTSIDE)
        else:
            x, _ = propagate_tight_numpy(x0, s["inc"], s["yaw0"], noise, *SIGMAS, DIST_PARTICLE)
            ll, _ = L.loglik_tight_numpy(x, beams, ranges, za, mvar, lik, SIG_U, OUTSIDE, None, SIG_D)
        w, _ = normalize_log_weights_numpy(ll)
        weighted_estimate_numpy(x, w, -1 if loose else 5, s["yaw0"])
        x = x[:, resample_indices_numpy(SYSTEMATIC, w, s["uni"])]
        shrink_jitter_numpy(x, rows, 0.1, gen.standard_normal((rows.size, m)))

    return jit, numpy


def _mpf_step(s):
    m = s["x0"].shape[1]
    za = s["ctx"].nmap.kernel_args()
    x0 = np.empty((mpf.N_MPF, m))
    x0[mpf.E], x0[mpf.N], x0[mpf.PSI] = s["x0"][0], s["x0"][1], s["x0"][5]
    x0[mpf.B], x0[mpf.PB], x0[mpf.EPS], x0[mpf.PEPS] = 0.0, 1.0, 0.0, 1e-10
    noise = np.random.default_rng(3).standard_normal((3, m))
    ll, w, mean, var, cov = np.empty(m), np.empty(m), np.empty(mpf.N_MPF), np.empty(mpf.N_MPF), np.empty((2, 2))
    args = (s["offsets"], s["up"], s["yaw0"], *za, SIG_U, OUTSIDE)

    def jit():
        x = x0.copy()
        mpf.mpf_propagate(x, s["inc"], s["yaw0"], noise, 0.07, 1e-7, 1e-12, 1e-6)
        mpf.mpf_loglik_update(x, *args, ll)
        normalize_log_weights(ll, w)
        weighted_estimate(x, w, mpf.PSI, s["yaw0"], mean, var, cov)

    def numpy():
        x = mpf.mpf_propagate_numpy(x0, s["inc"], s["yaw0"], noise, 0.07, 1e-7, 1e-12, 1e-6)
        lq, _, x = mpf.mpf_loglik_update_numpy(x, *args)
        wq, _ = normalize_log_weights_numpy(lq)
        weighted_estimate_numpy(x, wq, mpf.PSI, s["yaw0"])

    return jit, numpy


def _pmf_step(s, cells: int):
    """One heading slice of the point-mass filter: its nodes, the likelihood there, the blur, the moments."""
    nmap = s["ctx"].nmap
    za, grid, plain = nmap.kernel_args(), node_grid(nmap), Likelihood(False, 0, 4.0)
    ce, cn = float(s["x0"][0].mean()), float(s["x0"][1].mean())
    p0 = np.random.default_rng(4).random((cells, cells))
    nodes, ll, buf = np.empty((2, cells * cells)), np.empty(cells * cells), np.empty((cells, cells))

    def jit():
        p = p0.copy()
        pmf.grid_nodes(ce, cn, 2.0, cells, nodes)
        L.loglik_loose(nodes, s["offsets"], s["up"], grid, plain, SIG_U, OUTSIDE, ll)
        pmf.blur_separable(p, 0.8, buf)
        pmf.slice_moments(p, ce, cn, 2.0)

    def numpy():
        q = pmf.grid_nodes_numpy(ce, cn, 2.0, cells)
        L.loglik_loose_numpy(q, s["offsets"], s["up"], za, None, plain, SIG_U, OUTSIDE)
        p = pmf.blur_separable_numpy(p0, 0.8)
        pmf.slice_moments_numpy(p, ce, cn, 2.0)

    return jit, numpy


def _ekf_step(s):
    za = s["ctx"].nmap.kernel_args()
    x0 = np.array([s["x0"][0].mean(), s["x0"][1].mean(), 0.01, 0.0])
    p0 = np.diag([25.0, 25.0, 1e-3, 1e-10])
    args = (s["offsets"], s["up"], za, 10.0, SIG_U, 3, 100.0)

    def jit():
        x, p = x0.copy(), p0.copy()
        ekf.ekf_predict(x, p, 1.0, 0.5, 0.98, 0.01, 1e-6, 1e-12)
        ekf.iekf_update(x, p, *args)

    def numpy():
        x, p = ekf.ekf_predict_numpy(x0, p0, 1.0, 0.5, 0.98, 0.01, 1e-6, 1e-12)
        ekf.iekf_update_numpy(x, p, *args)

    return jit, numpy


def _tercom_step(s, pings: int = 30, half_cells: int = 10):
    za = s["ctx"].nmap.kernel_args()
    rng = np.random.default_rng(6)
    pe = s["x0"][0, 0] + np.cumsum(rng.normal(1.0, 0.1, pings))
    pn = s["x0"][1, 0] + np.cumsum(rng.normal(1.0, 0.1, pings))
    ph = np.asarray(s["vehicle"].obs.nav.pos[s["upd"][s["k"]], 2] - 30.0 + rng.normal(0, 1, pings))
    deltas = np.radians(np.linspace(-10, 10, 5))
    n = 2 * half_cells + 1
    msd, mad = np.empty((deltas.size, n, n)), np.empty((deltas.size, n, n))

    def jit():
        tercom.profile_surface(pe, pn, ph, pe[0], pn[0], half_cells, 5.0, deltas, za, msd, mad)
        tercom.surface_likelihood_moments(msd, deltas, half_cells, 5.0, pings, SIG_U)

    def numpy():
        a, _ = tercom.profile_surface_numpy(pe, pn, ph, pe[0], pn[0], half_cells, 5.0, deltas, za)
        tercom.surface_likelihood_moments_numpy(a, deltas, half_cells, 5.0, pings, SIG_U)

    return jit, numpy


def reference_steps(particles: int = 3000, reps: int = 10) -> dict:
    """For every built-in method, one update of its kernels against the same update of their
    plain-numpy references: microseconds each and the ratio numpy / jitted."""
    s = bench_state(particles)
    steps = {"tight-dvl": _pf_step(s, "dvl", False), "tight-sbe": _pf_step(s, "sbe", False),
             "loose-dvl": _pf_step(s, "dvl", True), "mpf-dvl": _mpf_step(s), "pmf-dvl": _pmf_step(s, 32),
             "pmf-sbe": _pmf_step(s, 32), "ekf-dvl": _ekf_step(s), "tercom-dvl": _tercom_step(s)}
    out = {}
    for name, (jit, ref) in steps.items():
        j, r = _best(jit, reps)[0], _best(ref, max(2, reps // 5))[0]
        out[name] = {"step_jit_us": round(j * 1e6, 1), "step_numpy_us": round(r * 1e6, 1),
                     "numpy_ratio": round(r / j, 1)}
    return out


def calibrated_cost_ns(particles: int = 3000, repeats: int = 2) -> dict[str, float]:
    """Per registered built-in method: thread-CPU ns per cost unit of a whole bench run."""
    return {m: run_figures(m, particles, repeats)["ns_per_unit_cpu"] for m in builtin_names()}


FIXED_COST_METHODS = ("tight-dvl", "tight-sbe", "loose-dvl")  # the CI and quick sweeps' methods
_START_UP = """
import sys, time
c0 = time.process_time()
{body}
print(time.process_time() - c0)
"""


# a worker forked from a process that has made the CLI's imports: the child's own CPU (fork, then ``body``)
_FORKED_WORKER = """
import os
{imports}
from tanbench.runner.executors import warm_up
pid = os.fork()
if pid == 0:
    {body}
    os._exit(0)
_, status, usage = os.wait4(pid, 0)
assert status == 0, status
print(usage.ru_utime + usage.ru_stime)
"""


def _child_cpu_s(body: str, script: str = _START_UP, **fields) -> float:
    """Process CPU seconds of ``body`` run in a fresh Python (imports included), or as ``script``
    (e.g. :data:`_FORKED_WORKER`, with its other ``fields``) measures it: the last line it prints."""
    proc = subprocess.run([sys.executable, "-c", script.format(body=body, **fields)], capture_output=True, text=True,
                          check=True)
    return float(proc.stdout.strip().splitlines()[-1])


def fixed_costs(runs: int = 5) -> dict:
    """What a sweep costs besides its filters, in thread/process CPU seconds (robust on a loaded machine).

    * ``parent_start_s``: a fresh ``tanbench run`` process importing what it needs;
    * ``worker_start_s``: a worker forked from such a process (how the CLI starts its workers on
      Linux, :func:`tanbench.runner.executors.local_context`) warming up (loading the cached
      kernels of) the three particle filters of the CI sweep; ``worker_spawn_s``: a spawned
      worker (elsewhere, or from a process running threads) importing tanbench and doing the same;
    * ``world_s``: building one noise-free world (truth, ping indices, ray-cast sonar ranges)
      of the default scenario, once per world and sweep, its seafloor read from the disk store;
    * ``seafloor_synthesis_s`` / ``seafloor_read_s``: synthesising the default seafloor (once per
      machine and code version, :mod:`tanbench.terrain.seafloor_cache`) / reading it back;
    * per task (a run of the default scenario, the best of ``runs``): ``simulation_s`` (the
      run's sensors and navigation solution), ``around_filter_s`` (per method, what
      ``run_method`` spends besides the filter: inputs, checks, scoring, bound; measured
      with a 16-particle filter that re-draws a diverged cloud instead of searching the map, whose own
      time is a small part of it), and
      ``store_s`` (the parent writing the task's rows and series).
    """
    import json


    parent_imports = "import tanbench.cli, tanbench.runner.engine, tanbench.results"
    warm_up_call = f"warm_up(None, {FIXED_COST_METHODS!r})"
    out = {"parent_start_s": _child_cpu_s(parent_imports),
           "worker_start_s": _child_cpu_s(warm_up_call, _FORKED_WORKER, imports=parent_imports),
           "worker_spawn_s": _child_cpu_s(
               "from tanbench.runner.executors import single_thread_environment, warm_up\n"
               f"single_thread_environment(); {warm_up_call}")}
    scenario = Scenario()
    world = json.dumps(scenario.world_spec(), sort_keys=True)
    key = terrain_key(scenario.terrain)
    c0 = time.thread_time()
    synthesise_seafloor(scenario.terrain)
    out["seafloor_synthesis_s"] = time.thread_time() - c0
    truth_map(scenario.terrain)  # stored if it was not
    c0 = time.thread_time()
    seafloor_cache.load(key)
    out["seafloor_read_s"] = time.thread_time() - c0
    noise_free_world.cache_clear()
    clear_truth_maps()
    c0 = time.thread_time()
    noise_free_world(world)
    out["world_s"] = time.thread_time() - c0
    # 16 particles: the filter's own time is a small part of this (~1 %); such a cloud diverges, so it re-draws
    # around its own estimate (recovery: estimate) instead of searching the map (the default's global search,
    # whose cost is the filter's, counted in its ns per particle-step where a run diverges)
    tiny = scenario.model_copy(update={"particles": 16,
                                       "filter": scenario.filter.model_copy(update={"recovery": "estimate"})})
    sim, around = [], []
    for r in range(runs):
        c0 = time.thread_time()
        vehicle = simulate_vehicle(scenario, np.random.SeedSequence([BENCH_SEED, r]))
        sim.append(time.thread_time() - c0)
        for method in FIXED_COST_METHODS:
            c0 = time.thread_time()
            run_method(tiny, method, vehicle, np.random.SeedSequence(r))
            around.append(time.thread_time() - c0)
    out["simulation_s"] = min(sim)
    out["around_filter_s"] = float(np.median(around))
    out["store_s"] = _store_cost(runs)
    return {k: round(v, 4) for k, v in out.items()}


def _store_cost(runs: int) -> float:
    """Thread CPU seconds of the parent storing one finished task (rows and series) of the default
    scenario (best of ``runs``)."""
    import tempfile
    from pathlib import Path


    sweep = parse_sweep(f"name: bench\nseed: {BENCH_SEED}\nruns: 1\nmethods: {list(FIXED_COST_METHODS)}\n"
                        "scenario: {particles: 16}\n")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench"
        plan = make_plan(sweep, out, None, 1)
        result = execute(plan.tasks[0])
        state = ResumeState.read(sweep, out)
        meta = store.provenance(sweep.text, sweep.name, sweep.spec.seed)
        columns = cell_columns(sweep)
        best = []
        for _ in range(runs):
            c0 = time.thread_time()
            store_result(result, plan, state, columns, meta, False)
            best.append(time.thread_time() - c0)
    return min(best)


def yardstick_ns(path, particles: int = 3000) -> float | None:
    """The yardstick's naive filter step (``measure()`` of the file ``path``, e.g. the project's
    ``../shared/tools/yardstick.py``) in ns per particle-step by thread CPU, in this process; None if
    there is no such file."""
    import importlib.util
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        return None
    module = sys.modules.get("tanbench_yardstick")
    if module is None or getattr(module, "__file__", None) != str(path):
        spec = importlib.util.spec_from_file_location("tanbench_yardstick", path)
        module = importlib.util.module_from_spec(spec)
        # registered before it runs: numba's cache records a jitted function's module by name and
        # imports it when it loads the function again (unregistered, a warm cache failed to load:
        # "No module named '<dynamic>'")
        sys.modules["tanbench_yardstick"] = module
        spec.loader.exec_module(module)
    return float(module.measure(M=particles))


def compile_target() -> str:
    """The CPU numba compiles the kernels for, and the widest vectors they may use: the host's, unless
    ``NUMBA_CPU_NAME`` / ``NUMBA_CPU_FEATURES`` say otherwise. The kernels' figures depend on it: tight-dvl
    against the yardstick was 0.33 with AVX-512 and 0.45-0.47 compiled for AVX2 on the same machine
    (docs/speed.md, "seventeenth session")."""
    import llvmlite.binding as llvm
    from numba.core import config

    name = config.CPU_NAME or llvm.get_host_cpu_name()
    if config.CPU_FEATURES is not None:
        return f"{name}, features {config.CPU_FEATURES!r} (NUMBA_CPU_FEATURES)"
    if config.CPU_NAME is not None:
        return f"{name} (NUMBA_CPU_NAME) with its own default features"
    features = llvm.get_host_cpu_features()
    widest = "AVX-512" if features.get("avx512f") else "AVX2" if features.get("avx2") else "neither AVX2 nor AVX-512"
    return f"{name} (this host), {widest}"


def run_bench(particles: int = 3000, repeats: int = 3, methods=None, yardstick=None) -> dict:
    """Measure and return every figure as a dict. With ``yardstick`` (a file with a ``measure()``),
    tight-dvl's filter and the yardstick's step are timed in turn in this process, ``repeats`` times each."""
    methods = list(methods or names())
    runs = []
    for method in methods:
        runs.append(run_figures(method, particles, repeats))
        if method in PARTICLE_FILTERS:
            runs.append(run_figures(method, particles, repeats, "numpy"))
        if method == "tight-dvl":
            runs += [run_figures(method, particles, repeats, options=options) for options in OPTION_RUNS]
    rounds = []
    if yardstick is not None and yardstick_ns(yardstick, particles) is not None:  # the first call compiles
        for _ in range(repeats):
            tight = run_figures("tight-dvl", particles, 1)["ns_per_unit_cpu"]
            rounds.append({"tight_dvl_ns": tight, "yardstick_ns": yardstick_ns(yardstick, particles)})
    return {"particles": particles, "updates": 1191, "target": compile_target(), "runs": runs,
            "steps": reference_steps(particles),
            "kernels": kernel_breakdown(particles), "fixed": fixed_costs(),
            "multibeam": multibeam_likelihood(particles), "yardstick": rounds}


def multibeam_likelihood(particles: int = 3000, beams: int = 64, reps: int = 10) -> dict:
    """Cost per particle-beam of the multibeam likelihood: the tight PF's likelihood pass over a
    ``beams``-beam, 120-degree fan cast from the true pose half-way through the bench run, on the
    mid-run cloud (thread CPU ns per particle and beam), jitted and by its numpy twin."""
    s = bench_state(particles)
    sc, tr, k = s["scenario"], s["vehicle"].truth, s["upd"][s["k"] + 1]
    angles = fan_angles_deg(beams, 120.0)
    fan = fan_vectors(angles)
    ranges = swath_ranges(truth_map(sc.terrain), tr.pos[k:k + 1], tr.pitch[k:k + 1], tr.roll[k:k + 1],
                          tr.yaw[k:k + 1], np.radians(angles)[None, :], sc.sensors.max_range_m)[0]
    vec = beam_vectors(fan, ranges)
    used = vec.shape[0]
    x, grid, lik, m = s["x0"].copy(), s["grid"], s["lik"], particles
    work = L.work_block(L.new_likelihood_work(m, 4 * grid.grids), m)
    consts = L.beam_constants(SIG_U, SIG_D, OUTSIDE)
    ll, dist = np.empty(m), np.zeros((2, m))
    nmap, f = s["ctx"].nmap, sc.filter
    mvar = filter_map_variance(f, nmap)
    za = nmap.kernel_args()
    jit = _best(lambda: L.loglik_tight_pass(x, 0, vec, grid, lik, consts, s["att"], dist, False, work, ll), reps)[0]
    ref = _best(lambda: L.loglik_tight_numpy(x, fan, ranges, za, mvar, lik, SIG_U, OUTSIDE, None, SIG_D), 2)[0]
    return {"beams": used, "particles": m, "ns_per_particle_beam_jit": round(jit / (m * used) * 1e9, 2),
            "ns_per_particle_beam_numpy": round(ref / (m * used) * 1e9, 2), "numpy_ratio": round(ref / jit, 1)}
