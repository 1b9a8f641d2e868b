"""``filter.recovery: global`` against the defaults (docs/filters.md section 10): the paired test.

Every run's vehicle data and filter seed are those of the defaults' keys; each tight method of a
cell runs once at the defaults and once with ``recovery: global`` on the same data and seed, so a
pair differs only where a divergence fired (the search runs only then). The test worlds J25-J40
(``heldout_relief.py OUT --unseen``) and the guards (every distinct cell of five committed sweeps)
are fixed in section 10. Writes one CSV row per (group, cell, run, method, arm) and prints the
section's rules.

    .venv/bin/python examples/prototypes/heldout_relief.py .cache/unseen-relief --unseen
    .venv/bin/python examples/prototypes/global_recovery.py OUT.csv [--workers 2]
    .venv/bin/python examples/prototypes/global_recovery.py --summary OUT.csv
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from loose_fix_gate import _t_interval, sign_test_p, write_rows
from tanbench.config import Scenario
from tanbench.methods import get, run_method
from tanbench.runner.seeds import keyed_filter_seed, keyed_vehicle_seed
from tanbench.simulation import simulate_vehicle
from tanbench.sweep import load_sweep

UNSEEN_DIR = Path(".cache/unseen-relief")
UNSEEN_WORLDS = [f"J{k}" for k in range(25, 41)]
GUARDS = {  # group -> (sweep, runs per distinct cell)
    "zhou2017": ("configs/zhou2017.yaml", 50), "ci": ("configs/ci.yaml", 80), "realism": ("configs/realism.yaml", 20),
    "monterey": ("configs/monterey.yaml", 20), "multibeam": ("configs/multibeam.yaml", 10),
}
TIGHT = ("tight-dvl", "tight-sbe", "tight-mbe")
FIELDS = ["group", "cell", "run", "method", "arm", "diverged", "final_horizontal_error_m", "mean_horizontal_error_m",
          "reinitialisations", "recoveries", "filter_wall_s"]


def with_global(scenario: Scenario) -> Scenario:
    data = scenario.model_dump(mode="json")
    data["filter"]["recovery"] = "global"
    return Scenario(**data)


def distinct_cells(guards: dict):
    """(label, name, scenario, root seed, runs, the sweep's methods) of every distinct cell of the unseen worlds
    J25-J40 (10 runs each, label "unseen") and of the ``guards`` (group -> (sweep, runs per cell))."""
    sweeps = [(w, str(UNSEEN_DIR / f"{w}.yaml"), 10) for w in UNSEEN_WORLDS]
    sweeps += [(group, path, runs) for group, (path, runs) in guards.items()]
    for group, path, runs in sweeps:
        sweep = load_sweep(path)
        seen = set()
        for cell in sweep.cells:
            if cell.cell_id in seen:
                continue
            seen.add(cell.cell_id)
            label = "unseen" if group.startswith("J") else group
            name = group if label == "unseen" else f"{group}:{cell.cell_id[:8]}"
            yield label, name, cell.scenario, sweep.spec.seed, runs, sweep.spec.methods


def jobs() -> list:
    out = []
    for label, name, scenario, seed, runs, methods in distinct_cells(GUARDS):
        tight = [m for m in methods if m in TIGHT]
        out += [(label, name, scenario, seed, r, tight) for r in range(runs)]
    return out


def _pair(job):
    group, name, scenario, root, run, methods = job
    vehicle = simulate_vehicle(scenario, keyed_vehicle_seed(root, scenario.pairing_key(), run))
    rows = []
    for method in methods:
        fseed = keyed_filter_seed(root, scenario.cell_key(), get(method).seed_id, run)
        for arm, sc in (("defaults", scenario), ("global", with_global(scenario))):
            m = run_method(sc, method, vehicle, np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key)).metrics
            rows.append({"group": group, "cell": name, "run": run, "method": method, "arm": arm,
                         **{k: m[k] for k in FIELDS[5:]}})
    return rows


def run(out_csv: str, workers: int) -> None:
    write_rows(out_csv, FIELDS, _pair, jobs(), workers, chunksize=2)
    summary(out_csv)


def describe_pairs(label: str, g, arm: str) -> tuple:
    """Print the paired outcome of ``g`` (a wide table: metric, arm columns), the candidate arm named ``arm``;
    returns (pairs, lost at the defaults, lost with ``arm``, b, c, (mean, low, high) of the final-error difference
    over the pairs kept in both)."""
    d0, d1 = g[("diverged", "defaults")].astype(bool), g[("diverged", arm)].astype(bool)
    b, c = int((d0 & ~d1).sum()), int((~d0 & d1).sum())
    kept = g[~d0 & ~d1]
    diff = (kept[("final_horizontal_error_m", arm)] - kept[("final_horizontal_error_m", "defaults")]).to_numpy()
    ci = _t_interval(diff) if diff.size > 1 and diff.std() > 0 else (float(diff.mean()) if diff.size else 0.0,) * 3
    wall = g[("filter_wall_s", arm)].sum() / g[("filter_wall_s", "defaults")].sum()
    print(f"{label}: {len(g)} pairs; lost at the defaults {int(d0.sum())}, with {arm} {int(d1.sum())}; "
          f"discordant b = {b} (defaults only), c = {c} ({arm} only); one-sided sign test p = "
          f"{sign_test_p(b, c):.4f}; final error {arm} - defaults {ci[0]:+.3f} m [{ci[1]:+.3f}, {ci[2]:+.3f}] "
          f"({diff.size} kept in both); reinitialisations {int(g[('reinitialisations', 'defaults')].sum())} / "
          f"{int(g[('reinitialisations', arm)].sum())}; filter time x{wall:.2f}")
    return len(g), int(d0.sum()), int(d1.sum()), b, c, ci


def four_rules(wide, test_label: str, test_mask, test_name: str, arm: str) -> None:
    """Section 10's four rules (sections 17 and 18 use them unchanged) on the wide paired table: the test worlds
    (``test_mask``, printed as ``test_label`` and, in the rules, ``test_name``), the fault-free guards, realism and
    Monterey, the candidate arm named ``arm``."""
    group = wide.index.get_level_values("group")
    sets = {test_label: test_mask,
            "fault-free guards (zhou2017, ci, monterey, multibeam)": group.isin(["zhou2017", "ci", "monterey",
                                                                                  "multibeam"]),
            "realism (world faults)": group == "realism", "monterey": group == "monterey"}
    un, ff, re, mo = (describe_pairs(label, wide[mask], arm) for label, mask in sets.items())
    print(f"R1 ({test_name} worlds, lost runs, p < 0.05): "
          f"{'holds' if sign_test_p(un[3], un[4]) < 0.05 else 'fails'}")
    r2 = ff[4] <= ff[3] and re[4] <= re[3]
    print(f"R2 (guards: c <= b, fault-free and realism each): {'holds' if r2 else 'fails'}")
    print(f"R3 (accuracy upper bounds: fault-free <= +0.2 m, realism <= +1.0 m, {test_name} <= +1.0 m): "
          f"{'holds' if ff[5][2] <= 0.2 and re[5][2] <= 1.0 and un[5][2] <= 1.0 else 'fails'}")
    print(f"R4 (Monterey: 0 lost with {arm}): {'holds' if mo[2] == 0 else 'fails'}")


def summary(path: str) -> None:
    """Section 10's rules on the CSV of :func:`run`."""
    import pandas as pd

    df = pd.read_csv(path)
    df["diverged"] = df["diverged"].astype(str).str.lower().isin(["true", "1", "1.0"])
    wide = df.pivot_table(index=["group", "cell", "run", "method"], columns="arm",
                          values=["diverged", "final_horizontal_error_m", "reinitialisations", "filter_wall_s"],
                          aggfunc="first")
    group = wide.index.get_level_values("group")
    four_rules(wide, "unseen worlds J25-J40", group == "unseen", "unseen", "global")
    print("\nissue 24's real-relief target on the unseen worlds (at most tight-dvl 0, tight-sbe 1 lost of 10; "
          "no final error above 200 m), lost / largest final error:")
    u = df[df["group"] == "unseen"]
    print("| world | " + " | ".join(f"{m} {a}" for m in ("tight-dvl", "tight-sbe") for a in ("defaults", "global"))
          + " |\n|---|---|---|---|---|")
    for world, g in u.groupby("cell", sort=False):
        cells = []
        for m in ("tight-dvl", "tight-sbe"):
            for a in ("defaults", "global"):
                s = g[(g["method"] == m) & (g["arm"] == a)]
                cells.append(f"{int(s['diverged'].sum())} ({s['final_horizontal_error_m'].max():.1f} m)")
        print(f"| {world} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    args = sys.argv[1:]
    if args[:1] == ["--summary"]:
        summary(args[1])
    elif len(args) in (1, 3):
        run(args[0], int(args[args.index("--workers") + 1]) if "--workers" in args else 2)
    else:
        raise SystemExit(__doc__)
