"""``filter.recovery_search_around: estimate-then-navigation`` against the defaults (docs/filters.md 17): paired runs.

Every run's vehicle data and filter seed are those of the defaults' keys (as ``global_recovery.py``); each tight
method of a cell runs at the defaults and, with the second search square, on the same data and seed. The arms
can differ only after a divergence fired (a search runs only then), so a run whose defaults arm was never
reinitialised is the same run in both arms: its candidate row is the defaults' row, marked ``copied``, not run
again. ``--roots`` runs each sweep again with other root seeds (other realisations of the same cells).

    .venv/bin/python examples/prototypes/nav_centred_search.py OUT.csv SWEEP[:RUNS[:METHODS]] ... [--roots R1,R2]
        [--methods tight-sbe,tight-dvl] [--workers 2]
    .venv/bin/python examples/prototypes/nav_centred_search.py --summary OUT.csv[,OUT2.csv]
(``--distant``: section 18's candidate, ``estimate-then-distant-navigation``.)
"""

from __future__ import annotations

import sys

import numpy as np

from global_recovery import TIGHT, describe_pairs, four_rules
from loose_fix_gate import _pinned, write_rows
from tanbench.config import Scenario
from tanbench.methods import get, run_method
from tanbench.runner.seeds import keyed_filter_seed, keyed_vehicle_seed
from tanbench.simulation import simulate_vehicle
from tanbench.sweep import load_sweep

CANDIDATE = "navigation"
FIELDS = ["group", "cell", "root", "run", "method", "arm", "copied", "diverged", "final_horizontal_error_m",
          "mean_horizontal_error_m", "reinitialisations", "recoveries", "filter_wall_s"]


# the candidate's value of filter.recovery_search_around: section 17's, or section 18's (``--distant``)
SEARCH_AROUND = {"value": "estimate-then-navigation"}


def with_second_square(scenario: Scenario) -> Scenario:
    return _pinned(scenario, recovery_search_around=SEARCH_AROUND["value"])


def jobs(sweeps: list, roots: list | None, methods: list | None) -> list:
    """(group, cell name, scenario, root, run, methods) of every run of every distinct cell of ``sweeps``
    ((group, path, runs, methods or None)), once per root seed (the sweep's own when ``roots`` is None); the tight
    methods the sweep names, only those of the sweep's own list (or else of ``methods``) when given."""
    out = []
    for group, path, runs, own in sweeps:
        sweep = load_sweep(path)
        keep = own or methods
        tight = [m for m in sweep.spec.methods if m in TIGHT and (keep is None or m in keep)]
        seen = set()
        for cell in sweep.cells:
            if cell.cell_id in seen or not tight:
                continue
            seen.add(cell.cell_id)
            for root in roots or [sweep.spec.seed]:
                out += [(group, f"{group}:{cell.cell_id[:8]}", cell.scenario, root, r, tight) for r in range(runs)]
    return out


def as_run_for_sections_17_18(scenario: Scenario) -> Scenario:
    """The defaults sections 17 and 18 ran against: ``recovery_search_around: estimate`` (neutral; the default since
    section 18.1), so the pairs keep their keys and seeds."""
    return _pinned(scenario, recovery_search_around="estimate")


def _pair(job):
    group, name, scenario, root, run, methods = job
    scenario = as_run_for_sections_17_18(scenario)
    vehicle = simulate_vehicle(scenario, keyed_vehicle_seed(root, scenario.pairing_key(), run))
    rows = []
    for method in methods:
        fseed = keyed_filter_seed(root, scenario.cell_key(), get(method).seed_id, run)
        base = {"group": group, "cell": name, "root": root, "run": run, "method": method}
        m = run_method(scenario, method, vehicle, np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key))
        defaults = {k: m.metrics[k] for k in FIELDS[7:]}
        rows.append({**base, "arm": "defaults", "copied": False, **defaults})
        if defaults["reinitialisations"] == 0:  # no divergence: the candidate's run is this run
            rows.append({**base, "arm": CANDIDATE, "copied": True, **defaults})
            continue
        c = run_method(with_second_square(scenario), method, vehicle,
                       np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key))
        rows.append({**base, "arm": CANDIDATE, "copied": False, **{k: c.metrics[k] for k in FIELDS[7:]}})
    return rows


