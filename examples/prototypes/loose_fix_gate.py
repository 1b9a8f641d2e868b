"""loose-dvl's lost runs and the fix-prior gate (docs/filters.md section 9): the paired ablation.

Each run's vehicle data and filter seed are those of the cell without the gate
(``filter.loose_fix_prior_gate: null``, the defaults when the ablation was fixed); loose-dvl runs
once without and once with the gate at 13.8, on the same data and seed. The arms are named
"defaults" (no gate) and "gate" as in the section. Writes one CSV row per (cell, run, arm) and prints the section's statistics.

    .venv/bin/python examples/prototypes/loose_fix_gate.py OUT.csv [--workers 2]
    .venv/bin/python examples/prototypes/loose_fix_gate.py --summary OUT.csv
    .venv/bin/python examples/prototypes/loose_fix_gate.py --diagnose SWEEP.yaml RUN [CELL [GATE]]
    .venv/bin/python examples/prototypes/loose_fix_gate.py --paired SWEEP.yaml RUNS
    .venv/bin/python examples/prototypes/loose_fix_gate.py --fallback OUT.csv   # section 9.1's test
    .venv/bin/python examples/prototypes/loose_fix_gate.py --gate-again OUT.csv  # section 12's test
    .venv/bin/python examples/prototypes/loose_fix_gate.py --first-fix OUT.csv   # section 13's test
    .venv/bin/python examples/prototypes/loose_fix_gate.py --reopen OUT.csv      # section 14's test
    .venv/bin/python examples/prototypes/loose_fix_gate.py --reopen-realism OUT.csv  # section 14.2's
    .venv/bin/python examples/prototypes/loose_fix_gate.py --reopen-fix OUT.csv  # section 15's

``--paired`` runs every loose-dvl run of a sweep's distinct cells with the gate on and off on the
same vehicle data and filter seed, the seeds of each cell with the gate at 13.8 in its key (the
checks of section 9 made while 13.8 was the default), and counts the runs lost in one arm only.

``--diagnose`` runs loose-dvl on one run of a sweep's cell with a copy of the loop that logs
every fix attempt (the PF's posterior, the window prior, the terrain-only fix and its chi-square
against the prior, the KF's innovation and correction).
"""

from __future__ import annotations

import csv
import inspect
import math
import sys
import textwrap
from collections import namedtuple
from multiprocessing import Pool

import numpy as np

from tanbench.config import Scenario
from tanbench.methods import get, run_method
from tanbench.runner.seeds import keyed_filter_seed, keyed_vehicle_seed
from tanbench.simulation import simulate_vehicle
from tanbench.sweep import load_sweep

ROOT = 20261203
GATE = 13.8
QUICK = {"terrain": {"kind": "synthetic", "seed": 1}, "noise_m": 1.0, "sampling_time_s": 1}
CELLS = {  # name -> (scenario, root seed, runs)
    "A10-2000": (dict(QUICK, area="A", map_resolution_m=10, particles=2000), ROOT, 300),
    "A10-1000": (dict(QUICK, area="A", map_resolution_m=10, particles=1000), ROOT, 200),
    "A20-1000": (dict(QUICK, area="A", map_resolution_m=20, particles=1000), ROOT, 200),
    "A30-3000": (dict(QUICK, area="A", map_resolution_m=30, particles=3000), ROOT, 200),
    "B10-2000": (dict(QUICK, area="B", map_resolution_m=10, particles=2000), ROOT, 100),
}
MONTEREY = "configs/monterey.yaml"
FIELDS = ["cell", "run", "arm", "diverged", "final_horizontal_error_m", "mean_horizontal_error_m",
          "fixes_accepted", "fixes_rejected", "nees_mean_whole_run"]


def cells() -> dict:
    out = {name: (with_gate(Scenario(**spec), None), root, runs) for name, (spec, root, runs) in CELLS.items()}
    sweep = load_sweep(MONTEREY)
    for cell in sweep.cells:
        out[f"Monterey-{cell.scenario.map_resolution_m:g}"] = (with_gate(cell.scenario, None), sweep.spec.seed, 20)
    return out


def with_gate(scenario: Scenario, gate: float | None, fallback: str = "refuse") -> Scenario:
    data = scenario.model_dump(mode="json")
    data["filter"]["loose_fix_prior_gate"] = gate
    data["filter"]["loose_fix_prior_fallback"] = fallback
    return Scenario(**data)


