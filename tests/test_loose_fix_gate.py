"""docs/filters.md 9: loose-dvl's fix-prior gate (filter.loose_fix_prior_gate)."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from mutation_support import LATER_NEUTRAL_FILTER as LATER_NEUTRAL  # the later defaults' neutral values
from tanbench.config import Scenario
from tanbench.methods import get, run_method
from tanbench.runner.seeds import keyed_filter_seed, keyed_vehicle_seed
from tanbench.simulation import simulate_vehicle
from tanbench.sweep import load_sweep


def test_the_gate_is_an_option_off_by_default_and_needs_heading_offsets():
    assert Scenario().filter.loose_fix_prior_gate is None
    on = Scenario(filter={"loose_fix_prior_gate": 13.8})
    assert on.cell_key() != Scenario().cell_key()  # a non-neutral value names its own cell
    assert "loose_fix_prior_gate" not in str(Scenario().identity())  # off is neutral: the keys from before it
    with pytest.raises(ValidationError, match="loose_fix_prior_gate"):
        Scenario(filter={"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
                         "loose_fix_fit_one_wild_beam": False, "loose_fix_prior_gate": 13.8})


def test_the_diagnosed_run_is_lost_by_its_fixes_and_kept_by_the_gate():
    """quick.yaml's area A cell, run 2: at the defaults an extrapolated terrain-only fix turns the
    navigation heading by -71 degrees and the KF never recovers; with the gate, on the same vehicle
    data and filter seed, that fix is refused. (Both arms take the seeds of the cell as diagnosed:
    without the gate, and with the tight filters' recovery of then, ``estimate``, which loose-dvl
    does not use but the cell's key holds.)"""
    sweep = load_sweep("configs/quick.yaml")
    quick = sweep.cells[0].scenario
    sc = Scenario(**{**quick.model_dump(mode="json"),
                     "filter": {**quick.model_dump(mode="json")["filter"], "loose_fix_prior_gate": None,
                                "recovery": "estimate", "loose_fix_fit_one_wild_beam": False,
                                "loose_reopen_heading": "navigation", "loose_reopen_position": "prior",
                                **LATER_NEUTRAL}})
    assert (sc.area, sc.map_resolution_m, sc.particles) == ("A", 10, 2000)
    vehicle = simulate_vehicle(sc, keyed_vehicle_seed(sweep.spec.seed, sc.pairing_key(), 2))
    fseed = keyed_filter_seed(sweep.spec.seed, sc.cell_key(), get("loose-dvl").seed_id, 2)
    gate = Scenario(**{**sc.model_dump(mode="json"),
                       "filter": {**sc.model_dump(mode="json")["filter"], "loose_fix_prior_gate": 13.8}})
    runs = {name: run_method(s, "loose-dvl", vehicle, np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key))
            for name, s in (("defaults", sc), ("gate", gate))}
    assert runs["defaults"].metrics["diverged"]
    assert runs["defaults"].metrics["final_horizontal_error_m"] > 100.0
    assert not runs["gate"].metrics["diverged"]
    assert runs["gate"].metrics["final_horizontal_error_m"] < 10.0


def test_the_fallback_needs_the_gate_and_keeps_the_diagnosed_run():
    """docs/filters.md 9.1: the refused fix replaced by the PF's own estimate; the diagnosed run is kept."""
    with pytest.raises(ValidationError, match="loose_fix_prior_fallback"):
        Scenario(filter={"loose_fix_prior_fallback": "posterior"})
    assert Scenario(filter={"loose_fix_prior_fallback": "refuse"}).cell_key() == Scenario().cell_key()
    sweep = load_sweep("configs/quick.yaml")
    sc = _with_filter(sweep.cells[0].scenario, loose_fix_fit_one_wild_beam=False,  # the keys of the test's writing
                      loose_reopen_heading="navigation",
                      loose_reopen_position="prior", **LATER_NEUTRAL)
    vehicle = simulate_vehicle(sc, keyed_vehicle_seed(sweep.spec.seed, sc.pairing_key(), 2))
    fseed = keyed_filter_seed(sweep.spec.seed, sc.cell_key(), get("loose-dvl").seed_id, 2)
    data = sc.model_dump(mode="json")
    fallback = Scenario(**{**data, "filter": {**data["filter"], "loose_fix_prior_gate": 13.8,
                                               "loose_fix_prior_fallback": "posterior"}})
    m = run_method(fallback, "loose-dvl", vehicle, np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key))
    assert not m.metrics["diverged"] and m.metrics["final_horizontal_error_m"] < 10.0


