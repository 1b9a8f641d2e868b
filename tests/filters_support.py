"""Helpers shared by the filter test files (kernels, conformance, statistics).

Kept out of ``conftest.py`` (owned by the foundation tests): plain functions that the
filter test modules import explicitly. Everything is deterministic: seeds are fixed
constants here.
"""

from __future__ import annotations

import copy

import numpy as np

from tanbench.config import Scenario

KERNEL_SEED = 20170601  # the random inputs of the kernel tests
VEHICLE_SEED = 4242  # the vehicle run whose increments/map feed the kernel tests
STAT_ROOT = 31337  # root entropy of the statistical Monte Carlo runs
FILTER_ROOT = 777  # root entropy of the statistical filter seeds

# the per-update series every method returns (run._score), and the method-specific ones
COMMON_SERIES = {
    "t", "est_e", "est_n", "est_u", "est_heading_deg", "truth_e", "truth_n", "truth_u",
    "truth_heading_deg", "nav_e", "nav_n", "nav_heading_deg", "east_error_m", "north_error_m",
    "horizontal_error_m", "heading_error_deg", "nav_horizontal_error_m", "ess", "reinit",
    "var_e", "var_n", "cov_en", "nees", "pcrb_horizontal_m", "pcrb_heading_deg",
}


def series_keys(method: str) -> set:
    """The series a method's scored run has: the common ones, var_u / var_heading for methods that
    estimate up / heading, and the record's own series."""
    from tanbench.methods.registry import get

    record = get(method)
    keys = COMMON_SERIES | set(record.series)
    if "up" in record.states:
        keys |= {"var_u"}
    if "heading" in record.states:
        keys |= {"var_heading"}
    return keys


# a small multibeam, so that the multibeam methods take part; it changes no other number of a run
SHORT_MULTIBEAM = {"multibeam_beams": 8}


def short_scenario(duration_s: float = 120.0, particles: int = 400, **overrides) -> Scenario:
    """A cheap area-A scenario with a small multibeam; nested overrides are given as dicts (``filter={...}``)."""
    overrides["sensors"] = {**SHORT_MULTIBEAM, **overrides.get("sensors", {})}
    return Scenario(duration_s=duration_s, particles=particles, **overrides)


def vehicle_seed(run: int, root: int = STAT_ROOT) -> np.random.SeedSequence:
    """Vehicle seed of Monte Carlo run ``run``: ``SeedSequence(root, spawn_key=(run,))``."""
    return np.random.SeedSequence(root, spawn_key=(run,))


def filter_seed(run: int, method_index: int, root: int = FILTER_ROOT) -> np.random.SeedSequence:
    """Filter seed of one method on run ``run``."""
    return np.random.SeedSequence(root, spawn_key=(run, method_index))


def snapshot(obj):
    """A deep copy of a VehicleData (or anything) to compare against after a run."""
    return copy.deepcopy(obj)


