"""A loose-dvl fit-test candidate against the defaults (docs/filters.md sections 11 and 11.2): the paired test.

The candidates: ``no-fit-test`` (``filter.loose_fix_fit_test: false``, section 11, root seed 4122026 for its
test cells) and ``one-wild-beam`` (``filter.loose_fix_fit_one_wild_beam: true``, section 11.2, root seed 5122026).


Every run's vehicle data and filter seed are those of the defaults' keys; loose-dvl runs once at the
defaults and once with the candidate on the same data and seed, so a pair differs only where the fit
test held a fix back. The test cells (the 7 fault cells of ``configs/realism.yaml`` under the held-out
root seed) and the guards are fixed in section 11. Writes one CSV row per (group, cell, run, arm) and
prints the section's rules.

    .venv/bin/python examples/prototypes/heldout_relief.py .cache/unseen-relief --unseen
    .venv/bin/python examples/prototypes/loose_fit_test.py OUT.csv [--workers 2] [--candidate one-wild-beam]
    .venv/bin/python examples/prototypes/loose_fit_test.py --summary OUT.csv
"""

from __future__ import annotations

import sys

import numpy as np

from global_recovery import distinct_cells
from loose_fix_gate import LATER_NEUTRAL, _t_interval, sign_test_p, write_rows
from tanbench.config import Scenario
from tanbench.methods import get, run_method
from tanbench.runner.seeds import keyed_filter_seed, keyed_vehicle_seed
from tanbench.sweep import load_sweep
from tanbench.simulation import simulate_vehicle

METHOD = "loose-dvl"
# candidate -> (its filter settings, the held-out root seed of its test cells)
CANDIDATES = {"no-fit-test": ({"loose_fix_fit_test": False}, 4122026),
              "one-wild-beam": ({"loose_fix_fit_one_wild_beam": True}, 5122026)}
CANDIDATE = "no-fit-test"
TEST_RUNS = 30
# the realism sweep's fault cells at the recommended settings: (table, the fault's field, its value)
FAULTS = (("depth_bias", "faults.tide_bias_m", 2.0), ("tide", "faults.tide_amplitude_m", 1.5),
          ("current", "faults.current_east_mps", 0.3), ("dropouts", "faults.dropout_rate_per_ping", 0.02),
          ("outliers", "faults.outlier_fraction", 0.05), ("sound_speed", "faults.sound_speed_scale_error", 0.01),
          ("correlated_map_error", "terrain.map_error_correlation_m", 100.0))
GUARDS = {"zhou2017": ("configs/zhou2017.yaml", 50), "ci": ("configs/ci.yaml", 80),
          "monterey": ("configs/monterey.yaml", 20), "realism": ("configs/realism.yaml", 20)}
FIELDS = ["group", "cell", "run", "arm", "diverged", "final_horizontal_error_m", "mean_horizontal_error_m",
          "fixes_accepted", "fixes_rejected", "reinitialisations", "filter_wall_s"]


def as_tested(scenario: Scenario) -> Scenario:
    """The defaults as they were when both candidates were tested: ``loose_fix_fit_one_wild_beam`` off (its
    neutral value; the default since section 11.3), ``loose_reopen_heading: navigation`` (section 14.2) and
    ``loose_reopen_position: prior`` (section 15.1), so the pairs keep their keys and seeds."""
    data = scenario.model_dump(mode="json")
    data["filter"]["loose_fix_fit_one_wild_beam"] = False
    data["filter"]["loose_reopen_heading"] = "navigation"  # neutral; the default since section 14.2
    data["filter"]["loose_reopen_position"] = "prior"  # neutral; the default since section 15.1
    data["filter"].update(LATER_NEUTRAL)  # neutral; the defaults since sections 16.3 and 18.1
    return Scenario(**data)


def with_candidate(scenario: Scenario, candidate: str) -> Scenario:
    data = scenario.model_dump(mode="json")
    data["filter"].update(CANDIDATES[candidate][0])
    return Scenario(**data)


def test_cells() -> list:
    """(name, scenario) of the 7 fault cells, from the realism sweep's own cells."""
    sweep = load_sweep("configs/realism.yaml")
    out = []
    for table, field, value in FAULTS:
        group, name = field.split(".")
        for cell in sweep.cells:
            if table in cell.tables and getattr(getattr(cell.scenario, group), name) == value:
                out.append((table, cell.scenario))
                break
        else:
            raise SystemExit(f"no {table} cell with {field} = {value} in configs/realism.yaml")
    return out


def jobs(candidate: str) -> list:
    seed = CANDIDATES[candidate][1]
    out = [("test", table, as_tested(scenario), seed, r) for table, scenario in test_cells() for r in range(TEST_RUNS)]
    for label, name, scenario, root, runs, methods in distinct_cells(GUARDS):
        if METHOD in methods:
            out += [(label, name, as_tested(scenario), root, r) for r in range(runs)]
    return [job + (candidate,) for job in out]


