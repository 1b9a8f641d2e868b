"""What "reproduced" means for Zhou et al. 2017, fixed before the runs it judges
(docs/model.md section 11), and how often a faithful copy of the paper would pass it.

A **cell** (one table row: setting x method) reproduces when both hold:

* *mean*: the paper's 50-run mean lies inside the 95 % prediction interval for another
  50-run mean of the same distribution, ``mean +- t(0.975, n-1) s sqrt(1/n + 1/50)``
  (the plain confidence interval of our mean, ``s/sqrt(n)``, would ignore that the
  paper's mean is itself a 50-run estimate: a faithful copy would fail it one time in six);
* *extremes*: the paper's [min, max] is compatible with our runs: the number K of our
  runs above the paper's maximum, and the number L below its minimum, are each below
  the exact 1 % critical value of "K of our n runs exceed the largest of the paper's m
  runs" when both samples come from one continuous distribution,
  ``P(K >= k) = n(n-1)..(n-k+1) / ((n+m)(n+m-1)..(n+m-k+1))`` (k = 7 for n = m = 50).

A **statement** reproduces when each of its steps passes. A step compares two cells'
means with a one-sided t test at 1 % (paired by run where the cells share their vehicle
data, Welch otherwise) in one of two modes, chosen per step from the paper's own numbers
alone (``choose_modes``): *directional* (the paper's direction is significant) where a
faithful copy would pass it with probability >= 0.95 in every simulated scenario, else
*not reversed* (the opposite direction is not significant). 1a is a bound (the mean is not
significantly above the map resolution). 2a, 2b, 3a-3c and 6a rest on figures or on area B,
for which the paper gives no numbers: they are tested on means in the paper's direction
(3a-3c) or as set in ``tanbench/claims.py`` (2a, 2b, 6a), and no pass probability can be
derived for them.

The faithful copy (``simulate``): each cell's 50 runs drawn from a gamma or a lognormal
distribution with the paper's mean and a spread that makes the expected 1st and 50th order
statistics span the paper's [min, max]; runs of one world share a Gaussian copula with
correlation 0 or 0.5 (the pairing of common vehicle data, not reported by the paper).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import optimize, stats

from tanbench.paperdata import table_9, tables_3_7

ALPHA = 0.01           # one-sided level of every step
POWER_FOR_DIRECTIONAL = 0.95  # a step is tested in the paper's direction when a faithful copy passes it this often
CELL_LEVEL = 0.05      # the cell's mean interval is 95 %
EXTREME_LEVEL = 0.01   # each of the paper's extremes is tested at 1 %
PAPER_RUNS = 50
MAP_RESOLUTION_M = 10.0

# the settings of the paper's rows, over the defaults (area A, 10 m, +-1 m, 1 s, 3000 particles)
SETTINGS: dict[str, dict] = {
    "defaults": {},
    "map20": {"map_resolution_m": 20.0}, "map30": {"map_resolution_m": 30.0},
    "noise2": {"noise_m": 2.0}, "noise3": {"noise_m": 3.0},
    "T5": {"sampling_time_s": 5.0}, "T10": {"sampling_time_s": 10.0},
    "p2000": {"particles": 2000}, "p1000": {"particles": 1000},
    "B": {"area": "B"},
    "vehicle": {"area": "vehicle", "map_resolution_m": 25.0, "sampling_time_s": 5.0},
}
DEFAULTS = {"area": "A", "map_resolution_m": 10.0, "noise_m": 1.0, "sampling_time_s": 1.0, "particles": 3000}
WORLD = {s: ("B" if s == "B" else "vehicle" if s == "vehicle" else "A") for s in SETTINGS}
METHODS = ("tight-dvl", "tight-sbe", "loose-dvl")
FINAL, TIME_AVG = "final_horizontal_error_m", "mean_horizontal_error_m"


def paper_cells() -> pd.DataFrame:
    """The paper's cells: setting, method, statistic column, mean, min, max (27 of Tables 3-7, 6 of Table 9)."""
    rows = []
    t = tables_3_7().drop_duplicates(["map_resolution_m", "noise_m", "sampling_time_s", "particles", "method"])
    for _, r in t.iterrows():
        params = {k: r[k] for k in ("map_resolution_m", "noise_m", "sampling_time_s", "particles")}
        setting = next(s for s, p in SETTINGS.items() if WORLD[s] == "A"
                       and all(float(params[k]) == float({**DEFAULTS, **p}[k]) for k in params))
        rows.append((setting, r["method"], FINAL, r["mean_final_error_m"], r["min_final_error_m"],
                     r["max_final_error_m"]))
    for _, r in table_9().iterrows():
        rows.append(("vehicle", r["method"], FINAL, r["mean_final_error_m"], r["min_final_error_m"],
                     r["max_final_error_m"]))
        rows.append(("vehicle", r["method"], TIME_AVG, r["mean_error_m"], r["min_error_m"], r["max_error_m"]))
    return pd.DataFrame(rows, columns=["setting", "method", "column", "mean", "min", "max"])