def _with_filter(scenario: Scenario, **options) -> Scenario:
    data = scenario.model_dump(mode="json")
    return Scenario(**{**data, "filter": {**data["filter"], **options}})


def _diagnosed_outlier_run():
    """Section 11's diagnosed run: realism's 5 % outlier cell as it was then (the fit test on, no one-wild-beam
    rule), run 9; (that scenario, a function running loose-dvl on the run's vehicle data and filter seed with
    any other filter settings: its metrics)."""
    sweep = load_sweep("configs/realism.yaml")
    cell = next(c.scenario for c in sweep.cells if c.scenario.faults.outlier_fraction == 0.05
                and c.scenario.filter.likelihood == "student-t" and c.scenario.filter.map_aware_likelihood)
    sc = _with_filter(cell, loose_fix_fit_test=True, loose_fix_fit_one_wild_beam=False,
                      loose_reopen_heading="navigation",
                      loose_reopen_position="prior", **LATER_NEUTRAL)
    vehicle = simulate_vehicle(sc, keyed_vehicle_seed(sweep.spec.seed, sc.pairing_key(), 9))
    fseed = keyed_filter_seed(sweep.spec.seed, sc.cell_key(), get("loose-dvl").seed_id, 9)
    return sc, lambda s: run_method(s, "loose-dvl", vehicle,
                                    np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key)).metrics


def test_the_fit_test_is_an_option_neutral_when_on_and_needs_heading_offsets():
    assert Scenario(filter={"loose_fix_fit_test": True}).cell_key() == Scenario(
        filter={"loose_fix_fit_test": True, "recovery": "global"}).cell_key()
    assert "loose_fix_fit_test" not in str(Scenario(filter={"loose_fix_fit_test": True}).identity())
    assert Scenario(filter={"loose_fix_fit_test": False}).filter.loose_fix_fit_one_wild_beam  # moot without the test
    assert Scenario(filter={"loose_fix_fit_test": False}).cell_key() != Scenario(
        filter={"loose_fix_fit_test": True}).cell_key()
    with pytest.raises(ValidationError, match="loose_fix_fit_test"):
        Scenario(filter={"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
                         "loose_fix_fit_one_wild_beam": False, "loose_fix_fit_test": False})


def test_outliers_starve_the_fixes_through_the_fit_test():
    """docs/filters.md 11: realism's 5 % outlier cell, run 9, as diagnosed (the fit test on): one wild range
    fails the fit, so few fixes are attempted, the KF never learns the heading and the run is lost; without
    the fit test, on the same vehicle data and filter seed, more fixes come and the run is kept."""
    sc, run = _diagnosed_outlier_run()
    runs = {"fit test": run(sc), "no fit test": run(_with_filter(sc, loose_fix_fit_test=False))}
    assert runs["fit test"]["diverged"] and runs["fit test"]["final_horizontal_error_m"] > 100.0
    assert runs["fit test"]["fixes_accepted"] <= 5
    assert not runs["no fit test"]["diverged"] and runs["no fit test"]["final_horizontal_error_m"] < 10.0
    assert runs["no fit test"]["fixes_accepted"] > 2 * runs["fit test"]["fixes_accepted"]


