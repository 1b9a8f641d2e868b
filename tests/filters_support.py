"""Helpers shared by the filter test files (kernels, conformance, statistics).

Kept out of ``conftest.py`` (owned by the foundation tests): plain functions that the
filter test modules import explicitly. Everything is deterministic: seeds are fixed
constants here.
"""

from __future__ import annotations

import copy
import sys

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


# --------------------------------------------------------------------------------------
# the numpy references of whole loops (tests/test_*_reference*.py)
# --------------------------------------------------------------------------------------
JITTED_CALLED = "a jitted function was called from the numpy reference"


def copy_of_rng(rng):
    """An independent generator in the state of ``rng`` (fast words, Pcg64Stream or Generator)."""
    from tanbench.filters.rng import rng_state

    state = rng_state(rng)
    if isinstance(state, np.ndarray):
        return state
    g = np.random.Generator(np.random.PCG64())
    g.bit_generator.state = state
    return g


def same_rng_state(a, b) -> bool:
    """Whether two generators (as :func:`copy_of_rng` takes them) are in the same state."""
    from tanbench.filters.rng import rng_state

    sa, sb = rng_state(a), rng_state(b)
    return np.array_equal(sa, sb) if isinstance(sa, np.ndarray) else sa == sb


def forbid_jitted_calls(mp) -> int:
    """Replace every numba-jitted function a tanbench module holds by one that raises
    AssertionError(:data:`JITTED_CALLED`) (``mp``: a pytest monkeypatch): a reference that called one,
    directly or through a plain function, would fail. Returns how many were replaced."""
    from numba.core.dispatcher import Dispatcher

    def forbidden(*args, **kwargs):
        raise AssertionError(JITTED_CALLED)

    replaced = 0
    for modname, module in list(sys.modules.items()):
        if modname.startswith("tanbench") and module is not None:
            for attr, value in list(vars(module).items()):
                if isinstance(value, Dispatcher):
                    mp.setattr(module, attr, forbidden)
                    replaced += 1
    return replaced


def assert_close_by_column(name, a, b, rtol, floor=0.0):
    """``a`` against ``b`` (rows: updates or particles): integers exactly, floats within ``rtol`` of each
    column's largest magnitude plus ``floor`` (per column)."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, name
    if a.dtype.kind == "i":
        np.testing.assert_array_equal(a, b, err_msg=name)
        return
    a2, b2 = a.reshape(a.shape[0], -1), b.reshape(b.shape[0], -1)
    assert np.isfinite(a2).all() and np.isfinite(b2).all(), name
    scale = np.abs(b2).max(axis=0)
    bad = np.abs(a2 - b2) > rtol * scale + floor
    if bad.any():
        k, c = np.argwhere(bad)[0]
        raise AssertionError(f"{name}: first difference beyond {rtol:g} of the column's scale at row {k}, column {c}: "
                             f"{a2[k, c]!r} against the reference's {b2[k, c]!r} (scale {scale[c]:.3g})")