def _pair(job):
    group, name, scenario, root, run, candidate = job
    vehicle = simulate_vehicle(scenario, keyed_vehicle_seed(root, scenario.pairing_key(), run))
    fseed = keyed_filter_seed(root, scenario.cell_key(), get(METHOD).seed_id, run)
    rows = []
    for arm, sc in (("defaults", scenario), ("candidate", with_candidate(scenario, candidate))):
        m = run_method(sc, METHOD, vehicle, np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key)).metrics
        rows.append({"group": group, "cell": name, "run": run, "arm": arm, **{k: m[k] for k in FIELDS[4:]}})
    return rows


def run(out_csv: str, workers: int, candidate: str = CANDIDATE) -> None:
    write_rows(out_csv, FIELDS, _pair, jobs(candidate), workers, chunksize=2)
    summary(out_csv)


def _compare(g):
    d0, d1 = g[("diverged", "defaults")].astype(bool), g[("diverged", "candidate")].astype(bool)
    b, c = int((d0 & ~d1).sum()), int((~d0 & d1).sum())
    kept = g[~d0 & ~d1]
    diff = (kept[("final_horizontal_error_m", "candidate")] - kept[("final_horizontal_error_m", "defaults")]).to_numpy()
    ci = _t_interval(diff) if diff.size > 1 and diff.std() > 0 else (float(diff.mean()) if diff.size else 0.0,) * 3
    return len(g), int(d0.sum()), int(d1.sum()), b, c, ci, diff.size


def summary(path: str) -> None:
    """Section 11's rules on the CSV of :func:`run`."""
    import pandas as pd

    df = pd.read_csv(path)
    df["diverged"] = df["diverged"].astype(str).str.lower().isin(["true", "1", "1.0"])
    wide = df.pivot_table(index=["group", "cell", "run"], columns="arm",
                          values=["diverged", "final_horizontal_error_m", "fixes_accepted", "filter_wall_s"],
                          aggfunc="first")
    group = wide.index.get_level_values("group")
    sets = {"test cells (realism faults, the candidate's held-out root seed)": group == "test",
            "fault-free guards (zhou2017, ci, monterey)": group.isin(["zhou2017", "ci", "monterey"]),
            "unseen worlds J25-J40": group == "unseen", "realism guard (its own seed)": group == "realism",
            "monterey": group == "monterey"}
    out = {}
    for label, mask in sets.items():
        g = wide[mask]
        n, l0, l1, b, c, ci, kept = out[label] = _compare(g)
        wall = g[("filter_wall_s", "candidate")].sum() / g[("filter_wall_s", "defaults")].sum()
        print(f"{label}: {n} pairs; lost at the defaults {l0}, with the candidate {l1}; discordant b = {b} "
              f"(defaults only), c = {c} (candidate only); one-sided sign test p = {sign_test_p(b, c):.4f}; final "
              f"error candidate - defaults {ci[0]:+.3f} m [{ci[1]:+.3f}, {ci[2]:+.3f}] ({kept} kept in both); "
              f"fixes accepted {int(g[('fixes_accepted', 'defaults')].sum())} / "
              f"{int(g[('fixes_accepted', 'candidate')].sum())}; filter time x{wall:.2f}")
    te, ff, un, re, mo = (out[k] for k in sets)
    print(f"R1 (test cells, lost runs, p < 0.05): {'holds' if sign_test_p(te[3], te[4]) < 0.05 else 'fails'}")
    ff_c, ff_b = ff[4] + un[4], ff[3] + un[3]
    print(f"R2 (guards: c <= b, fault-free with J25-J40 ({ff_b}, {ff_c}) and realism ({re[3]}, {re[4]}) each): "
          f"{'holds' if ff_c <= ff_b and re[4] <= re[3] else 'fails'}")
    print(f"R3 (accuracy upper ends: fault-free <= +0.2 m, J25-J40 <= +1.0 m, test cells <= +1.0 m, realism <= +1.0 m): "
          f"{'holds' if ff[5][2] <= 0.2 and un[5][2] <= 1.0 and te[5][2] <= 1.0 and re[5][2] <= 1.0 else 'fails'}")
    print(f"R4 (Monterey: 0 lost with the candidate): {'holds' if mo[2] == 0 else 'fails'}")
    print("\nper test cell (lost of 30 / mean final error, m):")
    t = df[df["group"] == "test"]
    print("| cell | defaults | candidate |\n|---|---|---|")
    for cell, g in t.groupby("cell", sort=False):
        cells = [f"{int(s['diverged'].sum())} / {s['final_horizontal_error_m'].mean():.2f}"
                 for s in (g[g["arm"] == a] for a in ("defaults", "candidate"))]
        print(f"| {cell} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    args = sys.argv[1:]
    if args[:1] == ["--summary"]:
        summary(args[1])
    elif len(args) in (1, 3, 5):
        run(args[0], int(args[args.index("--workers") + 1]) if "--workers" in args else 2,
            args[args.index("--candidate") + 1] if "--candidate" in args else CANDIDATE)
    else:
        raise SystemExit(__doc__)
