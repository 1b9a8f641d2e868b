"""Speed of the tight-dvl filter: jitted kernels against their plain-numpy references.

The benchmark of the filters issue: tight-dvl at 3000 particles, 4 DVL beams, the 10 m
map, area A. It reports nanoseconds per particle-step (a whole 1190 s run's filter
time divided by updates x particles: propagate, weight and the resampling share),
the wall time of that run, and the time of one update step (propagate + weight +
normalise + estimate + resample) jitted and in the numpy reference, with their ratio.
Then every built-in method's cost at its defaults on that run: filter wall time per run
and per update. Figures depend on the machine; nothing here is asserted by the tests.
"""

from __future__ import annotations

import math
import time

import numpy as np


def run_bench(particles: int = 3000, repeats: int = 3) -> dict:
    """Measure and return the figures as a dict."""
    from tanbench.config import Scenario
    from tanbench.filters.estimate import weighted_estimate, weighted_estimate_numpy
    from tanbench.filters.likelihood import loglik_tight, loglik_tight_numpy
    from tanbench.filters.propagate import propagate_tight, propagate_tight_numpy
    from tanbench.filters.resample import (SYSTEMATIC, apply_resample, normalize_log_weights,
                                           normalize_log_weights_numpy, resample_indices, resample_indices_numpy)
    from tanbench.methods import run_method, update_indices
    from tanbench.navigation.increments import compute_increments
    from tanbench.simulation import simulate_vehicle
    from tanbench.terrain import navigation_map

    scenario = Scenario(particles=particles)
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(2017))
    run_method(scenario, "tight-dvl", vehicle, np.random.SeedSequence(1))  # compile / load cache
    updates = update_indices(scenario, vehicle.obs)
    rows, upd = updates.rows, updates.imu
    walls = []
    for r in range(repeats):
        result = run_method(scenario, "tight-dvl", vehicle, np.random.SeedSequence(1 + r))
        walls.append(result.metrics["filter_wall_s"])
    run_wall = min(walls)
    ns_per = run_wall / (len(upd) * particles) * 1e9

    # one update step, jitted vs numpy, on the same state and draws
    rng = np.random.default_rng(5)
    nmap = navigation_map(scenario.terrain, scenario.map_resolution_m)
    zargs = nmap.kernel_args()
    inc = compute_increments(vehicle.obs.dt, vehicle.obs.nav.pos, vehicle.obs.nav.pitch, vehicle.obs.nav.roll,
                             vehicle.obs.nav.yaw, upd)
    k = len(upd) // 2
    x0 = np.empty((particles, 8))
    x0[:, 0] = vehicle.truth.pos[upd[k], 0] + rng.uniform(-20, 20, particles)
    x0[:, 1] = vehicle.truth.pos[upd[k], 1] + rng.uniform(-20, 20, particles)
    x0[:, 2] = vehicle.obs.nav.pos[upd[k], 2]
    x0[:, 3] = vehicle.obs.nav.pitch[upd[k]]
    x0[:, 4] = vehicle.obs.nav.roll[upd[k]]
    x0[:, 5] = vehicle.obs.nav.yaw[upd[k]] + rng.normal(0, 0.1, particles)
    x0[:, 6:] = rng.normal(0, 1e-4, (particles, 2))
    noise = rng.standard_normal((particles, 6))
    uni = rng.random(particles)
    ranges = vehicle.obs.dvl_ranges[rows[k + 1]]
    beams = vehicle.obs.dvl_beams
    sig = (0.1, 0.01, math.radians(2 / 60))

    def jitted():
        x = x0.copy()
        dist = np.zeros((particles, 2))
        ll = np.empty(particles)
        w = np.empty(particles)
        propagate_tight(x, inc[k], vehicle.obs.nav.yaw[upd[k]], noise, *sig, 1, dist)
        loglik_tight(x, beams, ranges, *zargs, 1.0, 5.0, dist, 0.1, vehicle.obs.nav.pitch[upd[k + 1]],
                     vehicle.obs.nav.roll[upd[k + 1]], vehicle.obs.nav.yaw[upd[k + 1]], ll)
        normalize_log_weights(ll, w)
        weighted_estimate(x, w, 5, 0.0, np.empty(8), np.empty(8), np.empty((2, 2)))
        idx = np.empty(particles, dtype=np.int64)
        resample_indices(SYSTEMATIC, w, uni, idx)
        apply_resample(x, idx, np.empty_like(x))

    def reference():
        x, dist = propagate_tight_numpy(x0, inc[k], vehicle.obs.nav.yaw[upd[k]], noise, *sig, 1)
        ll, _ = loglik_tight_numpy(x, beams, ranges, *zargs, 1.0, 5.0, dist, 0.1)
        w, _ = normalize_log_weights_numpy(ll)
        weighted_estimate_numpy(x, w, 5, 0.0)
        x = x[resample_indices_numpy(SYSTEMATIC, w, uni)]

    def best(fn, n):
        fn()
        times = []
        for _ in range(n):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return min(times)

    step_jit = best(jitted, 50)
    step_np = best(reference, 10)
    return {
        "method": "tight-dvl",
        "particles": particles,
        "updates": int(len(upd)),
        "ns_per_particle_step": round(ns_per, 2),
        "run_wall_s": round(run_wall, 4),
        "step_jit_us": round(step_jit * 1e6, 1),
        "step_numpy_us": round(step_np * 1e6, 1),
        "numpy_ratio": round(step_np / step_jit, 1),
        "targets": {"ns_per_particle_step": 40, "run_wall_s": 0.25, "numpy_ratio": 10},
        "methods": method_costs(scenario, vehicle),
    }


def method_costs(scenario, vehicle, repeats: int = 2) -> dict:
    """Every built-in method at its defaults on the same run: filter wall time of the whole run and
    per update (the best of ``repeats`` after a compile / cache-loading run)."""
    from tanbench.methods import run_method, update_indices
    from tanbench.methods.registry import builtin_names

    k = update_indices(scenario, vehicle.obs).size
    out = {}
    for method in builtin_names():
        walls = [run_method(scenario, method, vehicle, np.random.SeedSequence(7 + r)).metrics["filter_wall_s"]
                 for r in range(repeats + 1)][1:]
        out[method] = {"run_wall_s": round(min(walls), 4), "us_per_update": round(min(walls) / k * 1e6, 1)}
    return out