def paired(df):
    import pandas as pd

    df = df.copy()
    df["diverged"] = df["diverged"].astype(str).str.lower().isin(["true", "1", "1.0"])
    return df.pivot_table(index=["group", "cell", "root", "run", "method"], columns="arm",
                          values=["diverged", "final_horizontal_error_m", "reinitialisations", "filter_wall_s"],
                          aggfunc="first").pipe(pd.DataFrame)


def rules(wide) -> None:
    """docs/filters.md 17's four rules (section 18's too: section 10's) on the paired table; the test worlds are the
    groups named J..."""
    group = wide.index.get_level_values("group")
    four_rules(wide, "test worlds (the J... groups)", group.str.startswith("J"), "test", CANDIDATE)


def per_world(df) -> None:
    """Per test world: lost runs of each arm, the largest final error, and issue 24's target on runs 0-9."""
    df = df[df["group"].str.startswith("J")].copy()
    df["diverged"] = df["diverged"].astype(str).str.lower().isin(["true", "1", "1.0"])
    print("\n| world | runs | lost, defaults | lost, candidate | largest final error (m), defaults / candidate | "
          "target on runs 0-9, defaults / candidate |\n|---|---|---|---|---|---|")
    for world, g in sorted(df.groupby("group"), key=lambda t: int(t[0][1:])):
        cells = []
        for arm in ("defaults", CANDIDATE):
            a = g[g["arm"] == arm]
            first = a[a["run"] < 10]
            cells.append((int(a["diverged"].sum()), a["final_horizontal_error_m"].max(),
                          "met" if first["diverged"].sum() <= 1 and first["final_horizontal_error_m"].max() <= 200.0
                          else "missed"))
        print(f"| {world} | {int((g['arm'] == 'defaults').sum())} | {cells[0][0]} | {cells[1][0]} | "
              f"{cells[0][1]:.1f} / {cells[1][1]:.1f} | {cells[0][2]} / {cells[1][2]} |")


def summary(path: str) -> None:
    """docs/filters.md 17's rules, every group's pairs, per method, per test world, and the lost runs."""
    import pandas as pd

    df = pd.concat([pd.read_csv(p) for p in path.split(",")], ignore_index=True)  # CSVs of one test, comma-separated
    wide = paired(df)
    rules(wide)
    print()
    for group in wide.index.get_level_values("group").unique():
        describe_pairs(group, wide[wide.index.get_level_values("group") == group], CANDIDATE)
    for method in wide.index.get_level_values("method").unique():
        describe_pairs(f"  {method}, all groups", wide[wide.index.get_level_values("method") == method], CANDIDATE)
    per_world(df)
    lost = df[df["diverged"].astype(str).str.lower().isin(["true", "1", "1.0"])]
    print("\nlost runs (either arm): group, cell, root, run, method, arm, final error (m)")
    for r in lost.itertuples():
        print(f"  {r.group} {r.cell} {r.root} {r.run} {r.method} {r.arm} {r.final_horizontal_error_m:.1f}")


def _sweeps(args: list) -> list:
    """SWEEP[:RUNS[:METHOD,METHOD]] arguments as (group, path, runs, methods or None)."""
    out = []
    for a in args:
        path, _, rest = a.partition(":")
        runs, _, own = rest.partition(":")
        out.append((path.rsplit("/", 1)[-1].removesuffix(".yaml"), path, int(runs) if runs else 10,
                    own.split(",") if own else None))
    return out


if __name__ == "__main__":
    args = sys.argv[1:]
    if args[:1] == ["--summary"]:
        summary(args[1])
        raise SystemExit(0)
    opts = {}
    if "--distant" in args:
        args.remove("--distant")
        SEARCH_AROUND["value"] = "estimate-then-distant-navigation"
    for flag in ("--roots", "--methods", "--workers"):
        if flag in args:
            i = args.index(flag)
            opts[flag] = args[i + 1]
            del args[i:i + 2]
    if len(args) < 2:
        raise SystemExit(__doc__)
    roots = [int(r) for r in opts["--roots"].split(",")] if "--roots" in opts else None
    methods = opts["--methods"].split(",") if "--methods" in opts else None
    write_rows(args[0], FIELDS, _pair, jobs(_sweeps(args[1:]), roots, methods), int(opts.get("--workers", 2)),
               chunksize=1)
    summary(args[0])