def _pair(job):
    name, scenario, root, run = job[:4]
    fallback = job[4] if len(job) > 4 else "refuse"
    vehicle = simulate_vehicle(scenario, keyed_vehicle_seed(root, scenario.pairing_key(), run))
    fseed = keyed_filter_seed(root, scenario.cell_key(), get("loose-dvl").seed_id, run)
    rows = []
    if fallback in OPTION_CANDIDATES:  # sections 13 and 14: an option's other value
        arm, options = OPTION_CANDIDATES[fallback]
        data = scenario.model_dump(mode="json")
        candidate = (arm, Scenario(**{**data, "filter": {**data["filter"], **options}}))
    else:
        candidate = ("gate", with_gate(scenario, GATE, fallback))
    for arm, sc in (("defaults", scenario), candidate):
        m = run_method(sc, "loose-dvl", vehicle, np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key)).metrics
        rows.append({"cell": name, "run": run, "arm": arm, **{k: m[k] for k in FIELDS[3:]}})
    return rows


def write_rows(out_csv: str, fields: list, worker, jobs: list, workers: int, chunksize: int = 4) -> None:
    """Run ``worker`` over ``jobs`` in a pool and write the rows each returns to ``out_csv``, with progress."""
    with open(out_csv, "w", newline="") as fh, Pool(workers) as pool:
        writer = csv.DictWriter(fh, fields)
        writer.writeheader()
        for i, rows in enumerate(pool.imap_unordered(worker, jobs, chunksize=chunksize)):
            writer.writerows(rows)
            if i % 100 == 0:
                fh.flush()
                print(f"{i + 1} of {len(jobs)} jobs", flush=True)


def ablation(out_csv: str, workers: int) -> None:
    jobs = [(name, sc, root, r) for name, (sc, root, runs) in cells().items() for r in range(runs)]
    write_rows(out_csv, FIELDS, _pair, jobs, workers)
    summary(out_csv)


FALLBACK_SWEEPS = {"zhou2017": ("configs/zhou2017.yaml", 50), "ci": ("configs/ci.yaml", 80),
                   "realism": ("configs/realism.yaml", 20)}


# section 12: section 9's synthetic cells under a root seed of their own (Monterey and the sweeps keep theirs)
GATE_AGAIN_ROOT = 6122026
# section 13: the first fix from the cloud's posterior (filter.loose_first_fix: posterior), its own root seed
FIRST_FIX = "first-fix-posterior"
FIRST_FIX_ROOT = 7122026
# section 14: a reopened KF takes the cloud's heading (filter.loose_reopen_heading: cloud), its own root seed
REOPEN = "reopen-heading-cloud"
REOPEN_ROOT = 8122026
# section 15: a fix the reopened KF still rejects sets its position (filter.loose_reopen_position: fix), against
# today's defaults; its own root seeds for section 9's cells and for realism's cells (runs 0-79)
REOPEN_FIX = "reopen-position-fix"
REOPEN_FIX_ROOT = 9122026
REOPEN_FIX_REALISM = (9122027, range(80))
# section 16.2: fixes whose errors are correlated over 40 s (filter.loose_fix_correlation_s: 40), against today's
# defaults; its own root seeds for section 9's cells and for realism's cells (runs 0-79)
FIX_CORRELATION = "fix-correlation-40"
FIX_CORRELATION_ROOT = 10122026
FIX_CORRELATION_REALISM = (10122027, range(80))
FIX_CORRELATION_ARM = "fix-correlation"
# candidate -> (its arm's name in the CSV, its filter settings)
OPTION_CANDIDATES = {FIRST_FIX: ("first-fix", {"loose_first_fix": "posterior"}),
                     REOPEN: ("reopen", {"loose_reopen_heading": "cloud"}),
                     REOPEN_FIX: ("reopen-fix", {"loose_reopen_position": "fix"}),
                     FIX_CORRELATION: (FIX_CORRELATION_ARM, {"loose_fix_correlation_s": 40.0})}


# the neutral values of the defaults adopted after these tests ran (docs/filters.md 16.4 and 18.2): a cell's key holds
# every filter option, so each test's defaults pin them to keep the keys, and so the seeds, it ran on
LATER_NEUTRAL = {"loose_fix_correlation_s": 0.0, "recovery_search_around": "estimate"}


def _pinned(scenario: Scenario, **options) -> Scenario:
    data = scenario.model_dump(mode="json")
    return Scenario(**{**data, "filter": {**data["filter"], **options}})


