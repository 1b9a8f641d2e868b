"""Filter wall time of built-in methods run back to back on the same runs (ratios only; shared machine).

    ../../.venv/bin/python timing.py WORLD RUNS METHOD[@PARTICLES],...
"""

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(world, runs, methods):
    from measure import scenario_of
    from tanbench.methods import get, method_context
    from tanbench.navigation.increments import SharedIncrements
    from tanbench.runner.seeds import filter_seed, vehicle_seed
    from tanbench.simulation import simulate_vehicle

    seed, base = scenario_of(world, {})
    specs = []
    for m in methods.split(","):
        name, _, parts = m.partition("@")
        _, sc = scenario_of(world, {"scenario": {"particles": int(parts)}} if parts else {})
        specs.append((m, name, sc))
    walls = {m: [] for m, _, _ in specs}
    for run in range(int(runs)):
        vehicle = simulate_vehicle(base, vehicle_seed(seed, base, run))
        for m, name, sc in specs * 2:  # twice: the first call of a run warms the caches
            ctx = method_context(sc, name, vehicle, filter_seed(seed, sc, name, run), get(name))
            # each call pays its own increments table: the run's methods share one since the fifth session
            # (Observations.shared_increments), which would charge it to whichever ran first
            ctx.obs.shared_increments = SharedIncrements()
            t0 = time.perf_counter()
            get(name).run(ctx)
            walls[m].append(time.perf_counter() - t0)
    ref = np.median(walls[specs[0][0]])
    for m, w in walls.items():
        print(f"{m}: median {np.median(w):.3f} s, {np.median(w) / ref:.2f} x {specs[0][0]}")


if __name__ == "__main__":
    main(*sys.argv[1:])
