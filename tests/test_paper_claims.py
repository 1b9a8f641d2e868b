"""The paper's claims, tested on the committed reproductions of both profiles.

Every claim is evaluated by ``tanbench.claims.evaluate`` with the statistic, test and
threshold it had when it was set (one-sided, 1 %; paired Wilcoxon where runs share their
vehicle data, Mann-Whitney otherwise), on

* ``results/zhou2017``: the recommended profile (tanbench's defaults);
* ``results/zhou2017-literal``: the paper as written (profile zhou2017-literal,
  docs/model.md section 10); skipped if that directory has not been generated
  (``make paper-literal``).

Claims that do not reproduce are ``xfail(strict=True)``, their reason saying what the
anatomy (``configs/zhou2017-anatomy.yaml``, REPORT.md) measured. Strictness means a
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
        # measured on the committed 50-run results (recommended settings: map-aware likelihood, closed-loop
        # loose TAN); the anatomy numbers are from results/zhou2017-anatomy (20 runs)
        "1b": "regularised, one beam does as well as four: tight-sbe 1.8 m against tight-dvl 2.0 m (p = 1); the "
              "anatomy's regularisation switch takes the literal tight-sbe 98.8 -> 5.1 m (-93.6 [-165.7, -21.6])",
        "1c": "the closed-loop loose TAN's median (1.6 m) beats tight-dvl's (2.0 m); its mean, 13.9 m, comes from "
              "2 of 50 runs lost at the start (paired test p = 0.94)",
        "2b": "the MC mean |heading error| in area B is 1.81 deg (A: 1.45 deg, p = 0.06): the synthetic flat "
              "region still makes the heading observable",
        "4b-tight": "tight-dvl is insensitive to noise up to +-2 m (2.0 -> 2.0 m, p = 0.21)",
        "4b-loose": "loose-dvl 2 -> 3 m noise: 74 -> 116 m, p = 0.02, above the 1 % level",
        "4c-tight": "exact 100 Hz increments make long sampling cheap for tight-dvl (2.0, 6.1, 5.1 m at 1, 5, "
                    "10 s; 5 -> 10 s not worse); at T = 10 s the anatomy's propagation switch takes the literal "
                    "tight-sbe 68.0 -> 28.3 m (-39.7 [-70.3, -9.1])",
        "4c-loose": "loose-dvl 1 -> 5 s: 13.9 -> 65.6 m with p = 0.51 (lost runs at both)",
        "4d": "the map resolution, not the sampling time, is the steepest factor for the tight filters "
              "(x6.3 / x8.8 against x2.5 / x2.0)",
        "5-tight": "2000 particles already converge (tight-dvl 2.0 -> 2.9 -> 3.5 m, p = 0.68, 0.61)",
        "5-loose": "loose-dvl 13.9 -> 18.2 -> 24.9 m with 2000 and 1000 particles, p = 0.39 and 0.55",
        "6b": "on the vehicle run the closed-loop loose TAN (3.2 m) ends better than tight-dvl (4.3 m)",
    },
    "literal": {
        # measured on the committed results/zhou2017-literal (50 runs) and results/zhou2017-anatomy (20 runs)
        "1a": "tight-dvl's mean (70.3 m, median 3.0 m) is carried by 6 of 50 runs lost for good; the anatomy's "
              "regularisation switch takes the 20-run Table 3 mean 46.7 -> 2.9 m (lost 1 -> 0), but reseeding "
              "alone moves it to 5.1 m, so that interval (-43.8 [-131.8, +44.2]) includes zero",
        "2a": "MC mean |heading error| 6.5 deg: the lost runs keep 20 deg on average (the |MC mean signed "
              "error|, not counted, is 2.8 deg); regularisation or the guards remove them (lost 1 -> 0)",
        "2b": "the heading error in B (7.9 deg) is not larger than in A (6.5 deg; p = 0.10): A's lost runs raise "
              "A's; regularisation removes the lost runs of both areas (A 1 -> 0, B 5 -> 0)",
        "3a": "tight-sbe is not worse in B (51.0 m) than in A (139.0 m): it loses 20 of 50 runs in A; "
              "regularisation takes it to 5.1 m in A and 9.0 m in B (20 runs)",
        "3b": "the fix-only loose TAN is its uncorrected 30 deg heading in both areas (158 m in B, 205 m in A); "
              "the loose-architecture switch takes it to 65.0 m in A and 91.4 m in B",
        "4a-tight": "tight-sbe's 10 -> 20 m step is not significant (139 -> 107 m, p = 0.92): lost runs at every "
                    "map resolution; at 30 m regularisation takes tight-sbe 157.4 -> 40.5 m (-116.9 [-208.6, -25.2])",
        "4a-loose": "the fix-only loose TAN is lost in 45-50 of 50 runs at every map resolution (p = 0.074 for "
                    "10 -> 20 m); at 30 m the loose-architecture switch: -184.7 m [-258.9, -110.6]",
        "4b-tight": "lost runs at every noise level hide the 1 -> 2 m step (tight-dvl 70 -> 77 m, p = 0.28); at "
                    "3 m the robust likelihood takes tight-dvl 169.2 -> 13.5 m (-155.7 [-293.6, -17.8])",
        "4c-tight": "T = 1 s loses as many runs as T = 5 s (tight-dvl means 70 vs 19 m, medians 3.0 vs 2.7 m); at "
                    "T = 10 s the propagation switch takes tight-sbe 68.0 -> 28.3 m (-39.7 [-70.3, -9.1]): the "
                    "Euler step costs at long T, the lost-run lottery decides at 1 s",
        "4c-loose": "the fix-only loose TAN is its uncorrected heading at every sampling time (205, 175, 181 m); at "
                    "T = 10 s neither the propagation (+0.0) nor the architecture (-12.7 [-32.7, +7.4]) moves it",
        "4d": "noise 3 m is the steepest factor for the tight filters (x2.5, x1.5), sampling 10 s the mildest "
              "(x0.59, x0.43) because T = 1 s already loses runs; the T = 10 s propagation switch: tight-dvl "
              "-16.8 [-43.6, +10.1], tight-sbe -39.7 [-70.3, -9.1]",
        "5-tight": "lost runs at every count (tight-dvl 2000 vs 3000: 45 vs 70 m, p = 0.52); at 1000 particles "
                   "regularisation takes tight-sbe 203.5 -> 13.9 m (-189.6 [-266.1, -113.1]) and the guards take "
                   "tight-dvl 154.5 -> 16.3 m (-138.2 [-255.6, -20.8])",
        "5-loose": "the fix-only loose TAN is its uncorrected heading at every count (205-211 m); at 1000 "
                   "particles the loose-architecture switch: -142.4 m [-218.2, -66.5]",
        "6b": "on the vehicle run (Table 8 IMU, no initial heading error) the fix-only loose-dvl (5.0 m) ends better "
              "than tight-dvl (13.0 m) and tight-sbe (19.7 m); the propagation switch takes tight-dvl 12.0 -> 3.5 m "
              "(-8.5 [-10.2, -6.8])",
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


@pytest.mark.xfail(strict=True, reason="measured on the committed 20-run sweep: tight-dvl 52.3 m (median 3.1) "
                   "< tight-sbe 216.8 m but p = 0.015 > 1 %; loose-dvl 250.5 m not above tight-sbe (p = 0.24); "
                   "tight-dvl at T = 10 s 18.5 m, not above T = 1 s (p = 0.41): without divergence recovery a "
                   "few lost runs dominate the means")
def test_literal_other_seafloor():
    """Literal profile, another seafloor (terrain seed 2, root seed 20170326, 20 runs; docs/model.md 10.1):
    tight-dvl < tight-sbe < loose-dvl at the defaults and tight-dvl worse at T = 10 s than at 1 s."""
    if not (SEAFLOOR_2 / "sweep.yaml").exists():
        pytest.skip(f"{SEAFLOOR_2} is not generated (make paper-literal)")
    c = other_seafloor(tr.load(SEAFLOOR_2))
    assert c.reproduced, "\n".join(c.evidence)
