"""The paper's claims, each checked with the statistical test it needs, on stored results.

Used by ``tests/test_paper_claims.py`` (on the committed ``results/zhou2017``) and by the
report (``tanbench report``). Methods of one run share their vehicle data, and so do the
area-A cells (same world, common random numbers), so comparisons between them are
paired; area A against area B or the vehicle run are different worlds, so those are
unpaired. The trend and ordering claims are counted on the tests they were set with before
any result was seen: one-sided rank tests (paired Wilcoxon signed-rank, i.e. the
pseudo-median; unpaired Mann-Whitney U). The paper reports means, so every comparison also
prints the test of the mean (a one-sided permutation test of the change of the mean, paired:
sign flips of the per-run differences, unpaired: permuted labels;
:func:`tanbench.inference.permutation_p`) with the lost-run counts (``diverged``); where it
disagrees the line says so, and it is reported, not counted (issue 22 asked for the mean;
the project counts a claim's original statistic). Level: 1 %.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy import stats

from tanbench.inference import permutation_p
from tanbench.paperdata import table_9, tables_3_7
from tanbench.results import TABLE_SCENARIO_COLUMNS

ALPHA = 0.01
PAPER_METHODS = ("tight-dvl", "tight-sbe", "loose-dvl")  # the methods the paper's claims are about


def _paper():
    """The paper's Table 3 (its defaults and mean final errors) and Table 9, by method."""
    t = tables_3_7()
    t3 = t[t["table"] == 3].set_index("method")
    defaults = {c: t3.iloc[0][c] for c in TABLE_SCENARIO_COLUMNS}
    defaults = {k: (v.item() if hasattr(v, "item") else v) for k, v in defaults.items()}
    return defaults, t3["mean_final_error_m"].to_dict(), table_9().set_index("method")["mean_final_error_m"].to_dict()


DEFAULTS, PAPER_TABLE3, PAPER_TABLE9 = _paper()


@dataclass
class Claim:
    """One claim of the paper: what it says, whether it reproduces, and the evidence."""

    key: str
    text: str
    reproduced: bool = True
    evidence: list[str] = field(default_factory=list)

    def check(self, ok: bool, line: str) -> None:
        self.reproduced = self.reproduced and bool(ok)
        self.evidence.append(("ok    " if ok else "FAILS ") + line)


def final_errors(runs: pd.DataFrame, method: str, column: str = "final_horizontal_error_m", **params) -> pd.Series:
    """Per-run values of ``column`` for ``method`` in the cell given by ``params`` over the defaults
    (the runs' lost flags ride along in ``attrs["lost"]``)."""
    mask = _cell_mask(runs, **params) & (runs["method"] == method).to_numpy() & (runs["status"] == "ok").to_numpy()
    sel = runs.loc[mask].set_index("run").sort_index()
    out = sel[column]
    if "diverged" in sel:
        out.attrs["lost"] = sel["diverged"].astype(bool)
    return out


def _cell_mask(runs: pd.DataFrame, **params) -> np.ndarray:
    """Rows of the cell given by ``params`` over the paper's defaults."""
    mask = np.ones(len(runs), bool)
    for k, v in {**DEFAULTS, **params}.items():
        mask &= (runs[k] == v).to_numpy()
    return mask


def paired_greater(a: pd.Series, b: pd.Series) -> tuple[float, float, int]:
    """One-sided p-value that mean(a) > mean(b) on common runs (paired permutation test of the
    mean: sign flips of the differences); also mean(a - b) and n."""
    a, b = a.align(b, join="inner")
    d = (a - b).to_numpy()
    if len(d) < 5 or np.allclose(d, 0):
        return 1.0, float(np.mean(d)) if len(d) else np.nan, len(d)
    return permutation_p(a.to_numpy(), b.to_numpy(), 0.0, paired=True), float(d.mean()), len(d)


def unpaired_greater(a: pd.Series, b: pd.Series) -> float:
    """One-sided p-value that mean(a) > mean(b) (permutation test of the mean, labels permuted)."""
    if len(a) < 3 or len(b) < 3:
        return 1.0
    return permutation_p(a.to_numpy(), b.to_numpy(), 0.0, paired=False)


def rank_greater(a: pd.Series, b: pd.Series, paired: bool) -> float:
    """The claims' counted test, as set: paired Wilcoxon signed-rank (pseudo-median), unpaired
    Mann-Whitney U, one-sided."""
    if paired:
        a, b = a.align(b, join="inner")
        if len(a) < 5 or np.allclose((a - b).to_numpy(), 0):
            return 1.0
        return float(stats.wilcoxon(a, b, alternative="greater").pvalue)
    if len(a) < 3 or len(b) < 3:
        return 1.0
    return float(stats.mannwhitneyu(a, b, alternative="greater").pvalue)


