"""Statistical behaviour of the filters on honest (full-length, area A) Monte Carlo runs.

16 runs of the paper's 1190 s area-A trajectory (vehicle seeds
``SeedSequence(STAT_ROOT, spawn_key=(run,))``, one filter seed per method and run, all
fixed), 1000 particles unless stated. The navigation system starts with the paper's
30 deg heading error, so its dead-reckoned track drifts by hundreds of metres. Each
test compares paired samples (the same vehicle data for both arms) with a one-sided
Wilcoxon signed-rank test. The thresholds were set from a run of these exact seeds
with wide margins (observed values are quoted in each docstring); they are fixed, so
the suite is deterministic. No wall-clock assertions.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import wilcoxon

from filters_support import filter_seed, vehicle_seed
from tanbench.config import Scenario
from tanbench.methods.registry import builtin_names
from tanbench.methods import run_method
from tanbench.simulation import simulate_vehicle

METHODS = builtin_names()

pytestmark = pytest.mark.slow

RUNS = 16
# the particle-count comparison (test c) also runs 64: its original 16-run version is kept and
# counted, and the same statistic is reported on 64 runs (the first 16 are the original runs)
RUNS_OF = {"tight-dvl-500": 64, "tight-dvl-2000": 64}
CONFIGS = {
    "tight-dvl": ({"particles": 1000}, "tight-dvl"),
    # the loose filter as Zhou et al.'s comparison describes it: fixes only, no heading correction
    "loose-dvl": ({"particles": 1000, "filter": {"loose_architecture": "fix-only"}}, "loose-dvl"),
    # the recommended closed-loop loose TAN (fixes into the navigation system's Kalman filter)
    "loose-dvl-kf": ({"particles": 1000}, "loose-dvl"),
    "tight-dvl-500": ({"particles": 500}, "tight-dvl"),
    "tight-dvl-2000": ({"particles": 2000}, "tight-dvl"),
    # the navigation reading pins the heading and diverges often: with the default global recovery every divergence
    # searches the map (143 s for this test alone, against 9 s without, 4 December); the claim is about the distance
    # innovation, so this configuration re-draws around its estimate (the recovery of before 4 December; the seeds
    # do not change)
    "tight-dvl-navdist": ({"particles": 1000, "filter": {"distance_innovation": "navigation", "recovery": "estimate"}},
                          "tight-dvl"),
}


def wrap_deg(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def summarise(result) -> dict:
    s = result.series
    half = len(s["t"]) // 2
    return {
        "final_error": result.metrics["final_horizontal_error_m"],
        "mean_error": result.metrics["mean_horizontal_error_m"],
        "final_heading_error": result.metrics["final_heading_error_deg"],
        # second half of the run: how far the estimated heading is from the truth / from the nav system
        "late_heading_error": float(np.median(np.abs(s["heading_error_deg"][half:]))),
        "late_heading_from_nav": float(np.median(np.abs(wrap_deg(s["est_heading_deg"] - s["nav_heading_deg"])[half:]))),
        "late_nav_heading_error": float(np.median(np.abs(wrap_deg(s["nav_heading_deg"] - s["truth_heading_deg"])[half:]))),
    }


@pytest.fixture(scope="module")
def monte_carlo():
    """``get(name, runs)`` -> {statistic: array over the first ``runs`` runs (default ``RUNS_OF``, else
    ``RUNS``)}; each run of a configuration is computed once, and only up to the count asked (xdist may
    put the 16- and 64-run cases of test c in different processes)."""
    rows: dict[str, list[dict]] = {}

    def get(name: str, runs: int | None = None) -> dict[str, np.ndarray]:
        runs = RUNS_OF.get(name, RUNS) if runs is None else runs
        overrides, method = CONFIGS[name]
        sc = Scenario(**overrides)
        done = rows.setdefault(name, [])
        for run in range(len(done), runs):
            vehicle = simulate_vehicle(sc, vehicle_seed(run))  # cheap: the truth is cached per world
            done.append(summarise(run_method(sc, method, vehicle, filter_seed(run, METHODS.index(method)))))
        return {k: np.array([r[k] for r in done[:runs]]) for k in done[0]}

    return get


def test_monte_carlo_setup_is_hard(monte_carlo):
    """The runs are distinct and the navigation system alone is far off (heading ~30 deg wrong),
    so the comparisons below are not vacuous. Observed: nav heading error median ~31 deg."""
    loose = monte_carlo("loose-dvl")
    assert np.median(loose["late_nav_heading_error"]) > 20.0
    assert np.unique(np.round(loose["late_nav_heading_error"], 6)).size == RUNS


def test_tight_beats_loose(monte_carlo):
    """(a) Zhou et al.'s central claim in area A: the tightly coupled filter ends much closer to
    the truth than the loosely coupled one (the loose filter cannot correct the navigation
    system's heading, only the position it has caused). Paired one-sided Wilcoxon on the final
    horizontal error. Observed: tight median ~3 m, loose median ~110 m, p ~1e-4."""
    tight, loose = monte_carlo("tight-dvl")["final_error"], monte_carlo("loose-dvl")["final_error"]
    assert wilcoxon(tight, loose, alternative="less").pvalue < 0.01
    assert np.median(tight) < 10.0
    assert np.median(tight) < np.median(loose) / 5


def test_closed_loop_loose_corrects_the_heading(monte_carlo):
    """(a') The recommended loose TAN feeds its fixes to the navigation system's Kalman filter,
    which estimates the heading: its late heading error is small although the navigation
    system stays ~30 deg off. Threshold: the robustness issue's own (below 5 deg)."""
    kf = monte_carlo("loose-dvl-kf")
    assert np.median(kf["late_heading_error"]) < 5.0
    assert np.median(kf["late_nav_heading_error"]) > 20.0


def test_tight_recovers_heading(monte_carlo):
    """(b) The heading is a state of the tight filter: starting from the navigation system's
    30 deg error, its final heading error is well below 30 deg. Observed: median ~2.4 deg,
    worst ~18 deg; one-sided Wilcoxon of (error - 30) < 0: p ~1.5e-5."""
    h = monte_carlo("tight-dvl")["final_heading_error"]
    assert np.median(h) < 10.0
    assert wilcoxon(h - 30.0, alternative="less").pvalue < 0.01
    assert (h < 30.0).mean() >= 0.9


@pytest.mark.parametrize("runs", [
    # the original 16-run version failed from issue 17 to issue 24 (an expected failure then: over the run
    # 2.13 m vs 2.47 m, '2000 better' p = 0.17); with issue 24's defaults it passes again (2 December 2026:
    # final 1.01 vs 0.96 m, '2000 worse' p = 0.088; over the run 0.80 vs 1.28 m, '2000 better' p = 0.017)
    pytest.param(RUNS, id="original-16runs", marks=pytest.mark.xfail(strict=True, reason=(
        "fails again since filter.recovery: global became the default (4 December 2026): it changes only the two "
        "500-particle runs that declared a divergence (runs 0 and 3), their mean final error 0.962 -> 0.942 m "
        "against 1.008 m with 2000, and '2000 worse' goes from p = 0.088 to p = 0.017 on the 16 runs; the 64-run "
        "version of the same statistic passes"))),
    pytest.param(RUNS_OF["tight-dvl-2000"], id="64runs")])
def test_more_particles_do_not_hurt(monte_carlo, runs):
    """(c) 2000 particles versus 500 on the same vehicle data. The final error with 2000 is not
    significantly larger (one-sided Wilcoxon "2000 worse" must not reject at 5 %), and the
    error averaged over the run is smaller with 2000 (fewer early false fixes; "2000 better"
    must reject at 5 %). Set on 16 runs (observed then: final p ~0.49, means ~3.5 m both; over
    the run 1.9 m vs 6.2 m, p ~0.007); that version is kept and counted. The same statistic
    and thresholds are also reported over 64 runs (``RUNS_OF``; the first 16 are the
    original runs)."""
    few, many = monte_carlo("tight-dvl-500", runs), monte_carlo("tight-dvl-2000", runs)
    assert wilcoxon(many["final_error"], few["final_error"], alternative="greater").pvalue > 0.05
    assert many["final_error"].mean() <= 1.25 * few["final_error"].mean() + 0.5
    assert wilcoxon(many["mean_error"], few["mean_error"], alternative="greater").pvalue > 0.05
    assert many["mean_error"].mean() < few["mean_error"].mean()
    assert wilcoxon(many["mean_error"], few["mean_error"], alternative="less").pvalue < 0.05


def test_distance_innovation_mode_decides_heading(monte_carlo):
    """(d) The design difference between the two readings of Eqs. 14-18. With the "navigation"
    reading (the nav system's dead-reckoned distance against each particle's displacement)
    every particle is pinned to the navigation system's wrong heading: over the second half
    of the run the estimate stays within a few degrees of the nav heading (observed median
    ~6 deg) and ~26 deg from the truth. With the default "particle" reading the heading is
    recovered (observed median error ~2 deg, ~30 deg away from the nav heading). Paired
    one-sided Wilcoxon on the late heading error: p ~1.5e-5 (every run)."""
    nav_mode, particle_mode = monte_carlo("tight-dvl-navdist"), monte_carlo("tight-dvl")
    assert np.median(nav_mode["late_heading_from_nav"]) < 10.0
    assert np.median(nav_mode["late_heading_error"]) > 15.0
    assert np.median(particle_mode["late_heading_error"]) < 5.0
    assert np.median(particle_mode["late_heading_from_nav"]) > 15.0
    assert wilcoxon(nav_mode["late_heading_error"], particle_mode["late_heading_error"],
                    alternative="greater").pvalue < 0.01
    # and the pinned heading costs position accuracy
    assert wilcoxon(nav_mode["final_error"], particle_mode["final_error"], alternative="greater").pvalue < 0.01