def as_run_on_4_december(scenario: Scenario) -> Scenario:
    """The defaults sections 12-14 ran against: ``loose_reopen_heading: navigation`` (its neutral value; the default
    since section 14.2) and ``loose_reopen_position: prior`` (neutral; the default since section 15.2), so the pairs
    keep their keys and seeds."""
    return _pinned(scenario, loose_reopen_heading="navigation", loose_reopen_position="prior", **LATER_NEUTRAL)


def as_run_for_section_15(scenario: Scenario) -> Scenario:
    """The defaults section 15 ran against (4 December, 18:00 UTC): ``loose_reopen_position: prior`` (neutral; the
    default since section 15.2), so its pairs keep their keys and seeds."""
    return _pinned(scenario, loose_reopen_position="prior", **LATER_NEUTRAL)


def as_run_for_section_16(scenario: Scenario) -> Scenario:
    """The defaults section 16.2 ran against (4 December, fourteenth session): ``loose_fix_correlation_s: 0``
    (neutral; the default since section 16.3), so its pairs keep their keys and seeds."""
    return _pinned(scenario, **LATER_NEUTRAL)


def sweep_jobs(label: str, path: str, root: int | None, runs, defaults, fallback: str) -> list:
    """Every distinct cell of the sweep ``path`` at the ``defaults``, runs ``runs`` under ``root`` (None: the sweep's
    own seed), named ``label:`` and the cell key's head."""
    sweep = load_sweep(path)
    root = sweep.spec.seed if root is None else root
    seen, jobs = set(), []
    for cell in sweep.cells:
        if cell.cell_id not in seen:
            seen.add(cell.cell_id)
            sc = defaults(cell.scenario)
            jobs += [(f"{label}:{sc.cell_key()[:8]}", sc, root, r, fallback) for r in runs]
    return jobs


def fallback_jobs(fallback: str = "posterior", root: int | None = None, defaults=as_run_on_4_december,
                  realism: tuple | None = None) -> list:
    """Section 9.1's design: section 9's cells, then every distinct cell of three committed sweeps with
    their own seeds (the defaults' keys), each run at the ``defaults`` and with the gate and its ``fallback``
    (section 12: ``refuse``, section 9's cells under ``root``). ``realism`` = (root seed, runs): realism's cells
    run under that seed and those runs instead of their own seed's first 20 (section 15)."""
    jobs = [(name, defaults(sc), root if root is not None and not name.startswith("Monterey") else cell_root,
             r, fallback) for name, (sc, cell_root, runs) in cells().items() for r in range(runs)]
    for label, (path, runs) in FALLBACK_SWEEPS.items():
        sweep_root, run_range = realism if label == "realism" and realism is not None else (None, range(runs))
        jobs += sweep_jobs(label, path, sweep_root, run_range, defaults, fallback)
    return jobs


# section 14.2: realism's distinct cells again, runs 20-99 (runs 0-19 were section 14.1's), its own root seed
REALISM_MORE = range(20, 100)


def reopen_realism_jobs() -> list:
    return sweep_jobs("realism", FALLBACK_SWEEPS["realism"][0], None, REALISM_MORE, as_run_on_4_december, REOPEN)


def reopen_realism(out_csv: str, workers: int) -> None:
    write_rows(out_csv, FIELDS, _pair, reopen_realism_jobs(), workers)
    reopen_realism_summary(out_csv)


def reopen_realism_summary(path: str) -> None:
    """Section 14.2's rule on the CSV of :func:`reopen_realism`."""
    import pandas as pd

    df = pd.read_csv(path)
    df["diverged"] = df["diverged"].astype(str).str.lower().isin(["true", "1", "1.0"])
    g = df.pivot_table(index=["cell", "run"], columns="arm", values=["diverged", "final_horizontal_error_m"],
                       aggfunc="first")
    d0, d1 = g[("diverged", "defaults")].astype(bool), g[("diverged", "reopen")].astype(bool)
    b, c = int((d0 & ~d1).sum()), int((~d0 & d1).sum())
    kept = g[~d0 & ~d1]
    diff = (kept[("final_horizontal_error_m", "reopen")] - kept[("final_horizontal_error_m", "defaults")]).to_numpy()
    mean, lo, hi = _t_interval(diff)
    print(f"realism runs 20-99: {len(g)} pairs; lost at the defaults {int(d0.sum())}, with the candidate {int(d1.sum())}; "
          f"b = {b}, c = {c} (one-sided sign test p = {sign_test_p(b, c):.4f}); final error candidate - defaults "
          f"{mean:+.3f} m [{lo:+.3f}, {hi:+.3f}] over {diff.size} kept pairs (sd {diff.std(ddof=1):.2f} m)")
    print(f"(a) upper end <= +1.0 m: {'holds' if hi <= 1.0 else 'fails'}; (b) c <= b: {'holds' if c <= b else 'fails'}")