def _lost_text(a: pd.Series, b: pd.Series) -> str:
    la, lb = a.attrs.get("lost"), b.attrs.get("lost")
    if la is None or lb is None:
        return ""
    return f"; lost runs {int(la.sum())}/{len(la)} vs {int(lb.sum())}/{len(lb)}"


def _greater(claim: Claim, label: str, a, b, paired=True, unit="m"):
    lost = _lost_text(a, b)
    rank = rank_greater(a, b, paired)
    if paired:
        p, diff, n = paired_greater(a, b)
        test = f"paired permutation test of the mean, n={n}"
    else:
        p = unpaired_greater(a, b)
        test = f"permutation test of the mean, n={len(a)}/{len(b)}"
    rank_test = "Wilcoxon signed-rank (pseudo-median)" if paired else "Mann-Whitney U"
    other = f" [the {test} disagrees: reported, not counted]" if (rank < ALPHA) != (p < ALPHA) else ""
    claim.check(rank < ALPHA, f"{label}: mean {a.mean():.1f} vs {b.mean():.1f} {unit} ({rank_test} p={rank:.2g}, "
                              f"counted; {test}, p={p:.2g}{lost}){other}")


def _cell_id(runs: pd.DataFrame, **params) -> str:
    return str(runs.loc[_cell_mask(runs, **params), "cell_id"].iloc[0])


def _heading(series: pd.DataFrame, cell_id: str, method: str, column: str, last_s: float = 60.0) -> float:
    s = series[(series["cell_id"] == cell_id) & (series["method"] == method)]
    return float(s.loc[s["t"] >= s["t"].max() - last_s, column].mean())


