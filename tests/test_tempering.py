"""Progressive correction (filters/tempering.py, docs/filters.md section 5 item 4): its kernels
against their numpy references, and what the tight loop does with it."""

from __future__ import annotations

import numpy as np
import pytest

from filters_support import short_scenario
from tanbench.filters.tempering import (HALVINGS, tempered_ess, tempered_ess_numpy, tempering_fraction,
                                        tempering_fraction_numpy, tempering_of)


def _weights(seed, m=1001, carried=0.0):
    rng = np.random.default_rng(seed)
    logw = carried * rng.standard_normal(m)
    ll = -0.5 * (rng.standard_normal(m) * 6.0) ** 2
    return logw, ll


@pytest.mark.parametrize("carried", [0.0, 0.7])
@pytest.mark.parametrize("lam", [0.0, 1e-3, 0.05, 0.4, 1.0])
def test_tempered_ess_matches_numpy(carried, lam):
    logw, ll = _weights(1, carried=carried)
    work = np.empty_like(logw)
    assert tempered_ess(logw, ll, lam, work) == pytest.approx(tempered_ess_numpy(logw, ll, lam), rel=1e-12)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("remaining", [1.0, 0.37])
def test_tempering_fraction_matches_numpy_and_brackets_the_target(seed, remaining):
    logw, ll = _weights(seed, carried=0.3 * (seed % 2))
    m = logw.size
    work = np.empty_like(logw)
    target = 0.5 * m
    lam = tempering_fraction(logw, ll, remaining, target, work)
    assert lam == pytest.approx(tempering_fraction_numpy(logw, ll, remaining, target), abs=remaining * 2.0 ** -HALVINGS * 2)
    assert 0.0 < lam < remaining
    assert tempered_ess_numpy(logw, ll, lam) >= target
    assert tempered_ess_numpy(logw, ll, lam + remaining * 2.0 ** -(HALVINGS - 1)) < target


def test_a_weak_update_is_one_stage():
    logw, ll = _weights(3)
    ll *= 1e-4
    assert tempering_fraction(logw, ll, 1.0, 0.5 * ll.size, np.empty_like(ll)) == 1.0


def test_off_is_one_stage_and_the_stages_always_resample():
    from tanbench.config import FilterSpec
    from tanbench.filters.resample import Resampling

    rs = Resampling(0, 0.5, 3, np.array([0, 1]), 0.5, 0.0)
    off = tempering_of(FilterSpec(), rs)
    assert off.stages == 1
    on = tempering_of(FilterSpec(tempering_ess=0.5, tempering_stages=5), rs)
    assert on.stages == 5 and on.ess_fraction == 0.5 and on.rs.ess_threshold > 1.0
    assert on.rs.kind == rs.kind and on.rs.size == rs.size


def test_navigation_distances_are_refused():
    from tanbench.config import FilterSpec

    with pytest.raises(ValueError, match="tempering_ess above 0 needs filter.distance_innovation"):
        FilterSpec(tempering_ess=0.5, distance_innovation="navigation")
    FilterSpec(tempering_ess=0.5, distance_innovation="none")


def _run_tight(monkeypatch, name, filter_settings, particles=300, seed=5, duration_s=90.0):
    """One short tight run in area A; returns (the method's output, the loop's TightOutputs)."""
    from tanbench.methods import get, method_context
    from tanbench.methods import tight as tight_method
    from tanbench.runner.seeds import vehicle_seed
    from tanbench.simulation import simulate_vehicle

    made = []
    new = tight_method.new_tight_outputs
    monkeypatch.setattr(tight_method, "new_tight_outputs", lambda k: made.append(new(k)) or made[-1])
    scenario = short_scenario(duration_s=duration_s, particles=particles, filter=filter_settings)
    vehicle = simulate_vehicle(scenario, vehicle_seed(11, scenario, 0))
    out = get(name).run(method_context(scenario, name, vehicle, np.random.SeedSequence(seed, spawn_key=(0, 1)),
                                       get(name)))
    return out, made[-1]


@pytest.mark.parametrize("name", ["tight-dvl", "tight-sbe"])
def test_the_loop_applies_an_informative_update_in_stages(monkeypatch, name):
    """Off: one stage per update. On: the first update (a 150 m square weighed by the terrain) takes
    several stages, never more than tempering_stages, and an update that ended before the last stage
    keeps at least the target's effective particles."""
    _, off = _run_tight(monkeypatch, name, {})
    assert np.all(off.stages == 1)
    out, on = _run_tight(monkeypatch, name, {"tempering_ess": 0.5, "tempering_stages": 6})
    assert on.stages[0] > 1 and on.stages.max() <= 6
    early = on.stages < 6
    assert np.all(on.ess[early] >= 0.5 * 300 * (1 - 1e-9))
    assert off.ess[0] < 0.5 * 300
    assert np.all(np.isfinite(out.east)) and np.all(np.isfinite(out.north))


def test_the_stage_limit_holds(monkeypatch):
    _, on = _run_tight(monkeypatch, "tight-dvl", {"tempering_ess": 0.9, "tempering_stages": 2})
    assert on.stages.max() == 2 and on.stages.min() == 1


def test_the_plan_charges_tempering():
    from tanbench.config import Scenario
    from tanbench.methods import get
    from tanbench.methods.tight import TEMPERING_COST

    off, on = Scenario(), Scenario(filter={"tempering_ess": 0.5})
    for name in ("tight-dvl", "tight-sbe", "tight-mbe"):
        assert get(name).estimate_seconds(on) == pytest.approx(TEMPERING_COST * get(name).estimate_seconds(off))
    assert get("pmf-dvl").estimate_seconds(on) == get("pmf-dvl").estimate_seconds(off)


@pytest.mark.parametrize("name, settings", [
    ("tight-dvl", {"tight_regularisation": "shared"}),  # the shared kernel's stages (resample_and_regularise)
    ("tight-sbe", {"random_numbers": "numpy"}),
    ("tight-mbe", {}),
])
def test_tempering_runs_with_the_other_kernels(monkeypatch, name, settings):
    out, on = _run_tight(monkeypatch, name, {"tempering_ess": 0.5, **settings})
    assert on.stages[0] > 1 and on.stages.max() <= 8
    assert np.all(np.isfinite(out.east)) and np.all(np.isfinite(out.north))


def test_a_tempered_diverging_run_is_the_one_pass_run(monkeypatch):
    """With tempering, the loop that stops at its first search and runs again with it (tight_filter_loop) gives
    the run a single pass with the search's bundle gives: the stages draw the same numbers in both passes."""
    from test_global_recovery import _one_pass_with_the_search
    from tanbench.methods import tight as tight_method

    settings = {"tempering_ess": 0.5, "recovery_profile_updates": 30, "divergence_sigma": 0.5, "divergence_steps": 2}
    two, two_loop = _run_tight(monkeypatch, "tight-sbe", settings, duration_s=120.0)
    assert two.reinit[30:].sum() > 0
    with monkeypatch.context() as m:
        m.setattr(tight_method, "tight_filter_loop", _one_pass_with_the_search)
        one, one_loop = _run_tight(m, "tight-sbe", settings, duration_s=120.0)
    for field in ("est", "var", "ess", "reinit", "stages"):
        np.testing.assert_array_equal(getattr(two_loop, field), getattr(one_loop, field), err_msg=field)