def test_one_wild_beam_is_the_default_neutral_when_off_and_needs_heading_offsets():
    """docs/filters.md 11.3: on by default; off is the behaviour before the option (no key field)."""
    assert Scenario().filter.loose_fix_fit_one_wild_beam
    assert "loose_fix_fit_one_wild_beam" not in str(Scenario(filter={"loose_fix_fit_one_wild_beam": False}).identity())
    assert "loose_fix_fit_one_wild_beam" in str(Scenario().identity())
    assert Scenario().cell_key() == Scenario(filter={"loose_fix_fit_one_wild_beam": True}).cell_key()
    with pytest.raises(ValidationError, match="loose_fix_fit_one_wild_beam"):
        Scenario(filter={"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None})


def test_one_wild_beam_keeps_the_diagnosed_outlier_run():
    """docs/filters.md 11.2: the run of section 11's diagnosis, on the same vehicle data and filter seed, with
    an update failing the fit by one beam leaving the count: more fixes, and the run is kept."""
    sc, run = _diagnosed_outlier_run()
    m = run(_with_filter(sc, loose_fix_fit_one_wild_beam=True))
    assert not m["diverged"] and m["final_horizontal_error_m"] < 10.0 and m["fixes_accepted"] > 8


def test_the_first_fix_from_the_posterior_is_an_option_and_keeps_section_7_4s_lost_run():
    """docs/filters.md 13: ``filter.loose_first_fix: posterior`` (not adopted, 13.1) resets the KF at the first fix
    to the cloud's posterior. Section 7.4's lost run (area A as configs/methods.yaml's budget-default cell, run 28,
    2000 particles) is reset at 36 s to a terrain-only fix about 270 m from the cloud and never recovers; from the
    posterior, on the same vehicle data and filter seed, it ends within metres."""
    assert Scenario().filter.loose_first_fix == "terrain-only"
    assert Scenario(filter={"loose_first_fix": "terrain-only"}).cell_key() == Scenario().cell_key()
    with pytest.raises(ValidationError, match="loose_first_fix"):
        Scenario(filter={"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
                         "loose_fix_fit_one_wild_beam": False, "loose_reopen_heading": "navigation",
                         "loose_reopen_position": "prior",
                         "loose_first_fix": "posterior"})
    root = 14140014  # configs/methods.yaml
    sc = Scenario(terrain={"kind": "synthetic", "seed": 1}, area="A", map_resolution_m=10, noise_m=1.0,
                  sampling_time_s=1, particles=2000,
                  filter={"loose_reopen_heading": "navigation",
                          "loose_reopen_position": "prior", **LATER_NEUTRAL})  # the keys of the test's writing
    vehicle = simulate_vehicle(sc, keyed_vehicle_seed(root, sc.pairing_key(), 28))
    fseed = keyed_filter_seed(root, sc.cell_key(), get("loose-dvl").seed_id, 28)
    runs = {name: run_method(s, "loose-dvl", vehicle,
                             np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key)).metrics
            for name, s in (("defaults", sc), ("posterior", _with_filter(sc, loose_first_fix="posterior")))}
    assert runs["defaults"]["final_horizontal_error_m"] > 100.0 and runs["defaults"]["fixes_accepted"] == 1
    assert runs["posterior"]["final_horizontal_error_m"] < 10.0


def test_the_cloud_heading_matches_its_numpy_reference_across_the_wrap():
    from tanbench.filters.loose_turned import cloud_heading_offset, cloud_heading_offset_numpy

    rng = np.random.default_rng(3)
    for centre in (0.0, 3.0, -3.1, 10.0):  # particle yaws on either side of +-pi from the reference
        yaw = centre + 0.2 * rng.standard_normal(500)
        w = rng.random(500)
        w /= w.sum()
        got = cloud_heading_offset(yaw, w, 0.3)
        assert got == pytest.approx(cloud_heading_offset_numpy(yaw, w, 0.3), abs=1e-12)
        assert abs(got) <= np.pi
        assert np.cos(got - (centre - 0.3)) > 0.99  # the cloud's centre, seen from the reference


def test_the_reopened_heading_is_an_option_and_keeps_the_diagnosed_30_m_run():
    """docs/filters.md 14: configs/zhou2017.yaml's area A 30 m cell, run 3 (lost in results/zhou2017 before 14.2): a
    fix turns the KF's heading 77 degrees off while the cloud's heading stays within degrees of the truth; with
    ``filter.loose_reopen_heading: cloud`` (the default since 14.2) the reopened KF takes the cloud's heading and the
    run ends within metres, on the same vehicle data and filter seed (those of the cell before 14.2)."""
    assert Scenario().filter.loose_reopen_heading == "cloud"
    assert "loose_reopen_heading" not in str(Scenario(filter={"loose_reopen_heading": "navigation"}).identity())
    assert Scenario(filter={"loose_reopen_heading": "navigation"}).cell_key() != Scenario().cell_key()
    with pytest.raises(ValidationError, match="loose_reopen_heading"):
        Scenario(filter={"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
                         "loose_fix_fit_one_wild_beam": False, "loose_reopen_heading": "cloud"})
    sweep = load_sweep("configs/zhou2017.yaml")
    sc = _with_filter(sweep.cells[2].scenario, loose_reopen_heading="navigation",
                      loose_reopen_position="prior", **LATER_NEUTRAL)  # the keys of the test's writing
    assert (sc.area, sc.map_resolution_m, sc.particles) == ("A", 30, 3000)
    vehicle = simulate_vehicle(sc, keyed_vehicle_seed(sweep.spec.seed, sc.pairing_key(), 3))
    fseed = keyed_filter_seed(sweep.spec.seed, sc.cell_key(), get("loose-dvl").seed_id, 3)
    runs = {name: run_method(s, "loose-dvl", vehicle,
                             np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key)).metrics
            for name, s in (("defaults", sc), ("cloud", _with_filter(sc, loose_reopen_heading="cloud")))}
    assert runs["defaults"]["final_horizontal_error_m"] > 100.0
    assert runs["cloud"]["final_horizontal_error_m"] < 10.0