def evaluate(runs: pd.DataFrame, series: pd.DataFrame) -> list[Claim]:
    """Every claim of the paper the zhou2017 sweep can check, split where the paper's
    sentence makes several checkable statements (so a partial reproduction shows as such)."""
    f = lambda m, **kw: final_errors(runs, m, **kw)  # noqa: E731
    out = []

    def claim(key, text):
        c = Claim(key, text)
        out.append(c)
        return c

    dvl, sbe, loose = f("tight-dvl"), f("tight-sbe"), f("loose-dvl")
    c = claim("1a", "Area A, defaults: tight-dvl's mean final error is within the map resolution "
                    f"(paper {PAPER_TABLE3['tight-dvl']} m with a {DEFAULTS['map_resolution_m']:g} m map).")
    c.check(dvl.mean() <= DEFAULTS["map_resolution_m"],
            f"tight-dvl mean final error {dvl.mean():.1f} m <= {DEFAULTS['map_resolution_m']:g} m")
    c = claim("1b", f"Area A, defaults: tight-sbe is clearly worse than tight-dvl (paper {PAPER_TABLE3['tight-sbe']} m "
                    f"against {PAPER_TABLE3['tight-dvl']} m).")
    _greater(c, "tight-sbe worse than tight-dvl", sbe, dvl)
    c = claim("1c", f"Area A, defaults: loose-dvl is the worst (paper {PAPER_TABLE3['loose-dvl']} m).")
    _greater(c, "loose-dvl worse than tight-sbe", loose, sbe)
    _greater(c, "loose-dvl worse than tight-dvl", loose, dvl)

    a_id, b_id = _cell_id(runs), _cell_id(runs, area="B")
    c = claim("2a", "Area A: tight-dvl's heading error falls from 30 deg to under 2 deg "
                    "(Figure 7: the Monte Carlo mean of |heading error| over the last 60 s).")
    mean_a = abs(_heading(series, a_id, "tight-dvl", "heading_error_deg_mean"))
    abs_a = _heading(series, a_id, "tight-dvl", "heading_error_deg_abs_mean")
    # the statistic as set: the mean of |error|; the |mean signed error| (the heading of the Monte Carlo
    # mean trajectory, which Figure 7's caption may describe) is reported beside it and not counted
    c.check(abs_a < 2.0, f"MC mean |heading error| over the last 60 s {abs_a:.2f} deg < 2 deg "
                         f"(not counted: |MC mean signed error| {mean_a:.2f} deg)")
    c = claim("2b", "Area B: tight-dvl's heading error falls only to around 10 deg (Figure 11).")
    mean_b = abs(_heading(series, b_id, "tight-dvl", "heading_error_deg_mean"))
    abs_b = _heading(series, b_id, "tight-dvl", "heading_error_deg_abs_mean")
    c.check(5.0 <= abs_b <= 20.0, f"MC mean |heading error| over the last 60 s {abs_b:.2f} deg, around 10 deg "
                                  f"(5..20; |MC mean error| {mean_b:.2f} deg)")
    _greater(c, "final heading error larger in B than in A",
             f("tight-dvl", column="final_heading_error_deg", area="B"),
             f("tight-dvl", column="final_heading_error_deg"), paired=False, unit="deg")

    c = claim("3a", "Area B (flat): the tightly coupled methods are worse than in area A.")
    for m in ("tight-dvl", "tight-sbe"):
        _greater(c, f"{m}: B worse than A", f(m, area="B"), f(m), paired=False)
    c = claim("3b", "Area B (flat): the loosely coupled method is worse than in area A.")
    _greater(c, "loose-dvl: B worse than A", f("loose-dvl", area="B"), f("loose-dvl"), paired=False)
    c = claim("3c", "Area B (flat): tight is still better than loose.")
    for m in ("tight-dvl", "tight-sbe"):
        _greater(c, f"area B: loose-dvl worse than {m}", f("loose-dvl", area="B"), f(m, area="B"))

    for key, param, values, text in (
        ("4a", "map_resolution_m", (10.0, 20.0, 30.0), "Error grows with map resolution 10 -> 20 -> 30 m"),
        ("4b", "noise_m", (1.0, 2.0, 3.0), "Error grows with measurement noise 1 -> 2 -> 3 m"),
        ("4c", "sampling_time_s", (1.0, 5.0, 10.0), "Error grows with sampling time 1 -> 5 -> 10 s"),
        ("5", "particles", (3000, 2000, 1000), "Error shrinks as particles go 1000 -> 2000 -> 3000"),
    ):
        for group, methods in (("tight", ("tight-dvl", "tight-sbe")), ("loose", ("loose-dvl",))):
            c = claim(f"{key}-{group}", f"{text}: {', '.join(methods)}, each step.")
            for m in methods:
                for lo, hi in zip(values[:-1], values[1:]):
                    _greater(c, f"{m}: {param} {hi:g} worse than {lo:g}", f(m, **{param: hi}), f(m, **{param: lo}))

    c = claim("4d", "Sampling time degrades the error most steeply (Table 6 against Tables 4-5).")
    for m in PAPER_METHODS:
        base = f(m).mean()
        growth = {p: f(m, **{p: v}).mean() / base for p, v in
                  (("sampling_time_s", 10.0), ("map_resolution_m", 30.0), ("noise_m", 3.0))}
        steepest = max(growth, key=growth.get)
        c.check(steepest == "sampling_time_s",
                f"{m}: error ratio at the worst setting: sampling 10 s x{growth['sampling_time_s']:.2f}, "
                f"map 30 m x{growth['map_resolution_m']:.2f}, noise 3 m x{growth['noise_m']:.2f}")

    kw = dict(area="vehicle", map_resolution_m=25.0, sampling_time_s=5.0)
    vid = _cell_id(runs, **kw)
    c = claim("6a", "Vehicle run: the tightly coupled filters converge once the rough terrain starts (about 240 s).")
    for m in ("tight-dvl", "tight-sbe"):
        s = series[(series["cell_id"] == vid) & (series["method"] == m)]
        t, std = s["t"].to_numpy(), s["filter_std_m_mean"].to_numpy()
        below = np.nonzero(std < 10.0)[0]
        t_conv = float(t[below[0]]) if below.size else float("nan")
        c.check(180.0 <= t_conv <= 400.0, f"{m}: MC mean filter std first below 10 m at t = {t_conv:.0f} s "
                                          f"(180..400 s)")
        before = s.loc[s["t"] < 240, "horizontal_error_m_mean"].mean()
        after = s.loc[s["t"] >= 300, "horizontal_error_m_mean"].mean()
        c.check(after < before, f"{m}: MC mean error {before:.1f} m before 240 s, {after:.1f} m after 300 s")
    c = claim("6b", "Vehicle run: the tightly coupled filters end better than the loosely coupled one "
                    f"(Table 9: {PAPER_TABLE9['tight-dvl']} and {PAPER_TABLE9['tight-sbe']} m against "
                    f"{PAPER_TABLE9['loose-dvl']} m).")
    for m in ("tight-dvl", "tight-sbe"):
        _greater(c, f"vehicle run: loose-dvl final error above {m}", f("loose-dvl", **kw), f(m, **kw))
    return out


def other_seafloor(runs: pd.DataFrame) -> Claim:
    """The literal profile's ranking and sampling-time trend on another seafloor
    (``configs/zhou2017-literal-seed2.yaml``; docs/model.md section 10.1, fixed before it was run)."""
    f = lambda m, **kw: final_errors(runs, m, **kw)  # noqa: E731
    c = Claim("seafloor-2", "Another synthetic seafloor, area A, literal profile: tight-dvl < tight-sbe < loose-dvl "
                            "at the defaults, and tight-dvl's error grows from T = 1 s to T = 10 s.")
    _greater(c, "tight-sbe worse than tight-dvl", f("tight-sbe"), f("tight-dvl"))
    _greater(c, "loose-dvl worse than tight-sbe", f("loose-dvl"), f("tight-sbe"))
    _greater(c, "tight-dvl: sampling_time_s 10 worse than 1", f("tight-dvl", sampling_time_s=10.0), f("tight-dvl"))
    return c
