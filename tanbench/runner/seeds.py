"""Random streams of a sweep: one root ``SeedSequence``, keyed by spec, never by position.

* the vehicle data of run r of a cell comes from (root, pairing key, r): every cell with
  the same world (terrain, trajectory, sensors, initial errors; world faults aside, so a
  fault is measured on the fault-free cell's runs) and every method share it, so comparisons across methods, particle counts, map resolutions, noise levels or
  sampling times are paired (common random numbers);
* the filter noise of a method comes from (root, cell key, method, r).

A run's result thus depends only on its spec and these seeds, whatever the worker
count, executor or order of execution.
"""

from __future__ import annotations

import numpy as np

from tanbench.config import Scenario
from tanbench.methods.registry import get

VEHICLE_STREAM = 1
FILTER_STREAM = 2


def _key_int(hex_key: str) -> int:
    return int(hex_key, 16)


def vehicle_seed(root: int, scenario: Scenario, run: int) -> np.random.SeedSequence:
    """The seed of run ``run``'s simulated vehicle data."""
    return keyed_vehicle_seed(root, scenario.pairing_key(), run)


def filter_seed(root: int, scenario: Scenario, method: str, run: int) -> np.random.SeedSequence:
    """The seed of ``method``'s filter noise in run ``run`` of this cell (its registry ``seed_id``)."""
    return keyed_filter_seed(root, scenario.cell_key(), get(method).seed_id, run)


def keyed_vehicle_seed(root: int, pairing_key: str, run: int) -> np.random.SeedSequence:
    """:func:`vehicle_seed` from the cell's pairing key (computed once per cell by a caller that needs many)."""
    return np.random.SeedSequence(root, spawn_key=(VEHICLE_STREAM, _key_int(pairing_key), run))


def keyed_filter_seed(root: int, cell_key: str, seed_id: int, run: int) -> np.random.SeedSequence:
    """:func:`filter_seed` from the cell key and the method's seed id."""
    return np.random.SeedSequence(root, spawn_key=(FILTER_STREAM, _key_int(cell_key), seed_id, run))


def seed_number(seed: np.random.SeedSequence) -> int:
    """A 63-bit integer that identifies a seed sequence's stream (for result tables)."""
    return int(seed.generate_state(1, np.uint64)[0] >> np.uint64(1))