# ---------------------------------------------------------------------------------------- cells

def extreme_critical(n: int, m: int = PAPER_RUNS, level: float = EXTREME_LEVEL) -> int:
    """Smallest k with P(at least k of n runs exceed the largest of m runs) <= level (same distribution)."""
    p, k = 1.0, 0
    while p > level:
        p *= (n - k) / (n + m - k)
        k += 1
        if k > n:
            return n + 1
    return k


def cell_checks(values: np.ndarray, mean, lo, hi, m: int = PAPER_RUNS):
    """Vectorised over the leading axis of ``values`` (reps, n): (mean ok, extremes ok, interval low, high)."""
    values = np.atleast_2d(values)
    n = values.shape[1]
    mu, s = values.mean(axis=1), values.std(axis=1, ddof=1)
    half = stats.t.ppf(1 - CELL_LEVEL / 2, n - 1) * s * np.sqrt(1 / n + 1 / m)
    k = extreme_critical(n, m)
    above, below = (values > hi).sum(axis=1), (values < lo).sum(axis=1)
    return np.abs(mu - mean) <= half, (above < k) & (below < k), mu - half, mu + half


def _cell_flags(values, mean, lo, hi):
    """cell_checks for one paper copy per rep (mean, lo, hi of shape (reps,))."""
    mean_ok, _, low, high = cell_checks(values, 0.0, -np.inf, np.inf)
    k = extreme_critical(values.shape[1])
    above, below = (values > hi[:, None]).sum(axis=1), (values < lo[:, None]).sum(axis=1)
    return (low <= mean) & (mean <= high), (above < k) & (below < k)


# ---------------------------------------------------------------------------------------- statements

@dataclass(frozen=True)
class Step:
    """Cell ``a`` (setting, method) has a larger mean of ``column`` than cell ``b`` in the paper."""

    a: tuple[str, str]
    b: tuple[str, str]
    column: str = FINAL

    @property
    def paired(self) -> bool:
        return WORLD[self.a[0]] == WORLD[self.b[0]]

    def label(self) -> str:
        return f"{self.a[1]}@{self.a[0]} > {self.b[1]}@{self.b[0]}" + (" (time-avg)" if self.column == TIME_AVG else "")


@dataclass
class Statement:
    key: str
    claim: str                      # the original claim (1-6) it belongs to
    text: str
    steps: list = field(default_factory=list)
    bound: tuple | None = None      # (setting, method, threshold): mean not significantly above
    simulable: bool = True


