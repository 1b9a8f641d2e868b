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
        # loose TAN); the 6-run anatomy of the literal profile is in docs/zhou2017-discussion.md
        "1b": "regularised, one beam does as well as four: tight-sbe 1.8 m against tight-dvl 2.0 m (p = 1); the "
              "anatomy's regularisation switch takes the literal tight-sbe from 120 to 4.5 m",
        "1c": "the closed-loop loose TAN's median (1.6 m) beats tight-dvl's (2.0 m); its mean, 13.9 m, comes from "
              "2 of 50 runs lost at the start (paired test p = 0.94)",
        "2b": "the MC mean |heading error| in area B is 1.81 deg (A: 1.45 deg, p = 0.06): the synthetic flat "
              "region still makes the heading observable",
        "4b-tight": "tight-dvl is insensitive to noise up to +-2 m (2.0 -> 2.0 m, p = 0.21)",
        "4b-loose": "loose-dvl 2 -> 3 m noise: 74 -> 116 m, p = 0.02, above the 1 % level",
        "4c-tight": "exact 100 Hz increments make long sampling cheap for tight-dvl (2.0, 6.1, 5.1 m at 1, 5, "
                    "10 s; 5 -> 10 s not worse); the anatomy's Euler switch at T = 10 s costs the literal tight-sbe "
                    "59 -> 13 m",
        "4c-loose": "loose-dvl 1 -> 5 s: 13.9 -> 65.6 m with p = 0.51 (lost runs at both)",
        "4d": "the map resolution, not the sampling time, is the steepest factor for the tight filters "
              "(x6.3 / x8.8 against x2.5 / x2.0)",
        "5-tight": "2000 particles already converge (tight-dvl 2.0 -> 2.9 -> 3.5 m, p = 0.68, 0.61)",
        "5-loose": "loose-dvl 13.9 -> 18.2 -> 24.9 m with 2000 and 1000 particles, p = 0.39 and 0.55",
        "6b": "on the vehicle run the closed-loop loose TAN (3.2 m) ends better than tight-dvl (4.3 m)",
    },
    "literal": {
        "1a": "tight-dvl's mean is carried by runs lost for good (50 runs: mean 70.3 m, median 3.0 m, 6 runs "
              "above 75 m); without divergence recovery or regularisation nothing brings them back",
        "2a": "MC mean |heading error| 6.5 deg: the lost runs keep their heading error (the |MC mean signed "
              "error|, not counted, is 2.8 deg)",
        "2b": "the heading error in B (7.9 deg) is not larger than in A (6.5 deg; p = 0.10): A's lost runs "
              "raise A's",
        "3a": "tight-sbe is not worse in B (51.0 m) than in A (139.0 m): in A it loses 20 of 50 runs",
        "3b": "loose-dvl is its uncorrected 30 deg heading in both areas (158 m in B, 205 m in A)",
        "4a-tight": "tight-sbe's 10 -> 20 m step is not significant (139 -> 107 m, p = 0.92): lost runs at every "
                    "map resolution",
        "4a-loose": "loose-dvl is its uncorrected heading (182-234 m); the 10 -> 20 m step has p = 0.074",
        "4b-tight": "lost runs at every noise level hide the 1 -> 2 m step (tight-dvl 70 -> 77 m, p = 0.28)",
        "4c-tight": "T = 1 s loses as many runs as T = 5 s and more metres (tight-dvl mean 70 vs 19 m, median 3.0 vs "
                    "2.7 m): the anatomy's propagation switch at T = 10 s takes tight-sbe from 59 to 13 m, so the "
                    "Euler step costs at long T, but resampling every second without regularisation costs more at 1 s",
        "4c-loose": "the loose filter propagates with the navigation system's increments in both profiles; "
                    "loose-dvl is its uncorrected heading (205, 175, 181 m)",
        "4d": "noise 3 m is the steepest factor for the tight filters (x2.5, x1.5), sampling 10 s the mildest "
              "(x0.59, x0.43) because T = 1 s already loses runs",
        "5-tight": "lost runs at every count (tight-dvl 2000 vs 3000: 45 vs 70 m, p = 0.52); the anatomy's "
                   "regularisation switch at 1000 particles takes tight-sbe from 299 to 27 m",
        "5-loose": "loose-dvl is its uncorrected heading (205-211 m)",
        "6b": "on the vehicle run loose-dvl (5.0 m) ends better than tight-dvl (13.0 m) and tight-sbe (19.7 m); "
              "the recommended profile's tight filters end at 4.0 and 3.3 m there",
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


@pytest.mark.xfail(strict=True, reason="measured on the 20-run sweep (development run): tight-dvl 52.3 m (median 3.1) "
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
