"""Shared fixtures: the default scenario, the paper's facts, the truth map and one simulated run.

Everything here is session-scoped and deterministic (fixed seeds), so the expensive
objects (a 3000 m x 1200 m synthetic seafloor, a 1190 s run at 100 Hz) are built once.
"""

from __future__ import annotations

import numpy as np
import pytest

from tanbench.config import Scenario
from tanbench.paperdata import scenario_facts

RUN_SEED = 2017  # the one fixed seed of the shared simulated run


@pytest.fixture(scope="session")
def run_seed() -> int:
    """The seed of the shared simulated run."""
    return RUN_SEED


@pytest.fixture(scope="session")
def facts() -> dict:
    """Zhou et al. 2017 facts as data (never retyped in the tests)."""
    return scenario_facts()


@pytest.fixture(scope="session")
def scenario() -> Scenario:
    """The default scenario: area A, paper layout seed 1, Table 1 sensors, 10 m map."""
    return Scenario()


@pytest.fixture(scope="session")
def paper_truth(scenario):
    """The paper layout's synthetic truth seafloor, seed 1 (cached by tanbench)."""
    from tanbench.terrain import truth_map

    return truth_map(scenario.terrain)


@pytest.fixture(scope="session")
def paper_run(scenario, run_seed):
    """One full-length (1190 s) simulated vehicle run of the default scenario, fixed seed."""
    from tanbench.simulation import simulate_vehicle

    return simulate_vehicle(scenario, np.random.SeedSequence(run_seed))


# the built-in methods' kernels, compiled before the test processes start in this many processes side by side,
# whole families in the groups `tanbench run` compiles on a cold cache (tanbench.runner.plan.compile_groups)
WARM_UP_PROCESSES = 2


def pytest_sessionstart(session):
    """With pytest-xdist (``-n``), compile the built-in methods' numba kernels into the on-disk cache once,
    in the controlling process, before the test processes start; each of them would otherwise compile
    the same kernels at the same time on an empty cache (a fresh clone). It is the warm-up
    ``tanbench run`` does before its workers start on a cold cache
    (:func:`tanbench.runner.executors.warm_up_side_by_side`, the groups of
    :func:`tanbench.runner.plan.compile_groups`), in two processes, and only if the cache does not hold
    them yet. Tests never depend on it: a test process loads what is cached and compiles whatever else
    it calls."""
    import time

    config = session.config
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    from tanbench import kernel_cache
    from tanbench.methods.registry import builtin_names
    from tanbench.runner.executors import warm_up_side_by_side
    from tanbench.runner.plan import compile_groups

    names = builtin_names()
    if not kernel_cache.cold_methods(names):
        return
    started = time.perf_counter()
    warm_up_side_by_side(None, compile_groups(names, WARM_UP_PROCESSES, cold=names))
    print(f"compiled the numba kernels once before the test processes started ({time.perf_counter() - started:.0f} s)")


# The test modules that took longest in a full run (pytest --durations summed per module, 3 December,
# from most to least), run first. pytest-xdist's default "load" distribution hands the tests out in
# collection order, in chunks that shrink as the run goes on: with these first, the last tests of the
# run are short ones and neither test process waits long for the other at the end. The order of the
# tests inside a module does not change; a module missing here (or renamed) only runs later.
SLOW_MODULES_FIRST = (
    "test_resume", "test_bad_input", "test_identity", "test_user_methods", "test_sweep_cli", "test_mutations",
    "test_filter_conformance", "test_method_conformance", "test_realism", "test_cluster_maps", "test_verdicts",
    "test_fitted_profile",
)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(session, config, items):
    """Run the modules of :data:`SLOW_MODULES_FIRST` first, in that order (a stable sort by module)."""
    rank = {name: i for i, name in enumerate(SLOW_MODULES_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.stem, len(rank)))
