"""The paper's claims, tested on the committed reproductions of both profiles.

Every claim is evaluated by ``tanbench.claims.evaluate`` with the statistic, test and
threshold it had when it was set (one-sided, 1 %; paired Wilcoxon where runs share their
vehicle data, Mann-Whitney otherwise), on

* ``results/zhou2017``: the recommended profile (tanbench's defaults);
* ``results/zhou2017-literal``: the paper as written (profile zhou2017-literal,
  docs/model.md section 9); skipped if that directory has not been generated
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
        "1b": "regularisation decides it: the anatomy's literal -> liu-west switch takes tight-sbe from tens of "
              "metres to ~2 m in area A, while tight-dvl barely moves",
        "2a": "the MC mean of |heading error| over the last 60 s is 2.2 deg, just above the 2 deg bound "
              "(the |MC mean signed error|, not counted, is 0.4 deg)",
        "2b": "with regularisation and exact propagation the heading converges to ~2 deg in area B too",
        "3b": "loose-dvl's error is dominated by its uncorrected 30 deg heading, not by the terrain",
        "4a-loose": "loose-dvl's error is dominated by its uncorrected heading",
        "4b-tight": "tight-dvl is insensitive to noise up to +-2 m",
        "4b-loose": "loose-dvl's error is dominated by its uncorrected heading",
        "4c-tight": "the anatomy's propagation switch: exact 100 Hz increments make T = 10 s almost free "
                    "for the tight filters (the Euler step of Eq. 1 is what makes sampling time costly)",
        "4c-loose": "loose-dvl's error is dominated by its uncorrected heading; the loose filter's propagation is "
                    "the navigation system's own increments in both profiles",
        "4d": "with exact propagation sampling time is the mildest factor, not the steepest",
        "5-tight": "regularisation: 2000 particles already converge; 1000 fail only in a few runs",
        "5-loose": "loose-dvl's error is dominated by its uncorrected heading",
    },
    "literal": {},
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
    """Literal profile, another seafloor (terrain seed 2, root seed 20170326, 20 runs; docs/model.md 9.1):
    tight-dvl < tight-sbe < loose-dvl at the defaults and tight-dvl worse at T = 10 s than at 1 s."""
    if not (SEAFLOOR_2 / "sweep.yaml").exists():
        pytest.skip(f"{SEAFLOOR_2} is not generated (make paper-literal)")
    c = other_seafloor(tr.load(SEAFLOOR_2))
    assert c.reproduced, "\n".join(c.evidence)
