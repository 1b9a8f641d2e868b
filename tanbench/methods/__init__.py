"""TAN methods: the registry, the plug-in contract, and running one method on one run.

``run_method`` is what the sweep engine calls: it builds the method's
:class:`~tanbench.methods.api.MethodContext` from the run's observations (never the
truth; read-only, in the method's own copies), runs the method, checks its output and
scores it (:mod:`tanbench.scoring`) against the bound its record names. ``run_estimates`` is its first half, which
``tanbench replay`` shares for recorded missions.
"""

from __future__ import annotations

import time

import numpy as np

from tanbench.bounds.pcrb import method_bound
from tanbench.methods.api import (MethodContext, MethodOutput, Updates, as_output, check_start_on_map,
                                  input_write_error, method_inputs, method_view, update_indices)
from tanbench.methods.registry import MethodRecord, get, names, register
from tanbench.scoring import score
from tanbench.terrain import navigation_map

__all__ = ["MethodContext", "MethodOutput", "MethodRecord", "Updates", "get", "names", "register",
           "run_method", "run_estimates", "method_context", "check_start_on_map", "update_indices"]


def method_context(scenario, name: str, vehicle, seed: np.random.SeedSequence, record=None,
                   nmap=None) -> MethodContext:
    """What method ``name`` is given for one run: observations, map, updates, rng, options.

    ``vehicle.obs`` are the observations, simulated or read from a mission log; ``nmap`` the
    navigation map (default: the scenario's, checked against the start of its track). Both
    reach the method read-only, in objects of its own.
    """
    record = record or get(name)
    if nmap is None:
        nmap = navigation_map(scenario.terrain, scenario.map_resolution_m)
        check_start_on_map(scenario, nmap)
    obs, nmap = method_inputs(vehicle.obs, nmap)
    return MethodContext(name=name, scenario=method_view(scenario), obs=obs, nmap=nmap,
                         updates=update_indices(scenario, obs), rng=np.random.default_rng(seed),
                         options=record.parse_options(scenario))


def run_estimates(scenario, name: str, vehicle, seed: np.random.SeedSequence, nmap=None):
    """Run method ``name`` on one run's observations: (its context, its checked output, its wall time).

    A method that writes into its (read-only) inputs fails with a one-line error naming it.
    """
    record = get(name)
    ctx = method_context(scenario, name, vehicle, seed, record, nmap)
    started = time.perf_counter()
    try:
        raw = record.run(ctx)
    except Exception as exc:  # noqa: BLE001 - re-raised, reworded when it is a write into the inputs
        reworded = input_write_error(name, exc)
        if reworded is None:
            raise
        raise reworded from None
    wall = time.perf_counter() - started
    return ctx, as_output(name, raw, ctx.updates.size), wall


def run_method(scenario, name: str, vehicle, seed: np.random.SeedSequence):
    """Run method ``name`` on one run's ``vehicle`` data with its filter ``seed``; score it."""
    ctx, out, wall = run_estimates(scenario, name, vehicle, seed)
    return score(scenario, vehicle, ctx.updates, out, wall, name, bound=method_bound(scenario, get(name).bound))
