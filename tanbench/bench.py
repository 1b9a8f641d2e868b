"""Speed of the methods: whole runs, their random-number variants, kernels against numpy references.

The bench scenario is the paper's: area A, the 10 m map, 4 DVL beams, 3000 particles,
a whole 1190 s run (1191 updates). For every registered method it reports

* ns per cost unit (particle-step for the particle filters: a run's filter time divided
  by updates x particles), by thread CPU time (what the method costs one core, robust
  on a loaded machine) and by wall time, and the whole run's wall time;
* for the built-in filters, the same with ``filter.random_numbers: fast``;
* the ratio of one update step in plain numpy (the kernels' references) to the jitted
  step, and a per-kernel breakdown (ns per particle) on a mid-run cloud.

Figures depend on the machine and its load; nothing here is asserted by the tests.
``calibrated_cost_ns`` gives what ``MethodRecord.cost_ns`` (``tanbench plan``'s estimate)
should hold on this machine: thread CPU ns per cost unit of a whole ``run_method``.
"""

from __future__ import annotations

import math
import time

import numpy as np

BENCH_SEED = 2017


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


def bench_scenario(particles: int, random_numbers: str = "numpy"):
    from tanbench.config import Scenario

    return Scenario(particles=particles, filter={"random_numbers": random_numbers})


def run_figures(method: str, particles: int, repeats: int, random_numbers: str = "numpy") -> dict:
    """Whole-run figures of ``method``: ns per cost unit (CPU and wall), run wall, calibrated cost."""
    from tanbench.methods import get, run_method
    from tanbench.simulation import simulate_vehicle

    scenario = bench_scenario(particles, random_numbers)
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
        "method": method, "random_numbers": random_numbers, "cost_units": units,
        "ns_per_unit_cpu": round(min(cpu) / units * 1e9, 1),
        "ns_per_unit_wall": round(min(filt) / units * 1e9, 1),
        "run_wall_s": round(min(wall), 3),
        "resampled_fraction": None if ess is None else round(float(np.mean(ess < 0.5 * particles)), 3),
    }


def _mid_run_state(particles: int):
    """A mid-run tight cloud and the inputs of one update of the bench run."""
    from tanbench.methods import method_context
    from tanbench.navigation.increments import compute_increments
    from tanbench.simulation import simulate_vehicle

    scenario = bench_scenario(particles)
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(BENCH_SEED))
    ctx = method_context(scenario, "tight-dvl", vehicle, np.random.SeedSequence(1))
    obs, nav, upd = vehicle.obs, vehicle.obs.nav, ctx.updates.imu
    rng = np.random.default_rng(5)
    k = len(upd) // 2
    x0 = np.empty((particles, 8))
    x0[:, 0] = vehicle.truth.pos[upd[k], 0] + rng.uniform(-20, 20, particles)
    x0[:, 1] = vehicle.truth.pos[upd[k], 1] + rng.uniform(-20, 20, particles)
    x0[:, 2] = nav.pos[upd[k], 2]
    x0[:, 3] = nav.pitch[upd[k]]
    x0[:, 4] = nav.roll[upd[k]]
    # headings about the true one, as a converged cloud's: ~30 degrees off the navigation's
    x0[:, 5] = vehicle.truth.yaw[upd[k]] + rng.normal(0, 0.02, particles)
    x0[:, 6:] = rng.normal(0, 1e-4, (particles, 2))
    inc = compute_increments(obs.dt, nav.pos, nav.pitch, nav.roll, nav.yaw, upd)
    from tanbench.methods.tight import likelihood_bundle

    return dict(k=k, x0=x0, inc=inc, nav=nav, upd=upd, zargs=ctx.nmap.kernel_args(),
                lik=likelihood_bundle(scenario.filter, ctx.nmap),
                ranges=np.ascontiguousarray(obs.dvl_ranges[ctx.updates.rows[k + 1]]),
                beams=np.ascontiguousarray(obs.dvl_beams), noise=rng.standard_normal((particles, 6)),
                uni=rng.random(particles))