# the paired tests of sections 9.1, 12, 13, 14.1 and 15: command-line flag -> the candidate as _pair reads it, the
# root seed of section 9's cells (None: section 9's own), the candidate's name in the printout, the defaults it ran
# against and realism's (root seed, runs) when not its own seed's first 20
PairedTest = namedtuple("PairedTest", "candidate root name defaults realism loss_guard",
                        defaults=(as_run_on_4_december, None, False))
PAIRED_TESTS = {"--fallback": PairedTest("posterior", None, "fallback"),
                "--gate-again": PairedTest("refuse", GATE_AGAIN_ROOT, "gate"),
                "--first-fix": PairedTest(FIRST_FIX, FIRST_FIX_ROOT, "first-fix"),
                "--reopen": PairedTest(REOPEN, REOPEN_ROOT, "reopen"),
                "--reopen-fix": PairedTest(REOPEN_FIX, REOPEN_FIX_ROOT, "reopen-fix", as_run_for_section_15,
                                           REOPEN_FIX_REALISM),
                "--fix-correlation": PairedTest(FIX_CORRELATION, FIX_CORRELATION_ROOT, FIX_CORRELATION_ARM,
                                                as_run_for_section_16, FIX_CORRELATION_REALISM, loss_guard=True)}


def fallback_ablation(out_csv: str, workers: int, test: str = "--fallback") -> None:
    t = PAIRED_TESTS[test]
    write_rows(out_csv, FIELDS, _pair, fallback_jobs(t.candidate, t.root, t.defaults, t.realism), workers)
    fallback_summary(out_csv, t.name, t.loss_guard)


def _t_interval(diff):
    from scipy import stats

    mean, sem = diff.mean(), diff.std(ddof=1) / math.sqrt(diff.size)
    t = stats.t.ppf(0.975, diff.size - 1)
    return mean, mean - t * sem, mean + t * sem


def fallback_summary(path: str, arm: str = "fallback", loss_guard: bool = False) -> None:
    """Section 9.1's four rules (section 12's too) on the CSV of :func:`fallback_ablation`; ``arm`` names the
    candidate in the printout; ``loss_guard``: also rule 1 as a guard (c <= b, section 16.2's amendment); with the
    runs' NEES in the CSV, section 16.2's fifth rule (:func:`consistency_rule`)."""
    import pandas as pd

    df = pd.read_csv(path)
    df["diverged"] = df["diverged"].astype(str).str.lower().isin(["true", "1", "1.0"])
    wide = df.pivot_table(index=["cell", "run"], columns="arm", values=["diverged", "final_horizontal_error_m"],
                          aggfunc="first")
    cell = wide.index.get_level_values("cell")
    groups = {"fault-free (section 9 cells, zhou2017, ci)": ~cell.str.startswith(("Monterey", "realism:")),
              "realism": cell.str.startswith("realism:"), "Monterey": cell.str.startswith("Monterey")}
    out = {}
    for label, mask in groups.items():
        g = wide[mask]
        col = "gate" if arm == "fallback" else arm  # the CSV's candidate arm (9.1's fallback is a gate's)
        d0, d1 = g[("diverged", "defaults")].astype(bool), g[("diverged", col)].astype(bool)
        b, c = int((d0 & ~d1).sum()), int((~d0 & d1).sum())
        kept = g[~d0 & ~d1]
        diff = (kept[("final_horizontal_error_m", col)] - kept[("final_horizontal_error_m", "defaults")]).to_numpy()
        out[label] = (len(g), int(d0.sum()), int(d1.sum()), b, c, _t_interval(diff) if diff.size > 1 else None)
        m = out[label][5]
        print(f"{label}: {len(g)} pairs; lost at the defaults {int(d0.sum())}, with the {arm} {int(d1.sum())}; "
              f"discordant b = {b} (defaults only), c = {c} ({arm} only); one-sided sign test p = "
              f"{sign_test_p(b, c):.4f}; final error {arm} - defaults "
              + (f"{m[0]:+.3f} m [{m[1]:+.3f}, {m[2]:+.3f}]" if m else "n/a"))
    ff, re, mo = (out[k] for k in groups)
    print(f"R1 (fault-free lost runs, p < 0.05): {'holds' if sign_test_p(ff[3], ff[4]) < 0.05 else 'fails'}")
    if loss_guard:  # section 16.2's rule 1, amended before its runs: a guard, as rule 2
        print(f"R1 amended (section 16.2: fault-free c <= b): {'holds' if ff[4] <= ff[3] else 'fails'}")
    print(f"R2 (realism: c <= b): {'holds' if re[4] <= re[3] else 'fails'}")
    print(f"R3 (accuracy: fault-free upper <= +0.2 m, realism upper <= +1.0 m): "
          f"{'holds' if ff[5][2] <= 0.2 and re[5][2] <= 1.0 else 'fails'}")
    print(f"R4 (Monterey: 0 lost with the {arm}): {'holds' if mo[2] == 0 else 'fails'}")
    if "nees_mean_whole_run" in df.columns:
        consistency_rule(df, arm)


