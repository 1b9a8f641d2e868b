"""The paper's claims, tested on the committed reproductions of both profiles.

Every claim is evaluated by ``tanbench.claims.evaluate`` with the statistic, test and
threshold set for it before results were seen (one-sided, 1 %; the trends and orderings on
their rank tests, Wilcoxon signed-rank where runs share their vehicle data, Mann-Whitney U
otherwise; the permutation test of the mean is reported beside and not counted; the p values
quoted in the recommended profile's reasons are of the counted test, the mean's beside it
where the two disagree), on

* ``results/zhou2017``: the recommended profile (tanbench's defaults);
* ``results/zhou2017-literal``: the paper as written (profile zhou2017-literal,
  docs/model.md section 10); skipped if that directory has not been generated
  (``make paper-literal``).

Claims that do not reproduce are ``xfail(strict=True)``, their reason saying what was
measured (the claim's evidence; for the literal profile also the anatomy,
``configs/zhou2017-anatomy.yaml``, REPORT.md). Strictness means a
change that makes one of them reproduce fails here, so this file (and the report) must
then be updated rather than silently going stale.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import tanbench.results as tr
from tanbench.claims import evaluate, other_seafloor

ROOT = Path(__file__).resolve().parents[1] / "results"
RESULTS = {"recommended": ROOT / "zhou2017", "literal": ROOT / "zhou2017-literal"}
SEAFLOOR_2 = ROOT / "zhou2017-literal-seed2"
SEE = "see results/zhou2017/REPORT.md (the anatomy) and docs/zhou2017-discussion.md"
NOT_REPRODUCED = {
    "recommended": {
        # measured on the committed 50-run results/zhou2017 (recommended settings: issue 24's defaults with
        # filter.recovery: global, filter.loose_fix_fit_one_wild_beam: true, filter.loose_reopen_heading: cloud,
        # filter.loose_reopen_position: fix, filter.loose_fix_correlation_s: 40 and
        # filter.recovery_search_around: estimate-then-distant-navigation, regenerated 4 December 2026, fifteenth
        # session: new seeds for every cell); p values of the
        # counted one-sided test (Wilcoxon signed-rank or Mann-Whitney U, at 1 %), with the permutation test of the
        # mean (reported, not counted) where the two disagree; no run of these cells is lost unless the reason says so
        "1b": "tight-sbe (mean 1.1 m) is not significantly worse than tight-dvl (1.0 m): p = 0.16",
        "2b": "the MC mean |heading error| over the last 60 s in area B is 1.17 deg, not around 10 deg (5..20); "
              "tight-dvl's final heading error is larger in B than in A (1.1 against 0.6 deg, p = 0.00047)",
        "3c": "in area B loose-dvl (mean 6.9 m) is not significantly worse than tight-dvl (5.4 m, p = 0.16; the "
              "mean's permutation test, not counted: p = 0.026) nor than tight-sbe (6.5 m, p = 0.41)",
        "4b-tight": "tight-sbe's 2 -> 3 m step is not significant on the counted test (1.3 -> 1.5 m, p = 0.020); "
                    "its 1 -> 2 m step passes (1.1 -> 1.3 m, p = 0.0022), as do both of tight-dvl's (1.0 -> 1.1 m, "
                    "p = 0.0006; 1.1 -> 1.2 m, p = 0.0047)",
        "4b-loose": "loose-dvl's 1 -> 2 m step is not significant on the counted test (1.6 -> 1.9 m, p = 0.012; the "
                    "mean's permutation test, not counted: p = 0.0085) nor its 2 -> 3 m step (1.9 -> 2.1 m, "
                    "p = 0.18)",
        "4c-tight": "tight-dvl's 1 -> 5 s step is flat (1.0 and 1.0 m, p = 0.79; 5 -> 10 s: 1.1 m, p = 0.00026); "
                    "tight-sbe's steps pass (1.1 -> 1.4 -> 1.8 m, p = 0.00038 and 3.1e-05)",
        "4c-loose": "loose-dvl's mean falls as the sampling time grows (1.6 -> 1.3 -> 1.2 m at T = 1, 5, 10 s; "
                    "p = 0.99 and 0.98)",
        "4d": "the 30 m map, not the 10 s sampling time, is the steepest factor for every filter (error ratios "
              "x9.35, x5.67, x4.34 for tight-dvl, tight-sbe, loose-dvl against x1.14, x1.70, x0.73 at T = 10 s "
              "and x1.25, x1.38, x1.31 at 3 m noise; loose-dvl loses none of 50 runs at the defaults, on the "
              "30 m map or at 3 m noise)",
        "5-tight": "no step is significant: tight-dvl 1.0, 1.0, 1.0 m at 3000, 2000, 1000 particles (p = 0.041 and "
                   "0.46), tight-sbe 1.1, 1.0, 1.1 m (p = 0.9 and 0.27)",
        "5-loose": "loose-dvl 1.6, 1.6 and 1.7 m at 3000, 2000 and 1000 particles: neither the 3000 -> 2000 step "
                   "(p = 0.18) nor the 2000 -> 1000 step (p = 0.17) is shown",
        "6b": "on the vehicle run tight-sbe (1.9 m) ends better than loose-dvl (2.5 m, p = 0.0003) but tight-dvl "
              "(3.2 m) does not (p = 1): loose-dvl with correlated fixes (docs/filters.md 16.4) ends below tight-dvl "
              "in both realisations since; the claim passed in the realisation before them (the counted test and "
              "threshold unchanged)",
    },
    "literal": {
        # measured on the committed results/zhou2017-literal (50 runs) and results/zhou2017-anatomy (20 runs)
        "1a": "tight-dvl's mean (13.0 m, median 3.2 m) is carried by 3 of 50 runs lost for good (the other 47: "
              "4.2 m); the anatomy's regularisation switch takes the 20-run Table 3 mean 8.3 -> 2.8 m (lost 1 -> 0), "
              "but reseeding alone moves it to 3.8 m, so that interval (-5.5 [-16.3, +5.3]) includes zero",
        "2a": "MC mean |heading error| 5.6 deg: the 3 lost runs keep 23 deg on average, the converged ones 4.4 deg "
              "(the |MC mean signed error|, not counted, is 1.7 deg); in the anatomy's Table 3 cell (1 lost run of "
              "20) regularisation and the guards lose none, but so do the reseeded copies",
        "3a": "tight-sbe is not significantly worse in B (62.4 m, median 50.1 m) than in A (114.7 m, median 23.9 m; "
              "p = 0.98): it loses 16 of 50 runs in A, 15 in B; regularisation takes it to 2.9 m in A and 10.7 m "
              "in B (20 runs)",
        "3b": "the fix-only loose TAN is its uncorrected 30 deg heading in both areas (169 m in B, 194 m in A); "
              "the loose-architecture switch takes it to 17.1 m in A and 116.5 m in B",
        "4a-tight": "tight-sbe's mean falls from 10 to 20 m (114.7 -> 65.4 m, p = 0.95; 134.2 m at 30 m, p = "
                    "0.0095) and tight-dvl's 20 -> 30 m step is not significant (53.6 -> 75.8 m, p = 0.23): "
                    "tight-sbe loses 16, 11 and 23 of 50 runs at 10, 20 and 30 m, tight-dvl 3, 8 and 23; at 30 m "
                    "regularisation takes tight-sbe 146.6 -> 17.4 m (-129.2 [-225.7, -32.7])",
        "4a-loose": "the fix-only loose TAN is lost in 43-50 of 50 runs at every map resolution (10 -> 20 m: "
                    "194.2 -> 172.4 m, p = 0.98); at 30 m the loose-architecture switch cuts its lost runs 19 -> 6, "
                    "but its interval includes zero (-107.8 m [-227.7, +12.1])",
        "4b-tight": "lost runs at every noise level (tight-dvl 3, 7, 13 and tight-sbe 16, 18, 31 of 50 at 1, 2, 3 m) "
                    "hide the steps: tight-dvl 13.0 -> 110.9 -> 97.1 m (p = 0.010 and 0.66), tight-sbe 114.7 -> "
                    "136.2 -> 193.5 m (p = 0.25, 0.020); at 3 m no single switch's interval excludes zero for "
                    "the tight filters (robust likelihood, tight-dvl: -117.3 [-245.7, +11.1])",
        "4c-tight": "tight-dvl's 1 -> 5 s step is not significant (means 13.0 vs 16.1 m, medians 3.2 vs 1.9 m, "
                    "p = 0.36) and tight-sbe loses more runs at T = 1 s than at 5 and 10 s (16, 9, 11 of 50; means "
                    "114.7, 42.1, 51.6 m); at T = 10 s the propagation switch takes tight-dvl 46.7 -> 16.7 m "
                    "(-30.0 [-54.1, -5.9]): the Euler step costs at long T, the lost-run lottery decides at 1 s",
        "4c-loose": "the fix-only loose TAN is its uncorrected heading at every sampling time (194, 181, 186 m); at "
                    "T = 10 s neither the propagation (+0.0) nor the architecture (-5.3 [-26.1, +15.6]) moves it",
        "4d": "noise 3 m is the steepest factor for the tight filters (x7.4, x1.7), sampling 10 s the mildest "
              "(x3.3, x0.45): the means are carried by lost runs (tight-dvl loses 13, 23, 10 of 50 at noise 3 m, "
              "map 30 m, T = 10 s; tight-sbe 16 already at the defaults); the T = 10 s propagation switch: "
              "tight-dvl -30.0 [-54.1, -5.9], tight-sbe -14.0 [-40.8, +12.7]",
        "5-tight": "lost runs at every count (tight-dvl 3, 9, 15 of 50 at 3000, 2000, 1000: 13.0, 59.0, 97.2 m, "
                   "p = 0.0085 and 0.14; tight-sbe 16-18 of 50 at each count); at 1000 particles regularisation "
                   "takes tight-sbe 76.9 -> 13.8 m (-63.0 [-106.5, -19.5]) and the guards take tight-dvl "
                   "115.0 -> 3.2 m (-111.9 [-177.9, -45.8])",
        "5-loose": "the fix-only loose TAN is its uncorrected heading at every count (194-210 m); at 1000 "
                   "particles the loose-architecture switch: -211.0 m [-254.5, -167.6]",
        "6b": "on the vehicle run (Table 8 IMU, no initial heading error) the fix-only loose-dvl (5.2 m) ends better "
              "than tight-dvl (13.1 m) and tight-sbe (19.0 m); the propagation switch takes tight-dvl 13.7 -> 3.5 m "
              "(-10.2 [-11.8, -8.6])",
    },
}
KEYS = ["1a", "1b", "1c", "2a", "2b", "3a", "3b", "3c", "4a-tight", "4a-loose", "4b-tight", "4b-loose",
        "4c-tight", "4c-loose", "4d", "5-tight", "5-loose", "6a", "6b"]
_CACHE: dict = {}


def claims_of(profile: str) -> dict:
    """Every claim evaluated once per profile on its committed results (skip if absent)."""
    directory = RESULTS[profile]
    if not (directory / "sweep.yaml").exists():
        pytest.skip(f"{directory} is not generated (make paper-literal)")
    if profile not in _CACHE:
        _CACHE[profile] = {c.key: c for c in evaluate(tr.load(directory), tr.load_series(directory))}
    return _CACHE[profile]


@pytest.mark.parametrize("profile", list(RESULTS))
def test_every_claim_is_covered(profile):
    """The test list and the evaluated claims are the same set."""
    assert set(claims_of(profile)) == set(KEYS)


@pytest.mark.parametrize("profile, key", [
    pytest.param(p, k, marks=pytest.mark.xfail(strict=True, reason=f"{NOT_REPRODUCED[p][k]}; {SEE}"))
    if k in NOT_REPRODUCED[p] else (p, k) for p in RESULTS for k in KEYS])
def test_claim(profile, key):
    """The claim holds on the committed 50-run results of the profile."""
    c = claims_of(profile)[key]
    assert c.reproduced, f"claim {key} ({profile}): {c.text}\n" + "\n".join(c.evidence)


@pytest.mark.xfail(strict=True, reason="measured on the committed 20-run sweep: tight-dvl 3.3 m < tight-sbe "
                   "231.1 m (p = 0.0005) and tight-dvl at T = 10 s 24.6 m above T = 1 s (p = 0.0005) hold, but "
                   "loose-dvl 253.9 m is not above tight-sbe (p = 0.35): both means are mostly lost runs "
                   "(tight-sbe loses 11 of 20, loose-dvl 17)")
def test_literal_other_seafloor():
    """Literal profile, another seafloor (terrain seed 2, root seed 20170326, 20 runs; docs/model.md 10.1):
    tight-dvl < tight-sbe < loose-dvl at the defaults and tight-dvl worse at T = 10 s than at 1 s."""
    if not (SEAFLOOR_2 / "sweep.yaml").exists():
        pytest.skip(f"{SEAFLOOR_2} is not generated (make paper-literal)")
    c = other_seafloor(tr.load(SEAFLOOR_2))
    assert c.reproduced, "\n".join(c.evidence)
