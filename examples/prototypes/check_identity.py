"""The prototype with its options off is the built-in tight filter bit for bit (one short run)."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main():
    from tanbench.config import Scenario
    from tanbench.methods import get, method_context
    from tanbench.runner.seeds import vehicle_seed
    from tanbench.simulation import simulate_vehicle
    from tan_proto import loose, tight
    from worlds import world

    for name, sensor in (("tight-dvl", "dvl"), ("tight-sbe", "sbe"), ("loose-dvl", None)):
        seed, sc = world("A")
        sc.update(duration_s=200.0, particles=700)
        scenario = Scenario(**sc)
        vehicle = simulate_vehicle(scenario, vehicle_seed(seed, scenario, 0))
        fseed = np.random.SeedSequence(5, spawn_key=(1, 2))
        a = get(name).run(method_context(scenario, name, vehicle, fseed, get(name)))
        ctx = method_context(scenario, name, vehicle, fseed, get(name))
        b = tight.run_tight(ctx, sensor) if sensor else loose.run_loose(ctx)
        same = all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("east", "north", "yaw", "var_e", "ess"))
        print(name, "identical" if same else "DIFFERENT", float(np.abs(a.east - b.east).max()))
        if not same:
            raise SystemExit(1)


if __name__ == "__main__":
    main()
