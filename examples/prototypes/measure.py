"""Run method variants on the worlds of ``worlds.py`` and keep every per-update series.

    nice -n 10 ../../.venv/bin/python measure.py OUT --worlds A,B --variants tight-dvl,pmf-dvl --runs 10 --workers 2

A variant (``variants.py``) is a method (built-in or a plug-in of ``tan_proto``) with its
method options and filter settings. One task is one run of one world: the vehicle data are
simulated once (the seeds a sweep of that world would use: run r's vehicle seed from the
world's root seed, pairing key and r) and every variant runs on them, so all comparisons are
paired. Each (world, variant, run) is written to OUT/world/variant/run-NNNNN.parquet (the
series of every key the method returns, the per-run metrics as columns of the first row);
what exists is not recomputed.
"""

from __future__ import annotations

import argparse
import json
import sys
from multiprocessing import get_context
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def scenario_of(world_name: str, variant: dict):
    from tanbench.config import Scenario
    from worlds import world

    seed, sc = world(world_name)
    sc.setdefault("filter", {}).update(variant.get("filter", {}))
    sc.update(variant.get("scenario", {}))
    if variant.get("options"):
        sc["method_options"] = {variant["method"]: variant["options"]}
    return seed, Scenario(**sc)


def task(args):
    world_name, run, labels, out = args
    import numpy as np
    import pandas as pd

    from tanbench.methods import run_method
    from tanbench.runner.seeds import filter_seed, vehicle_seed
    from tanbench.simulation import simulate_vehicle
    from variants import VARIANTS

    seed, base = scenario_of(world_name, {})
    vehicle = simulate_vehicle(base, vehicle_seed(seed, base, run))
    done = []
    for label in labels:
        path = Path(out) / world_name / label / f"run-{run:05d}.parquet"
        if path.exists():
            continue
        variant = VARIANTS[label]
        seed, sc = scenario_of(world_name, variant)
        assert sc.pairing_key() == base.pairing_key()
        result = run_method(sc, variant["method"], vehicle, filter_seed(seed, sc, variant["method"], run))
        k = len(result.series["t"])
        cols = {key: np.asarray(v, dtype=float) for key, v in result.series.items()
                if np.ndim(v) == 1 and len(v) == k}
        frame = pd.DataFrame(cols)
        for key, value in result.metrics.items():
            frame[f"m_{key}"] = value
        frame["run"] = run
        path.parent.mkdir(parents=True, exist_ok=True)
        frame.to_parquet(path.with_suffix(".tmp"))
        path.with_suffix(".tmp").rename(path)
        done.append((label, result.metrics["final_horizontal_error_m"], result.metrics["filter_wall_s"]))
    return world_name, run, done


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--worlds", required=True)
    p.add_argument("--variants", required=True)
    p.add_argument("--runs", type=int, default=10)
    p.add_argument("--first-run", type=int, default=0)
    p.add_argument("--workers", type=int, default=2)
    a = p.parse_args(argv)
    from variants import VARIANTS

    labels = a.variants.split(",")
    unknown = [v for v in labels if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"unknown variants: {unknown}")
    tasks = [(w, r, labels, a.out) for w in a.worlds.split(",") for r in range(a.first_run, a.first_run + a.runs)]
    tasks = [t for t in tasks if any(not (Path(a.out) / t[0] / v / f"run-{t[1]:05d}.parquet").exists()
                                     for v in labels)]
    print(f"{len(tasks)} tasks", flush=True)
    if a.workers <= 1:
        results = map(task, tasks)
    else:
        pool = get_context("spawn").Pool(a.workers, maxtasksperchild=20)
        results = pool.imap_unordered(task, tasks)
    for world_name, run, done in results:
        print(world_name, run, json.dumps([(lab, round(e, 2), round(w, 2)) for lab, e, w in done]), flush=True)


if __name__ == "__main__":
    main()