def test_the_reopened_position_is_an_option_and_keeps_the_diagnosed_area_a_run():
    """docs/filters.md 15: area A at the defaults (``configs/methods.yaml``'s cell, root seed 14140014) with 2000
    particles, run 8 (lost in section 7.5's equal-time runs): the KF's position drifts about 190 m while its heading
    is 37 degrees off; the reopened KF takes the cloud's heading, but its initial position variance cannot reach the
    fix, so every later fix is rejected. With ``filter.loose_reopen_position: fix`` such a fix sets the position and
    the run ends within metres, on the same vehicle data and filter seed."""
    assert Scenario().filter.loose_reopen_position == "fix"  # the default since 15.1
    # prior is neutral: the keys from before the option
    assert "loose_reopen_position" not in str(Scenario(filter={"loose_reopen_position": "prior"}).identity())
    assert Scenario(filter={"loose_reopen_position": "prior"}).cell_key() != Scenario().cell_key()
    with pytest.raises(ValidationError, match="loose_reopen_position"):
        Scenario(filter={"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
                         "loose_fix_fit_one_wild_beam": False, "loose_reopen_heading": "navigation",
                         "loose_reopen_position": "prior",
                         "loose_reopen_position": "fix"})
    root, area = 14140014, {"terrain": {"kind": "synthetic", "seed": 1}, "area": "A", "map_resolution_m": 10,
                            "noise_m": 1.0, "sampling_time_s": 1, "particles": 3000}
    vehicle = simulate_vehicle(Scenario(**area), keyed_vehicle_seed(root, Scenario(**area).pairing_key(), 8))
    sc = Scenario(**{**area, "particles": 2000,
                     "filter": {"loose_reopen_position": "prior", **LATER_NEUTRAL}})  # its writing's keys
    fseed = keyed_filter_seed(root, sc.cell_key(), get("loose-dvl").seed_id, 8)
    runs = {name: run_method(s, "loose-dvl", vehicle,
                             np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key)).metrics
            for name, s in (("defaults", sc), ("fix", _with_filter(sc, loose_reopen_position="fix")))}
    assert runs["defaults"]["final_horizontal_error_m"] > 100.0
    assert abs(runs["defaults"]["final_heading_error_deg"]) < 5.0  # the heading is right: the position is what is lost
    assert runs["fix"]["final_horizontal_error_m"] < 10.0


