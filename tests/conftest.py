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