def consistency_rule(df, arm: str) -> None:
    """Section 16.2's fifth rule: per synthetic cell of section 9 the verdict's ANEES (the mean over its runs of each
    run's whole-run mean NEES, lost runs included) in each arm, against the band for that many runs
    (docs/model.md 9.2). (a) every cell above its band at the defaults has a lower ANEES with the candidate; (b) no
    cell at or below the band's top at the defaults is above it with the candidate; (c) the candidate's ANEES is at
    least 1.0 in every cell."""
    from tanbench.metrics.consistency import mc_bounds

    ok_a = ok_b = ok_c = True
    for name in CELLS:
        g = df[df["cell"] == name]
        n = int((g["arm"] == "defaults").sum())
        lo, hi = mc_bounds(n)
        a0 = g.loc[g["arm"] == "defaults", "nees_mean_whole_run"].astype(float).mean()
        a1 = g.loc[g["arm"] == arm, "nees_mean_whole_run"].astype(float).mean()
        ok_a &= not (a0 > hi) or a1 < a0
        ok_b &= a0 > hi or not a1 > hi
        ok_c &= a1 >= 1.0
        print(f"{name}: {n} runs, band [{lo:.2f}, {hi:.2f}]; ANEES defaults {a0:.2f}, {arm} {a1:.2f}")
    print(f"R5 (consistency: (a) {'holds' if ok_a else 'fails'}, (b) {'holds' if ok_b else 'fails'}, "
          f"(c) {'holds' if ok_c else 'fails'}): {'holds' if ok_a and ok_b and ok_c else 'fails'}")


def sign_test_p(b: int, c: int) -> float:
    """One-sided exact binomial test: P(X <= c) for X ~ Bin(b + c, 1/2)."""
    n = b + c
    return sum(math.comb(n, i) for i in range(c + 1)) / 2.0 ** n if n else 1.0