def test_correlated_fixes_are_the_default_and_widen_the_kalman_covariance():
    """docs/filters.md 16: a fix error correlated over ``filter.loose_fix_correlation_s`` (40 s, the default since
    16.3; 0, independent fixes, is neutral and the literal profile's) scales each fix's covariance in a KF update by
    (1 + r) / (1 - r), r = exp(-interval / time constant). On the same vehicle data and filter seed the KF then
    reports a larger position variance once fixes arrive."""
    import math

    from tanbench.filters.loose import fix_covariance_scale

    assert Scenario().filter.loose_fix_correlation_s == 40.0
    assert "loose_fix_correlation_s" not in str(Scenario(filter={"loose_fix_correlation_s": 0.0}).identity())
    assert Scenario(filter={"loose_fix_correlation_s": 0.0}).cell_key() != Scenario().cell_key()
    with pytest.raises(ValidationError, match="loose_fix_correlation_s"):
        Scenario(filter={"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
                         "loose_fix_fit_one_wild_beam": False, "loose_reopen_heading": "navigation",
                         "loose_reopen_position": "prior"})
    assert fix_covariance_scale(10.0, 0.0) == 1.0
    r = math.exp(-0.25)
    assert fix_covariance_scale(10.0, 40.0) == pytest.approx((1 + r) / (1 - r)) and fix_covariance_scale(10.0, 40.0) > 8
    sc = Scenario(area="B", duration_s=400.0)
    ss = np.random.SeedSequence([16, 3])
    vehicle = simulate_vehicle(sc, ss.spawn(1)[0])
    fseed = ss.spawn(2)[1]
    late = {}
    for tau in (0.0, 40.0):
        out = run_method(_with_filter(sc, loose_fix_correlation_s=tau), "loose-dvl", vehicle,
                         np.random.SeedSequence(fseed.entropy, spawn_key=fseed.spawn_key))
        t = np.asarray(out.series["t"])
        var = np.asarray(out.series["var_e"]) + np.asarray(out.series["var_n"])
        assert out.metrics["fixes_accepted"] >= 10
        late[tau] = var[t >= 200].mean()
    assert late[40.0] > 2.0 * late[0.0]


def test_heading_offsets_off_names_every_option_to_change_in_one_error():
    """``filter.loose_heading_offsets: false`` with today's defaults: one error names every option that acts only with
    heading offsets and the value each must take, so that one edit of the sweep file mends it."""
    with pytest.raises(ValidationError) as caught:
        Scenario(filter={"loose_heading_offsets": False})
    text = str(caught.value)
    for name, value in (("loose_bias_gate_sigma", "null"), ("loose_fix_shape", "null"),
                        ("loose_fix_fit_one_wild_beam", "false"), ("loose_reopen_heading", "navigation"),
                        ("loose_reopen_position", "prior"), ("loose_fix_correlation_s", "0.0")):
        assert f"{name}: {value}" in text
    fixed = {"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
             "loose_fix_fit_one_wild_beam": False, "loose_reopen_heading": "navigation",
             "loose_reopen_position": "prior", "loose_fix_correlation_s": 0.0}
    assert not Scenario(filter=fixed).filter.loose_heading_offsets