def statements() -> list[Statement]:
    """The 19 statements (the original 9 claims split where a sentence makes several)."""
    T, L = ("tight-dvl", "tight-sbe"), ("loose-dvl",)
    out = [
        Statement("1a", "1", "Area A defaults: tight-dvl's mean final error within the 10 m map resolution",
                  bound=("defaults", "tight-dvl", MAP_RESOLUTION_M)),
        Statement("1b", "1", "Area A defaults: tight-sbe worse than tight-dvl",
                  [Step(("defaults", "tight-sbe"), ("defaults", "tight-dvl"))]),
        Statement("1c", "1", "Area A defaults: loose-dvl the worst",
                  [Step(("defaults", "loose-dvl"), ("defaults", "tight-sbe")),
                   Step(("defaults", "loose-dvl"), ("defaults", "tight-dvl"))]),
        Statement("2a", "2", "Area A: tight-dvl's heading error under 2 deg (Figure 7)", simulable=False),
        Statement("2b", "2", "Area B: tight-dvl's heading error only to about 10 deg (Figure 11)", simulable=False),
        Statement("3a", "3", "Area B: the tight filters worse than in area A",
                  [Step(("B", m), ("defaults", m)) for m in T], simulable=False),
        Statement("3b", "3", "Area B: loose-dvl worse than in area A",
                  [Step(("B", "loose-dvl"), ("defaults", "loose-dvl"))], simulable=False),
        Statement("3c", "3", "Area B: tight still better than loose",
                  [Step(("B", "loose-dvl"), ("B", m)) for m in T], simulable=False),
    ]
    for key, text, chain in (("4a", "error grows with map resolution 10 -> 20 -> 30 m", ("defaults", "map20", "map30")),
                             ("4b", "error grows with noise 1 -> 2 -> 3 m", ("defaults", "noise2", "noise3")),
                             ("4c", "error grows with sampling time 1 -> 5 -> 10 s", ("defaults", "T5", "T10")),
                             ("5", "error shrinks as particles go 1000 -> 2000 -> 3000", ("defaults", "p2000", "p1000"))):
        for group, methods in (("tight", T), ("loose", L)):
            out.append(Statement(f"{key}-{group}", key, f"{text}: {', '.join(methods)}",
                                 [Step((hi, m), (lo, m)) for m in methods for lo, hi in zip(chain[:-1], chain[1:])]))
    out.append(Statement("4d", "4d", "sampling time 10 s degrades the mean most (against the 30 m map and 3 m noise)",
                         [Step(("T10", m), (other, m)) for m in METHODS for other in ("map30", "noise3")]))
    out.append(Statement("6a", "6", "vehicle run: the tight filters converge at about 240 s", simulable=False))
    out.append(Statement("6b", "6", "vehicle run: tight better than loose (time-averaged error, the original statistic)",
                         [Step(("vehicle", "loose-dvl"), ("vehicle", m), TIME_AVG) for m in T]))
    order = ["1a", "1b", "1c", "2a", "2b", "3a", "3b", "3c", "4a-tight", "4a-loose", "4b-tight", "4b-loose",
             "4c-tight", "4c-loose", "5-tight", "5-loose", "4d", "6a", "6b"]
    return sorted(out, key=lambda s: order.index(s.key)) + endpoint_statements()


ENDS = {"4a": "map30", "4b": "noise3", "4c": "T10", "5": "p1000"}


def endpoint_statements() -> list[Statement]:
    """4a-5 on the end points only (last value against the defaults): the many-seafloor sweep's cells.
    Not part of the 19; their own keys end in ``-end``."""
    out = []
    for key, end in ENDS.items():
        for group, methods in (("tight", ("tight-dvl", "tight-sbe")), ("loose", ("loose-dvl",))):
            out.append(Statement(f"{key}-{group}-end", f"{key}-end", f"{key}-{group}, {end} against the defaults",
                                 [Step((end, m), ("defaults", m)) for m in methods]))
    return out


SEAFLOOR_STATEMENTS = ("1a", "1b", "1c", "4d") + tuple(f"{k}-{g}-end" for k in ENDS for g in ("tight", "loose"))
NINETEEN = ("1a", "1b", "1c", "2a", "2b", "3a", "3b", "3c", "4a-tight", "4a-loose", "4b-tight", "4b-loose",
            "4c-tight", "4c-loose", "5-tight", "5-loose", "4d", "6a", "6b")


ORIGINAL_CLAIMS = ("1", "2", "3", "4a", "4b", "4c", "4d", "5", "6")