def summary(path: str) -> None:
    import pandas as pd
    from scipy import stats

    df = pd.read_csv(path)
    df["diverged"] = df["diverged"].astype(str).str.lower().isin(["true", "1", "1.0"])
    wide = df.pivot_table(index=["cell", "run"], columns="arm",
                          values=["diverged", "final_horizontal_error_m", "mean_horizontal_error_m",
                                  "fixes_accepted", "fixes_rejected"], aggfunc="first")
    print("| cell | pairs | lost: defaults | lost: gate | mean final error, both kept: defaults / gate (m) "
          "| fixes accepted / rejected: defaults | gate |")
    print("|---|---|---|---|---|---|---|")
    for name, g in wide.groupby(level="cell", sort=False):
        kept = g[~g[("diverged", "defaults")].astype(bool) & ~g[("diverged", "gate")].astype(bool)]
        print(f"| {name} | {len(g)} | {int(g[('diverged', 'defaults')].sum())} | {int(g[('diverged', 'gate')].sum())} "
              f"| {kept[('final_horizontal_error_m', 'defaults')].mean():.2f} / "
              f"{kept[('final_horizontal_error_m', 'gate')].mean():.2f} "
              f"| {g[('fixes_accepted', 'defaults')].mean():.1f} / {g[('fixes_rejected', 'defaults')].mean():.1f} "
              f"| {g[('fixes_accepted', 'gate')].mean():.1f} / {g[('fixes_rejected', 'gate')].mean():.1f} |")
    synth = wide[~wide.index.get_level_values("cell").str.startswith("Monterey")]
    d0 = synth[("diverged", "defaults")].astype(bool)
    d1 = synth[("diverged", "gate")].astype(bool)
    b, c = int((d0 & ~d1).sum()), int((~d0 & d1).sum())
    p = sign_test_p(b, c)
    verdict1 = "inconclusive (defaults lost fewer than 5)" if d0.sum() < 5 else ("holds" if p < 0.05 else "fails")
    print(f"\nrule 1 (synthetic, {len(synth)} pairs): lost at the defaults {int(d0.sum())}, with the gate {int(d1.sum())}; "
          f"discordant b = {b} (defaults only), c = {c} (gate only); one-sided sign test p = {p:.4f}: {verdict1}")
    kept = synth[~d0 & ~d1]
    diff = (kept[("final_horizontal_error_m", "gate")] - kept[("final_horizontal_error_m", "defaults")]).to_numpy()
    mean, sem = diff.mean(), diff.std(ddof=1) / math.sqrt(diff.size)
    t = stats.t.ppf(0.975, diff.size - 1)
    print(f"rule 2 ({diff.size} pairs kept in both): final error gate - defaults {mean:+.3f} m "
          f"[{mean - t * sem:+.3f}, {mean + t * sem:+.3f}]: {'holds' if mean + t * sem <= 0.2 else 'fails'} (upper <= +0.2 m)")
    mont = wide[wide.index.get_level_values("cell").str.startswith("Monterey")]
    lost = int(mont[("diverged", "gate")].astype(bool).sum())
    print(f"rule 3 (Monterey, {len(mont)} runs): lost with the gate {lost}: {'holds' if lost == 0 else 'fails'}")


def diagnose(sweep_path: str, run: int, cell_index: int = 0, gate: str = "none") -> None:
    """``gate``: "none" (the seeds and settings without the gate), a chi-square value (the same
    seeds, with that gate), or "sweep" (the sweep's own settings and seeds)."""
    import tanbench.filters.loose_turned as LT
    import tanbench.methods.loose as ML
    from tanbench.navigation.eskf import fix_prior_chi2

    sweep = load_sweep(sweep_path)
    sc = sweep.cells[cell_index].scenario
    if gate != "sweep":  # the run as stored before the gate's default (its key), or with a gate
        sc = with_gate(sc, None)
    vehicle = simulate_vehicle(sc, keyed_vehicle_seed(sweep.spec.seed, sc.pairing_key(), run))
    fseed = keyed_filter_seed(sweep.spec.seed, sc.cell_key(), get("loose-dvl").seed_id, run)
    if gate not in ("sweep", "none"):
        sc = with_gate(sc, float(gate))
    log = []
    src = textwrap.dedent(inspect.getsource(LT.loose_turned_loop.py_func)).replace("@nb.njit(cache=True)\n", "")
    at = "            usable = shape_ok and terrain_only_fix(mean, cov, m_prior, p_prior, kf.fix_max_std, zt, r)\n"
    assert at in src, "the loop changed: update --diagnose"
    src = src.replace(at, at + "            LOG.append([k, usable, mean[0], mean[1], math.sqrt(cov[0, 0] + cov[1, 1]), "
                                "m_prior[0], m_prior[1], math.sqrt(p_prior[0, 0] + p_prior[1, 1]), zt[0], zt[1], "
                                "math.sqrt(r[0, 0] + r[1, 1]), FIXCHI(zt, r, m_prior, p_prior), nav[E, 0], nav[N, 0], "
                                "nav[YAW, 0], math.sqrt(p_kf[EPSI, EPSI]), p_kf[EE, EPSI], p_kf[EN, EPSI]])\n")
    namespace = dict(vars(LT), LOG=log, FIXCHI=fix_prior_chi2)
    exec(compile(src, "loose_turned_loop (diagnostic copy)", "exec"), namespace)
    saved = ML.loose_turned_loop
    ML.loose_turned_loop = namespace["loose_turned_loop"]
    try:
        result = run_method(sc, "loose-dvl", vehicle, fseed)
    finally:
        ML.loose_turned_loop = saved
    truth = vehicle.truth
    upd_t = np.asarray(result.series["t"])
    te = np.interp(upd_t, truth.t, truth.pos[:, 0])
    tn = np.interp(upd_t, truth.t, truth.pos[:, 1])
    tyaw = np.interp(upd_t, truth.t, truth.yaw)  # continuous (Eq. 5: 0 north, +pi/2 west), as the filters' yaw
    m = result.metrics
    print(f"final error {m['final_horizontal_error_m']:.1f} m, fixes accepted {m['fixes_accepted']}, "
          f"rejected {m['fixes_rejected']}")
    print("  t  | PF error, std | prior std | fix: off the PF, std | chi2 vs prior | KF error, heading error (deg), "
          "its std (deg), P(e, psi), P(n, psi)")
    for k, usable, pe, pn, ps, _, _, qs, ze, zn, rs, chi, ne, nn, yaw, syaw, pep, pnp in log:
        k = int(k)
        fix = f"{math.hypot(ze - pe, zn - pn):7.1f} m, {rs:5.1f}" if usable else "      (none)     "
        print(f"{upd_t[k]:5.0f} | {math.hypot(pe - te[k], pn - tn[k]):6.1f} m, {ps:4.1f} | {qs:5.1f} | {fix} "
              f"| {chi if usable else float('nan'):8.1f} | {math.hypot(ne - te[k], nn - tn[k]):6.1f} m, "
              f"{(math.degrees(yaw - tyaw[k]) + 180.0) % 360.0 - 180.0:7.1f}, {math.degrees(syaw):5.1f}, {pep:8.2f}, "
              f"{pnp:8.2f}")


