"""The unit of work: one Monte Carlo run of one cell, every method on the same vehicle data.

``execute`` runs in a worker (a local process or a Dask worker). It never raises: a
failure of the simulation or of a method becomes rows with ``status="error"`` and the
error text, so one bad run never stops a sweep.
"""

from __future__ import annotations

import json
import os
import time
import traceback
from dataclasses import dataclass

import numpy as np

from tanbench.schema import METRIC_COLUMNS, SERIES_COLUMNS


@dataclass(frozen=True)
class Task:
    """What a worker needs: the cell's resolved spec (JSON), the run index, methods, root seed."""

    cell_id: str
    scenario_json: str
    run: int
    methods: tuple[str, ...]
    root_seed: int
    keep_series: bool

    @property
    def key(self) -> tuple[str, int]:
        return (self.cell_id, self.run)


@dataclass
class TaskResult:
    """Rows (one per method) and, if asked, each method's series as float32 arrays."""

    cell_id: str
    run: int
    rows: list[dict]
    series: dict[str, dict[str, np.ndarray]]


def _describe(exc: BaseException) -> str:
    from tanbench.errors import TanbenchError

    if isinstance(exc, TanbenchError):
        return str(exc)
    last = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    where = f" (at {os.path.basename(last.filename)}:{last.lineno})" if last else ""
    return f"{type(exc).__name__}: {exc}{where}"


def execute(task: Task) -> TaskResult:
    """Simulate the run's vehicle data once and run every method on it."""
    from tanbench.config import Scenario
    from tanbench.methods import run_method
    from tanbench.runner.seeds import filter_seed, seed_number, vehicle_seed
    from tanbench.simulation import simulate_vehicle

    scenario = Scenario(**json.loads(task.scenario_json))
    vseed = vehicle_seed(task.root_seed, scenario, task.run)
    base = {"cell_id": task.cell_id, "run": task.run, "seed": seed_number(vseed)}
    empty = {k: np.nan for k in METRIC_COLUMNS}
    rows, series = [], {}
    started = time.perf_counter()
    try:
        vehicle = simulate_vehicle(scenario, vseed)
        vehicle_error = None
    except Exception as exc:  # noqa: BLE001 - recorded, not raised
        vehicle, vehicle_error = None, _describe(exc)
    sim_wall = time.perf_counter() - started
    for method in task.methods:
        row = {**base, "method": method}
        t0 = time.perf_counter()
        try:
            fseed = filter_seed(task.root_seed, scenario, method, task.run)
        except Exception as exc:  # noqa: BLE001 - a user method that no longer imports here
            rows.append({**row, "filter_seed": -1, **empty, "status": "error", "error": _describe(exc),
                         "wall_s": 0.0})
            continue
        row["filter_seed"] = seed_number(fseed)
        if vehicle_error is not None:
            rows.append({**row, **empty, "status": "error", "error": f"simulation: {vehicle_error}",
                         "wall_s": sim_wall})
            continue
        try:
            result = run_method(scenario, method, vehicle, fseed)
        except Exception as exc:  # noqa: BLE001
            rows.append({**row, **empty, "status": "error", "error": _describe(exc),
                         "wall_s": time.perf_counter() - t0})
            continue
        rows.append({**row, **result.metrics, "status": "ok", "error": "",
                     "wall_s": time.perf_counter() - t0 + sim_wall / len(task.methods)})
        if task.keep_series:
            series[method] = {k: np.asarray(result.series[k], dtype=np.float32) for k in SERIES_COLUMNS}
    return TaskResult(cell_id=task.cell_id, run=task.run, rows=rows, series=series)