def _pvalues(a: np.ndarray, b: np.ndarray, paired: bool) -> np.ndarray:
    """One-sided p-values that mean(a) > mean(b), vectorised over the leading axis (reps, n)."""
    if paired:
        d = a - b
        n = d.shape[1]
        se = d.std(axis=1, ddof=1) / np.sqrt(n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(se > 0, d.mean(axis=1) / se, np.sign(d.mean(axis=1)) * np.inf)
        return np.where(np.isnan(t), 1.0, stats.t.sf(t, n - 1))
    na, nb = a.shape[1], b.shape[1]
    va, vb = a.var(axis=1, ddof=1) / na, b.var(axis=1, ddof=1) / nb
    se = np.sqrt(va + vb)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (a.mean(axis=1) - b.mean(axis=1)) / se
        dof = (va + vb) ** 2 / (va ** 2 / (na - 1) + vb ** 2 / (nb - 1))
    return np.where(np.isnan(t), 1.0, stats.t.sf(t, np.where(np.isfinite(dof), dof, 1.0)))


def step_pass(a, b, paired: bool, mode: str) -> np.ndarray:
    if mode == "directional":
        return _pvalues(a, b, paired) < ALPHA
    return _pvalues(b, a, paired) >= ALPHA  # not reversed


def bound_pass(values: np.ndarray, threshold: float) -> np.ndarray:
    """The mean is not significantly above ``threshold`` (one-sided t at ALPHA)."""
    values = np.atleast_2d(values)
    n = values.shape[1]
    t = (values.mean(axis=1) - threshold) / (values.std(axis=1, ddof=1) / np.sqrt(n))
    return stats.t.sf(t, n - 1) >= ALPHA


# ---------------------------------------------------------------------------------------- faithful copy

@dataclass(frozen=True)
class Scenario:
    family: str   # gamma or lognormal
    rho: float    # copula correlation of one world's runs

    @property
    def name(self) -> str:
        return f"{self.family}, rho {self.rho:g}"


SCENARIOS = tuple(Scenario(f, r) for f in ("gamma", "lognormal") for r in (0.0, 0.5))


def _order_quantiles(m: int = PAPER_RUNS) -> tuple[float, float]:
    """Quantile levels near the expected 1st and m-th order statistics (Blom's approximation)."""
    return (1 - 0.375) / (m + 0.25), (m - 0.375) / (m + 0.25)


def fitted_distribution(family: str, mean: float, lo: float, hi: float):
    """A frozen scipy distribution with the given mean whose expected extremes of 50 span [lo, hi]
    (width matched; the shape parameter solved by root finding)."""
    qlo, qhi = _order_quantiles()
    target = (hi - lo) / mean

    def params(shape) -> tuple:
        """(scipy distribution, its keyword parameters) of this mean and shape."""
        if family == "gamma":
            return stats.gamma, {"a": shape, "scale": mean / shape}
        return stats.lognorm, {"s": shape, "scale": mean * np.exp(-shape * shape / 2)}

    def dist(shape):
        family_dist, kw = params(shape)
        return family_dist(**kw)

    def width(shape):
        # the unfrozen ppf: the same numbers, without building a frozen distribution per root-finding step
        family_dist, kw = params(shape)
        return (family_dist.ppf(qhi, **kw) - family_dist.ppf(qlo, **kw)) / mean - target

    if family == "gamma":
        a, b = 0.05, 500.0  # width falls as the shape grows
    else:
        a, b = 0.01, 3.0
    if width(a) * width(b) > 0:
        shape = a if abs(width(a)) < abs(width(b)) else b
    else:
        shape = optimize.brentq(width, a, b)
    return dist(shape)


def simulate(scenario: Scenario, reps: int, seed: int, n: int = PAPER_RUNS) -> dict:
    """Faithful copies of the paper: {(setting, method, column): array (reps, n)} for every paper cell."""
    rng = np.random.default_rng(seed)
    cells = paper_cells()
    common = {w: rng.standard_normal((reps, n)) for w in ("A", "vehicle")}
    out = {}
    for _, c in cells.iterrows():
        z = np.sqrt(scenario.rho) * common[WORLD[c["setting"]]] + np.sqrt(1 - scenario.rho) * rng.standard_normal((reps, n))
        d = fitted_distribution(scenario.family, c["mean"], c["min"], c["max"])
        out[(c["setting"], c["method"], c["column"])] = d.ppf(stats.norm.cdf(z))
    return out


def evaluate_statements(sample: dict, modes: dict, keys=None) -> dict[str, np.ndarray]:
    """Pass flags (reps,) of every statement whose cells are in ``sample`` ({(setting, method, column): (reps, n)})."""
    out = {}
    for st in statements():
        if keys is not None and st.key not in keys:
            continue
        if st.bound is not None:
            s, m, thr = st.bound
            if (s, m, FINAL) in sample:
                out[st.key] = bound_pass(sample[(s, m, FINAL)], thr)
            continue
        if not st.steps or any((*x, step.column) not in sample for step in st.steps for x in (step.a, step.b)):
            continue
        ok = None
        for step in st.steps:
            r = step_pass(sample[(*step.a, step.column)], sample[(*step.b, step.column)], step.paired,
                          modes.get(step.label(), "directional"))
            ok = r if ok is None else ok & r
        out[st.key] = ok
    return out


SEAFLOOR_RUNS = 20  # runs per cell of the many-seafloor sweep (configs/seafloors/)


def choose_modes(reps: int = 2000, seed: int = 20170401) -> pd.DataFrame:
    """Per step: the directional test's pass probability under each faithful scenario (paper numbers only)
    and the mode it gets (directional where the smallest is >= POWER_FOR_DIRECTIONAL). The 19 statements'
    steps at the paper's 50 runs, the end-point statements' at the many-seafloor sweep's SEAFLOOR_RUNS."""
    rows = []
    by_n = {n: [simulate(sc, reps, seed + i, n=n) for i, sc in enumerate(SCENARIOS)]
            for n in (PAPER_RUNS, SEAFLOOR_RUNS)}
    for st in statements():
        if not st.simulable:
            continue
        sims = by_n[SEAFLOOR_RUNS if st.key.endswith("-end") else PAPER_RUNS]
        for step in st.steps:
            power = [float(step_pass(s[(*step.a, step.column)], s[(*step.b, step.column)], step.paired,
                                     "directional").mean()) for s in sims]
            rows.append({"statement": st.key, "step": step.label(), "paired": step.paired, "runs": sims[0][(*step.a, step.column)].shape[1],
                         **{sc.name: p for sc, p in zip(SCENARIOS, power)},
                         "mode": "directional" if min(power) >= POWER_FOR_DIRECTIONAL else "not reversed"})
    return pd.DataFrame(rows)


def step_modes() -> dict[str, str]:
    """The modes fixed by ``choose_modes`` (computed from the paper's numbers; deterministic)."""
    global _MODES
    if _MODES is None:
        t = choose_modes()
        _MODES = dict(zip(t["step"], t["mode"]))
    return _MODES


_MODES = None


def faithful_pass(reps: int = 2000, seed: int = 20170402, n: int = PAPER_RUNS):
    """Pass probability of every simulable statement, original claim and paper cell under each scenario
    (fresh draws, not those that chose the modes), and the distribution of the counts."""
    modes = step_modes()
    sts = statements()
    rows, counts, cells = [], [], []
    pc = paper_cells()
    for i, sc in enumerate(SCENARIOS):
        sample = simulate(sc, reps, seed + i, n=n)
        paper = simulate(sc, reps, seed + 100 + i)  # the paper's own 50 runs: another faithful draw
        flags = evaluate_statements(sample, modes)
        for key, f in flags.items():
            rows.append({"scenario": sc.name, "key": key, "p": float(f.mean())})
        for claim in ORIGINAL_CLAIMS:
            parts = [s.key for s in sts if s.claim == claim]
            if all(k in flags for k in parts):
                rows.append({"scenario": sc.name, "key": f"claim {claim}",
                             "p": float(np.logical_and.reduce([flags[k] for k in parts]).mean())})
        n_stat = np.sum([flags[k] for k in flags if k in NINETEEN], axis=0)
        n_sea = np.sum([flags[k] for k in flags if k in SEAFLOOR_STATEMENTS], axis=0)
        n_claim = np.sum([np.logical_and.reduce([flags[s.key] for s in sts if s.claim == c])
                          for c in ORIGINAL_CLAIMS if all(s.key in flags for s in sts if s.claim == c)], axis=0)
        cell_ok = []
        for _, c in pc.iterrows():
            key = (c["setting"], c["method"], c["column"])
            p = paper[key]
            mean_ok, ext_ok = _cell_flags(sample[key], p.mean(axis=1), p.min(axis=1), p.max(axis=1))
            cell_ok.append(mean_ok & ext_ok)
            cells.append({"scenario": sc.name, "setting": c["setting"], "method": c["method"], "column": c["column"],
                          "p_mean": float(mean_ok.mean()), "p_extremes": float(ext_ok.mean()),
                          "p_cell": float((mean_ok & ext_ok).mean())})
        n_cells = np.sum(cell_ok[:27], axis=0)
        counts.append({"scenario": sc.name, "statements": n_stat, "claims": n_claim, "cells": n_cells,
                       "seafloor": n_sea})
    return pd.DataFrame(rows), pd.DataFrame(cells), counts


# ---------------------------------------------------------------------------------------- observed runs

def observed_sample(runs: pd.DataFrame) -> tuple[dict, dict]:
    """{(setting, method, column): array (1, n)} of the runs in the paper's settings, aligned by run within
    a world (area A's cells share their vehicle data), and {world: run ids}. Lost runs stay in (they are
    part of the mean); runs that failed to run (status not ok) are dropped from every cell of their world."""
    out, ids = {}, {}
    for setting, params in SETTINGS.items():
        mask = np.ones(len(runs), bool)
        for k, v in {**DEFAULTS, **params}.items():
            mask &= (runs[k] == v).to_numpy()
        sel = runs.loc[mask]
        if sel.empty:
            continue
        w = WORLD[setting]
        for m in METHODS:
            rows = sel[sel["method"] == m]
            if rows.empty:
                continue
            ok = rows[rows["status"] == "ok"].set_index("run")
            ids[w] = ok.index if w not in ids else ids[w].intersection(ok.index)
            for col in (FINAL, TIME_AVG):
                out[(setting, m, col)] = ok[col]
    return {k: v.loc[ids[WORLD[k[0]]]].sort_index().to_numpy()[None, :] for k, v in out.items()}, ids


def resample(sample: dict, reps: int, seed: int) -> dict:
    """Bootstrap copies of an observed sample: runs drawn with replacement, the same draw for every cell of a world."""
    rng = np.random.default_rng(seed)
    draws = {}
    out = {}
    for key, v in sample.items():
        w = WORLD[key[0]]
        n = v.shape[1]
        if (w, n) not in draws:
            draws[(w, n)] = rng.integers(0, n, (reps, n))
        out[key] = v[0][draws[(w, n)]]
    return out


@dataclass
class Judgement:
    """The criterion applied to one results directory."""

    cells: pd.DataFrame
    statements: pd.DataFrame   # key, claim, passes (bool or None), bootstrap pass share, simulable
    counts: dict               # name -> (observed, bootstrap 2.5 %, 97.5 %, out of)


def judge(runs: pd.DataFrame, series: pd.DataFrame | None = None, reps: int = 1000, seed: int = 20170403,
          set_claims: dict | None = None) -> Judgement:
    """Cells and statements of ``runs`` under the criterion, with bootstrap intervals on the counts.
    ``set_claims``: {key: bool} for 2a, 2b and 6a as set in tanbench/claims.py (series statistics)."""
    sample, _ = observed_sample(runs)
    lost = observed_sample(runs.assign(**{FINAL: runs["diverged"].astype(float)}))[0] if "diverged" in runs else {}
    modes = step_modes()
    cells = []
    for _, c in paper_cells().iterrows():
        key = (c["setting"], c["method"], c["column"])
        if key not in sample:
            continue
        v = sample[key]
        mean_ok, ext_ok, low, high = cell_checks(v, c["mean"], c["min"], c["max"])
        n = v.shape[1]
        half_ci = stats.t.ppf(0.975, n - 1) * v.std(ddof=1) / np.sqrt(n)
        cells.append({"setting": c["setting"], "method": c["method"], "column": c["column"], "n": n,
                      "mean": float(v.mean()), "ci_low": float(v.mean() - half_ci), "ci_high": float(v.mean() + half_ci),
                      "pi_low": float(low[0]), "pi_high": float(high[0]),
                      "min": float(v.min()), "max": float(v.max()),
                      "above_paper_max": int((v > c["max"]).sum()), "below_paper_min": int((v < c["min"]).sum()),
                      "critical": extreme_critical(n),
                      "lost": int(lost[(c["setting"], c["method"], FINAL)].sum()) if lost else -1,
                      "paper_mean": c["mean"], "paper_min": c["min"], "paper_max": c["max"],
                      "ratio": float(v.mean() / c["mean"]), "mean_ok": bool(mean_ok[0]), "extremes_ok": bool(ext_ok[0]),
                      "reproduced": bool(mean_ok[0] and ext_ok[0])})
    cells = pd.DataFrame(cells)
    flags = evaluate_statements(sample, modes)
    boot = resample(sample, reps, seed)
    bflags = evaluate_statements(boot, modes)
    set_claims = set_claims or {}
    rows = []
    for st in statements():
        if st.key in flags:
            rows.append({"key": st.key, "claim": st.claim, "text": st.text, "passes": bool(flags[st.key][0]),
                         "boot_share": float(bflags[st.key].mean()), "simulable": st.simulable})
        else:
            rows.append({"key": st.key, "claim": st.claim, "text": st.text, "passes": set_claims.get(st.key),
                         "boot_share": np.nan, "simulable": st.simulable})
    table = pd.DataFrame(rows)
    counts = {}
    # statements: bootstrap over the ones computed from runs; the series-based ones (2a, 2b, 6a) enter as observed
    nineteen = table[table["key"].isin(NINETEEN)]
    fixed = sum(bool(p) for k, p in zip(nineteen["key"], nineteen["passes"]) if k not in bflags and p is not None)
    known = nineteen["passes"].notna()
    n_stat = np.sum([bflags[k] for k in bflags if k in NINETEEN], axis=0) + fixed
    counts["statements"] = (int(nineteen.loc[known, "passes"].sum()), *np.percentile(n_stat, [2.5, 97.5]),
                            int(known.sum()))
    simulable = [s.key for s in statements() if s.simulable and s.key in NINETEEN and s.key in flags]
    if simulable:
        counts["simulable"] = (int(sum(bool(flags[k][0]) for k in simulable)),
                               *np.percentile(np.sum([bflags[k] for k in simulable], axis=0), [2.5, 97.5]),
                               len(simulable))
    sea = [k for k in SEAFLOOR_STATEMENTS if k in flags]
    if sea:
        n_sea = np.sum([bflags[k] for k in sea], axis=0)
        counts["seafloor"] = (int(sum(bool(flags[k][0]) for k in sea)), *np.percentile(n_sea, [2.5, 97.5]), len(sea))
    claim_obs, claim_boot, n_claims = 0, 0, 0
    for claim in ORIGINAL_CLAIMS:
        part = nineteen[nineteen["claim"] == claim]
        if part["passes"].isna().any():
            continue
        n_claims += 1
        claim_obs += int(part["passes"].all())
        claim_boot = claim_boot + np.logical_and.reduce(
            [bflags[k] if k in bflags else np.full(reps, bool(p)) for k, p in zip(part["key"], part["passes"])])
    counts["claims"] = (claim_obs, *np.percentile(claim_boot, [2.5, 97.5]), n_claims)
    area_a = cells[cells["setting"] != "vehicle"]
    if len(area_a) == 27:
        bc = 0
        for _, c in area_a.iterrows():
            pc = paper_cells()
            r = pc[(pc["setting"] == c["setting"]) & (pc["method"] == c["method"]) & (pc["column"] == c["column"])].iloc[0]
            m_ok, e_ok, _, _ = cell_checks(boot[(c["setting"], c["method"], c["column"])], r["mean"], r["min"], r["max"])
            bc = bc + (m_ok & e_ok)
        counts["cells"] = (int(area_a["reproduced"].sum()), *np.percentile(bc, [2.5, 97.5]), len(area_a))
    elif len(area_a):
        counts["cells"] = (int(area_a["reproduced"].sum()), np.nan, np.nan, len(area_a))
    # the other reading of Tables 3-7's "Mean Horizontal Position Error": time-averaged (reported, not counted)
    hits = n_a = 0
    for _, c in area_a.iterrows():
        key = (c["setting"], c["method"], TIME_AVG)
        if key in sample:
            n_a += 1
            hits += bool(cell_checks(sample[key], c["paper_mean"], -np.inf, np.inf)[0][0])
    counts["time_avg_mean"] = (hits, np.nan, np.nan, n_a)
    return Judgement(cells, table, counts)


# ---------------------------------------------------------------------------------------- subsets

def table_subset(runs: pd.DataFrame, prefix: str) -> pd.DataFrame:
    """The runs of the tables named ``prefix*`` (e.g. ``lit_`` or ``rec_`` of a many-seafloor sweep)."""
    return runs[runs["tables"].astype(str).str.startswith(prefix)]


def first_runs(runs: pd.DataFrame, n: int) -> pd.DataFrame:
    """Runs 0 .. n-1 (the seeds a smaller sweep with the same root seed shares)."""
    return runs[runs["run"] < n]


def paired_difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    """Mean of a - b (paired by run) with its 95 % t interval."""
    d = np.asarray(a, float) - np.asarray(b, float)
    n = d.size
    half = stats.t.ppf(0.975, n - 1) * d.std(ddof=1) / np.sqrt(n) if n > 1 else np.nan
    return float(d.mean()), float(d.mean() - half), float(d.mean() + half)


# ---------------------------------------------------------------------------------------- held-out subsets

def subset_counts(runs: pd.DataFrame, keys, cells, reps: int = 1000, seed: int = 20170403) -> dict:
    """Counts of the statements ``keys`` and of the cells ``cells`` ((setting, method, column) tuples) that
    ``runs`` pass under the criterion, each as (observed, bootstrap 2.5 %, 97.5 %, out of): the runs resampled
    as in :func:`judge` (the same draw for every cell of a world). Only statements and cells present count."""
    sample, _ = observed_sample(runs)
    modes = step_modes()
    boot = resample(sample, reps, seed)
    flags, bflags = evaluate_statements(sample, modes, keys), evaluate_statements(boot, modes, keys)
    out = {}
    present = [k for k in keys if k in flags]
    if present:
        out["statements"] = (int(sum(bool(flags[k][0]) for k in present)),
                             *np.percentile(np.sum([bflags[k] for k in present], axis=0), [2.5, 97.5]), len(present))
    pc = paper_cells().set_index(["setting", "method", "column"])
    ok_obs, ok_boot, n = 0, 0, 0
    for key in cells:
        if key not in sample:
            continue
        c = pc.loc[key]
        m_ok, e_ok, _, _ = cell_checks(sample[key], c["mean"], c["min"], c["max"])
        bm, be, _, _ = cell_checks(boot[key], c["mean"], c["min"], c["max"])
        ok_obs += bool(m_ok[0] and e_ok[0])
        ok_boot = ok_boot + (bm & be)
        n += 1
    if n:
        out["cells"] = (ok_obs, *np.percentile(ok_boot, [2.5, 97.5]), n)
    return out


def faithful_subset_counts(keys, cells, reps: int = 1000, seed: int = 20170405) -> dict:
    """A faithful copy's counts on the same subsets: {"statements": (5th, 95th percentile, out of), "cells": ...},
    the smallest 5th and largest 95th percentile over the four scenarios (simulated as in :func:`faithful_pass`,
    the paper's own 50 runs drawn again for the cell test). Statements that cannot be simulated are left out."""
    modes = step_modes()
    lows, highs = {"statements": [], "cells": []}, {"statements": [], "cells": []}
    n_st = n_cells = 0
    for i, sc in enumerate(SCENARIOS):
        sample = simulate(sc, reps, seed + i)
        paper = simulate(sc, reps, seed + 100 + i)
        flags = evaluate_statements(sample, modes, keys)
        n_st = len(flags)
        count = np.sum(list(flags.values()), axis=0)
        ok = 0
        for key in cells:
            p = paper[key]
            m_ok, e_ok = _cell_flags(sample[key], p.mean(axis=1), p.min(axis=1), p.max(axis=1))
            ok = ok + (m_ok & e_ok)
        n_cells = len(cells)
        for name, v in (("statements", count), ("cells", ok)):
            lo, hi = np.percentile(v, [5, 95])
            lows[name].append(lo)
            highs[name].append(hi)
    return {"statements": (min(lows["statements"]), max(highs["statements"]), n_st),
            "cells": (min(lows["cells"]), max(highs["cells"]), n_cells)}
