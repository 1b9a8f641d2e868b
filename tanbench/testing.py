"""The public conformance check for TAN methods: ``check_method(method)``.

Every built-in method passes it, and a user calls it from their own test suite::

    from tanbench.testing import check_method

    def test_my_filter():
        check_method("my_package.my_filter:run")

It runs the method on short runs of a small scenario and checks, each failure an
``AssertionError`` naming the check:

1. the output contract: a ``MethodOutput`` (or dict) with finite east/north of one value
   per update, the right shapes and types, non-negative variances; scored metrics and
   series of the right lengths;
2. determinism: the same seed gives bit-identical results; another seed is allowed to differ;
3. executors: a run in a spawned worker process (as ``--workers N`` and Dask run it)
   equals the run in this process;
4. no shared input is mutated: the observations and the navigation map are unchanged
   after the run (methods of one run share them);
5. bad parameters are refused with one clear ``TanbenchError`` line: an unknown option
   (or any option, for a method that takes none).
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass, field

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.config import Scenario
from tanbench.methods import get, run_method
from tanbench.methods.api import update_indices
from tanbench.runner.executors import single_thread_environment
from tanbench.schema import METRIC_COLUMNS, SERIES_COLUMNS
from tanbench.simulation import simulate_vehicle
from tanbench.terrain import navigation_map

CHECK_SEED = 20261201


@dataclass
class ConformanceReport:
    """What ``check_method`` checked (every entry passed)."""

    method: str
    checks: list[str] = field(default_factory=list)


def default_check_scenario():
    """A short area-A scenario (90 s, 300 particles) with a small multibeam (8 beams, for the methods
    that weigh by it; it changes no other number of a run): a few seconds per method."""
    return Scenario(duration_s=90.0, particles=300, sensors={"multibeam_beams": 8})


def check_method(method: str, scenario=None, executors: bool = True) -> ConformanceReport:
    """Check that ``method`` (a registered name or ``package.module:function``) conforms."""
    record = get(method)
    scenario = scenario or default_check_scenario()
    report = ConformanceReport(method)
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(CHECK_SEED))
    before = copy.deepcopy(vehicle)
    nmap = _nav_map(scenario)
    map_before = nmap.z.copy()

    first = _run(run_method, scenario, method, vehicle, 1)
    _check_contract(first, vehicle, scenario, record)
    report.checks.append("output contract: shapes, types, finite estimates, metrics and series")

    assert_same_tree(vehicle, before, "observations/truth after the run")
    assert np.array_equal(nmap.z, map_before, equal_nan=True), f"{method}: the navigation map was modified"
    report.checks.append("no shared input (observations, navigation map) is mutated")

    again = _run(run_method, scenario, method, vehicle, 1)
    _assert_same_result(first, again, f"{method}: two runs with the same seed differ")
    report.checks.append("deterministic for a seed")

    if executors:
        remote = _run_in_worker(scenario, method)
        _assert_same_result(first, remote, f"{method}: a run in a spawned worker process differs from this process's")
        report.checks.append("identical in a worker process")

    _check_refuses_bad_options(scenario, method, record, vehicle)
    report.checks.append("bad options refused with one clear line")
    return report


def _nav_map(scenario):
    return navigation_map(scenario.terrain, scenario.map_resolution_m)


def _run(run_method, scenario, method, vehicle, seed):
    try:
        return run_method(scenario, method, vehicle, np.random.SeedSequence(seed))
    except TanbenchError as exc:
        raise AssertionError(f"{method}: {exc}") from None


def _check_contract(result, vehicle, scenario, record) -> None:
    k = update_indices(scenario, vehicle.obs).size
    missing = [m for m in METRIC_COLUMNS if m not in result.metrics]
    assert not missing, f"{record.name}: metrics missing {missing}"
    for key in ("final_horizontal_error_m", "mean_horizontal_error_m", "final_heading_error_deg"):
        assert math.isfinite(result.metrics[key]), f"{record.name}: metric {key} is not finite"
    for key in SERIES_COLUMNS:
        assert key in result.series, f"{record.name}: series {key} missing"
    for key, arr in result.series.items():
        assert np.shape(arr) == (k,), f"{record.name}: series {key} has shape {np.shape(arr)}, expected ({k},)"
    for key in ("est_e", "est_n", "est_u", "est_heading_deg"):
        assert np.isfinite(result.series[key]).all(), f"{record.name}: series {key} has NaN or inf"
    declared = [s for s in record.series if s not in result.series]
    assert not declared, f"{record.name}: declares series {declared} it does not return"


def _assert_same_result(a, b, message) -> None:
    assert a.metrics.keys() == b.metrics.keys(), message
    for key, value in a.metrics.items():
        if key == "filter_wall_s":
            continue
        other = b.metrics[key]
        same = (value == other) or (isinstance(value, float) and math.isnan(value) and math.isnan(other))
        assert same, f"{message} (metric {key}: {value!r} vs {other!r})"
    assert a.series.keys() == b.series.keys(), message
    for key in a.series:
        assert np.array_equal(np.asarray(a.series[key]), np.asarray(b.series[key]), equal_nan=True), \
            f"{message} (series {key})"


def assert_same_tree(a, b, path="vehicle") -> None:
    """Assert two dataclass / array / scalar trees are the same, bit for bit (NaN equal to NaN);
    a dataclass field declared ``compare=False`` is left out (a derived memory, not data)."""
    if hasattr(a, "__dataclass_fields__"):
        for f in a.__dataclass_fields__.values():
            if f.compare:  # not a derived memory such as Observations.shared_increments
                assert_same_tree(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, np.ndarray):
        assert np.array_equal(a, b, equal_nan=True), f"a method modified {path}"
    elif isinstance(a, float) and math.isnan(a):
        assert math.isnan(b), f"a method modified {path}"
    else:
        assert a == b, f"a method modified {path}"


def _worker_run(scenario_json: str, method: str):
    """In a spawned worker: simulate the same run and run the method (as the sweep engine does)."""
    scenario = Scenario(**json.loads(scenario_json))
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(CHECK_SEED))
    return run_method(scenario, method, vehicle, np.random.SeedSequence(1))


def _run_in_worker(scenario, method):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor


    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn"),
                             initializer=single_thread_environment) as pool:
        try:
            return pool.submit(_worker_run, scenario.model_dump_json(), method).result()
        except TanbenchError as exc:
            raise AssertionError(f"{method}: in a worker process: {exc}") from None


def _check_refuses_bad_options(scenario, method, record, vehicle) -> None:
    bad = scenario.model_copy(update={"method_options": {method: {"no_such_option_": 1}}})
    try:
        run_method(bad, method, vehicle, np.random.SeedSequence(1))
    except TanbenchError as exc:
        line = str(exc)
        assert "\n" not in line and ("no_such_option_" in line or "takes no options" in line), \
            f"{method}: an unknown option is refused, but the message does not name it: {line!r}"
        return
    raise AssertionError(f"{method}: an unknown option (method_options.{method}.no_such_option_) was accepted")