def _paired_job(job):
    scenario, root, run = job
    vehicle = simulate_vehicle(scenario, keyed_vehicle_seed(root, scenario.pairing_key(), run))
    fseed = keyed_filter_seed(root, scenario.cell_key(), get("loose-dvl").seed_id, run)
    out = []
    for gate in (GATE, None):
        m = run_method(with_gate(scenario, gate), "loose-dvl", vehicle,
                       np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key)).metrics
        out.append((bool(m["diverged"]), float(m["final_horizontal_error_m"])))
    return out


def paired_sweep(sweep_path: str, runs: int, workers: int = 2) -> None:
    sweep = load_sweep(sweep_path)
    cells = {}
    for cell in sweep.cells:  # distinct cells, each keyed with the gate at 13.8
        gated = with_gate(cell.scenario, GATE)
        cells.setdefault(gated.cell_key(), gated)
    jobs = [(sc, sweep.spec.seed, r) for sc in cells.values() for r in range(runs)]
    with Pool(workers) as pool:
        results = pool.map(_paired_job, jobs, chunksize=4)
    gate_only = sum(g[0] and not n[0] for g, n in results)
    off_only = sum(n[0] and not g[0] for g, n in results)
    both = sum(g[0] and n[0] for g, n in results)
    k, n = min(gate_only, off_only), gate_only + off_only
    p = min(1.0, 2 * sum(math.comb(n, i) for i in range(k + 1)) / 2.0 ** n) if n else 1.0
    print(f"{sweep_path}: {len(results)} pairs; lost with the gate only {gate_only}, without it only {off_only}, "
          f"both {both}; two-sided sign test p = {p:.4f}")


if __name__ == "__main__":
    args = sys.argv[1:]
    if args[:1] == ["--summary"]:
        summary(args[1])
    elif args[:1] and args[0] in PAIRED_TESTS:
        fallback_ablation(args[1], int(args[args.index("--workers") + 1]) if "--workers" in args else 2, args[0])
    elif args[:1] and args[0].removesuffix("-summary") in PAIRED_TESTS:
        t = PAIRED_TESTS[args[0].removesuffix("-summary")]
        fallback_summary(args[1], t.name, t.loss_guard)
    elif args[:1] == ["--reopen-realism"]:
        reopen_realism(args[1], int(args[args.index("--workers") + 1]) if "--workers" in args else 2)
    elif args[:1] == ["--reopen-realism-summary"]:
        reopen_realism_summary(args[1])
    elif args[:1] == ["--paired"]:
        paired_sweep(args[1], int(args[2]))
    elif args[:1] == ["--diagnose"]:
        diagnose(args[1], int(args[2]), int(args[3]) if len(args) > 3 else 0, args[4] if len(args) > 4 else "none")
    else:
        workers = int(args[args.index("--workers") + 1]) if "--workers" in args else 2
        ablation(args[0], workers)