def kernel_breakdown(particles: int = 3000, reps: int = 30) -> dict:
    """ns per particle (thread CPU) of each kernel of one tight-dvl and loose-dvl update,
    the jitted step against its numpy reference step, and the random numbers' cost."""
    import numba as nb

    from tanbench.filters.estimate import weighted_estimate, weighted_estimate_numpy
    from tanbench.filters.likelihood import (loglik_loose, loglik_loose_numpy, loglik_tight, loglik_tight_mapaware_stacked,
                                            loglik_tight_numpy)
    from tanbench.filters.params import Readings, TightModel
    from tanbench.filters.rng import loop_rng
    from tanbench.filters.tight import propagate_and_weigh
    from tanbench.filters.propagate import (propagate_loose, propagate_loose_numpy, propagate_tight,
                                            propagate_tight_numpy)
    from tanbench.filters.resample import (REG_LIU_WEST, SYSTEMATIC, apply_resample, effective_sample_size,
                                           normalize_log_weights, normalize_log_weights_numpy, regularise,
                                           resample_indices, resample_indices_numpy, shrink_jitter_numpy)
    from tanbench.filters.rng import FastRng
    from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

    s = _mid_run_state(particles)
    m, k, x0, nav, upd, z = particles, s["k"], s["x0"], s["nav"], s["upd"], s["zargs"]
    sig = (0.07, 0.01, math.radians(2 / 60))
    yaw_off = float(np.mean(x0[:, 5]) - nav.yaw[upd[k]])  # the cloud's heading offset, as the loop keeps it
    ref = (nav.pitch[upd[k + 1]], nav.roll[upd[k + 1]], nav.yaw[upd[k + 1]] + yaw_off)
    x, dist, ll, w = x0.copy(), np.zeros((m, 2)), np.empty(m), np.empty(m)
    idx, scratch, mean, v, cov = np.empty(m, dtype=np.int64), np.empty_like(x0), np.empty(8), np.empty(8), \
        np.empty((2, 2))
    cols = np.array([0, 1, 5, 6, 7], dtype=np.int64)
    noise = np.empty((m, 6))
    xl = np.ascontiguousarray(x0[:, :2])
    c = dcm_body_to_nav_numpy(np.array([ref[0]]), np.array([ref[1]]), np.array([nav.yaw[upd[k + 1]]]))[0]
    offsets = np.ascontiguousarray((s["beams"] @ c.T) * s["ranges"][:, None])
    d0 = s["inc"][k][:2]

    def per(fn):
        return round(_best(fn, reps)[0] / m * 1e9, 1)

    out = {"tight-dvl": {}, "loose-dvl": {}}
    from tanbench.filters.rng import Pcg64Stream

    for name, gen in (("numpy Generator", np.random.default_rng(7)),
                      ("numpy, inline PCG64 as the loops draw", Pcg64Stream(np.random.default_rng(7))),
                      ("fast", FastRng.from_seed(np.random.SeedSequence(7)))):
        out["tight-dvl"][f"random normals x6 ({name})"] = per(lambda: _draw_normals(gen, noise))
        out["tight-dvl"][f"random uniform x1 ({name})"] = per(lambda: _draw_uniforms(gen, s["uni"].copy()))
    t = out["tight-dvl"]
    t["propagate"] = per(lambda: propagate_tight(x, s["inc"][k], nav.yaw[upd[k]], s["noise"], *sig, 1, dist,
                                                 yaw_off))
    x[:] = x0
    t["likelihood (4 beams)"] = per(lambda: loglik_tight(x, s["beams"], s["ranges"], *z, 1.0, 5.0, dist, 0.1,
                                                         *ref, ll))
    zz = s["lik"].grids
    t["likelihood map-aware Student-t (4 beams)"] = per(lambda: loglik_tight_mapaware_stacked(
        x, s["beams"], s["ranges"], zz, *z[1:], 1.0, 5.0, dist, 0.1, *ref, s["lik"].kind, s["lik"].nu, ll))
    model = TightModel(sig[0], sig[1], sig[2], 1, 0.1, 1.0, 5.0)
    readings = Readings(0, 1.0, 0.0, True, 0.0)
    stream = loop_rng(np.random.default_rng(9), "numpy")

    def fused():
        x[:] = x0
        propagate_and_weigh(x, stream, True, s["inc"][k], nav.yaw[upd[k]], yaw_off, nav.pitch[upd[k]],
                            nav.roll[upd[k]], np.zeros(4), readings, model, s["beams"], s["ranges"], z, s["lik"],
                            *ref, ll)

    t["fused pass: 6 normals + propagate + map-aware likelihood (incl. copy)"] = per(fused)
    x[:] = x0
    t["normalise"] = per(lambda: normalize_log_weights(ll, w))
    t["estimate"] = per(lambda: weighted_estimate(x, w, 5, 0.0, mean, v, cov))
    t["ess"] = per(lambda: effective_sample_size(w))
    t["resample (indices + copy)"] = per(lambda: (resample_indices(SYSTEMATIC, w, s["uni"], idx),
                                                  apply_resample(x, idx, scratch)))
    x[:] = x0
    gen = np.random.default_rng(8)
    t["regularise (5 states, numpy draws)"] = per(lambda: regularise(x, gen, REG_LIU_WEST, cols, 0.1, 8))
    x[:] = x0
    fast = FastRng.from_seed(np.random.SeedSequence(8))
    t["regularise (5 states, fast draws)"] = per(lambda: regularise(x, fast, REG_LIU_WEST, cols, 0.1, 8))
    x[:] = x0

    def tight_jit():
        xx = x0.copy()
        propagate_tight(xx, s["inc"][k], nav.yaw[upd[k]], s["noise"], *sig, 1, dist, yaw_off)
        loglik_tight(xx, s["beams"], s["ranges"], *z, 1.0, 5.0, dist, 0.1, *ref, ll)
        normalize_log_weights(ll, w)
        weighted_estimate(xx, w, 5, 0.0, mean, v, cov)
        resample_indices(SYSTEMATIC, w, s["uni"], idx)
        apply_resample(xx, idx, scratch)

    def tight_numpy():
        xx, dd = propagate_tight_numpy(x0, s["inc"][k], nav.yaw[upd[k]], s["noise"], *sig, 1)
        lq, _ = loglik_tight_numpy(xx, s["beams"], s["ranges"], *z, 1.0, 5.0, dd, 0.1)
        ww, _ = normalize_log_weights_numpy(lq)
        weighted_estimate_numpy(xx, ww, 5, 0.0)
        xx = xx[resample_indices_numpy(SYSTEMATIC, ww, s["uni"])]
        shrink_jitter_numpy(xx, cols, 0.1, s["noise"][:, :5])

    lw = np.empty(m)
    lo = out["loose-dvl"]
    lo["propagate"] = per(lambda: propagate_loose(xl, d0[0], d0[1], s["noise"][:, :3], 0.1, 0.5))
    xl[:] = x0[:, :2]
    lo["likelihood (4 beams)"] = per(lambda: loglik_loose(xl, offsets, nav.pos[upd[k + 1], 2], *z, 1.0, 5.0, lw))
    lo["estimate"] = per(lambda: weighted_estimate(xl, w, -1, 0.0, mean[:2], v[:2], cov))

    def loose_jit():
        xx = xl.copy()
        propagate_loose(xx, d0[0], d0[1], s["noise"][:, :3], 0.1, 0.5)
        loglik_loose(xx, offsets, nav.pos[upd[k + 1], 2], *z, 1.0, 5.0, lw)
        normalize_log_weights(lw, w)
        weighted_estimate(xx, w, -1, 0.0, mean[:2], v[:2], cov)
        resample_indices(SYSTEMATIC, w, s["uni"], idx)
        apply_resample(xx, idx, scratch[:, :2].copy())

    def loose_numpy():
        xx = propagate_loose_numpy(xl, d0[0], d0[1], s["noise"][:, :3], 0.1, 0.5)
        lq, _ = loglik_loose_numpy(xx, offsets, nav.pos[upd[k + 1], 2], *z, 1.0, 5.0)
        ww, _ = normalize_log_weights_numpy(lq)
        weighted_estimate_numpy(xx, ww, -1, 0.0)
        xx = xx[resample_indices_numpy(SYSTEMATIC, ww, s["uni"])]

    steps = {}
    for name, jit, ref_fn in (("tight-dvl", tight_jit, tight_numpy), ("loose-dvl", loose_jit, loose_numpy)):
        j, r = _best(jit, reps)[0], _best(ref_fn, max(3, reps // 5))[0]
        steps[name] = {"step_jit_us": round(j * 1e6, 1), "step_numpy_us": round(r * 1e6, 1),
                       "numpy_ratio": round(r / j, 1)}
    _ = nb  # numba is imported for the helpers' compilation below
    return {"kernels": out, "steps": steps}


def _jitted_helpers():
    import numba as nb

    @nb.njit(cache=True)
    def draw_normals(rng, noise):
        for j in range(noise.shape[0]):
            for c in range(noise.shape[1]):
                noise[j, c] = rng.standard_normal()

    @nb.njit(cache=True)
    def draw_uniforms(rng, u):
        for j in range(u.shape[0]):
            u[j] = rng.random()

    return draw_normals, draw_uniforms


_draw_normals, _draw_uniforms = _jitted_helpers()


def calibrated_cost_ns(particles: int = 3000, repeats: int = 2) -> dict[str, float]:
    """Per registered built-in method: thread-CPU ns per cost unit of a whole bench run."""
    from tanbench.methods.registry import builtin_names

    return {m: run_figures(m, particles, repeats)["ns_per_unit_cpu"] for m in builtin_names()}


def run_bench(particles: int = 3000, repeats: int = 3, methods=None) -> dict:
    """Measure and return every figure as a dict."""
    from tanbench.methods.registry import builtin_names, names

    methods = list(methods or names())
    runs = []
    for method in methods:
        runs.append(run_figures(method, particles, repeats))
        if method in builtin_names():
            runs.append(run_figures(method, particles, repeats, "fast"))
    return {"particles": particles, "updates": 1191, "runs": runs, **kernel_breakdown(particles)}
