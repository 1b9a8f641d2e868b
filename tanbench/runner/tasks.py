"""The unit of work: one Monte Carlo run of one cell, every method on the same vehicle data.

``execute`` runs in a worker (a local process or a Dask worker). It never raises: a
failure of the simulation or of a method becomes rows with ``status="error"`` and the
error text, so one bad run never stops a sweep. A method that ends the process its own
way (``sys.exit``, ``os._exit``, raising ``KeyboardInterrupt``) fails the same way,
with what it did as the error: while a method runs, ``os._exit`` raises instead of
exiting (:func:`guard_exits`).
"""

from __future__ import annotations

import json
import os
import threading
import time
import traceback
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from tanbench.errors import TanbenchError, describe_exception
from tanbench.schema import METRIC_COLUMNS, SERIES_COLUMNS
from tanbench.config import Scenario
from tanbench.methods import get, run_method
from tanbench.runner.seeds import keyed_filter_seed, keyed_vehicle_seed, seed_number
from tanbench.simulation import simulate_vehicle


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
    """Rows (one per method), if asked each method's series as float32 arrays, and the code
    identity of each user method as the worker ran it (:meth:`MethodRecord.code_id`)."""

    cell_id: str
    run: int
    rows: list[dict]
    series: dict[str, dict[str, np.ndarray]]
    code: dict[str, str] = field(default_factory=dict)


class MethodEndedProcess(TanbenchError):
    """A method called ``os._exit`` or ``sys.exit``, or raised ``KeyboardInterrupt``: its run fails."""


class _ExitCalled(BaseException):
    """What ``os._exit`` raises while a method runs (a BaseException, like SystemExit)."""


_real_exit = os._exit
_running = threading.local()


def _guarded_exit(code: int = 0):
    if getattr(_running, "method", None):
        raise _ExitCalled(f"os._exit({code!r})")
    _real_exit(code)


def guard_exits() -> None:
    """Make ``os._exit`` raise while a method runs in this process (idempotent). Installed
    before any user method is imported, so ``from os import _exit`` gets it too."""
    os._exit = _guarded_exit


def _where(exc: BaseException) -> str:
    """' (at file.py:line)' of the last frame of ``exc``'s traceback outside this module."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if f.filename != __file__]
    return f" (at {os.path.basename(frames[-1].filename)}:{frames[-1].lineno})" if frames else ""


def run_guarded(method: str, call):
    """``call()`` with a method's ways of ending the process turned into its run's failure."""
    _running.method = method
    try:
        return call()
    except (SystemExit, KeyboardInterrupt, _ExitCalled) as exc:
        if isinstance(exc, _ExitCalled):
            what = f"called {exc}"
        elif isinstance(exc, SystemExit):
            what = f"called sys.exit({exc.code!r})"
        else:
            what = f"raised {type(exc).__name__}"
        raise MethodEndedProcess(f"method {method!r} {what}{_where(exc)}: a method cannot end the worker "
                                 f"process; raise an exception to fail its run") from None
    except Exception:
        raise
    except BaseException as exc:  # noqa: BLE001 - e.g. GeneratorExit, or the user's own BaseException subclass
        raise TanbenchError(f"method {method!r} raised {type(exc).__name__}: {exc}{_where(exc)} (a BaseException: "
                            f"raise an Exception to fail a run)") from None
    finally:
        _running.method = None


@lru_cache(maxsize=8)
def cell_scenario(scenario_json: str) -> tuple[Scenario, str, str]:
    """A task's cell: its (frozen) scenario, pairing key and cell key, built and hashed once per
    cell in a worker instead of once per task and method (the keys hash the resolved spec)."""
    scenario = Scenario(**json.loads(scenario_json))
    return scenario, scenario.pairing_key(), scenario.cell_key()


def execute(task: Task) -> TaskResult:
    """Simulate the run's vehicle data once and run every method on it."""
    guard_exits()
    scenario, pairing_key, cell_key = cell_scenario(task.scenario_json)
    # the seeds of runner.seeds.vehicle_seed / filter_seed, from the keys computed once per cell
    vseed = keyed_vehicle_seed(task.root_seed, pairing_key, task.run)
    base = {"cell_id": task.cell_id, "run": task.run, "seed": seed_number(vseed)}
    empty = {k: np.nan for k in METRIC_COLUMNS}
    rows, series, code = [], {}, {}
    started = time.perf_counter()
    try:
        vehicle = simulate_vehicle(scenario, vseed)
        vehicle_error = None
    except Exception as exc:  # noqa: BLE001 - recorded, not raised
        vehicle, vehicle_error = None, describe_exception(exc)
    sim_wall = time.perf_counter() - started
    for method in task.methods:
        row = {**base, "method": method}
        t0 = time.perf_counter()
        try:
            record = get(method)
            fseed = keyed_filter_seed(task.root_seed, cell_key, record.seed_id, task.run)
            code_id = record.code_id()
        except Exception as exc:  # noqa: BLE001 - a user method that no longer imports here
            rows.append({**row, "filter_seed": -1, **empty, "status": "error", "error": describe_exception(exc),
                         "wall_s": 0.0})
            continue
        if code_id is not None:
            code[method] = code_id
        row["filter_seed"] = seed_number(fseed)
        if vehicle_error is not None:
            rows.append({**row, **empty, "status": "error", "error": f"simulation: {vehicle_error}",
                         "wall_s": sim_wall})
            continue
        try:
            result = run_guarded(method, lambda: run_method(scenario, method, vehicle, fseed))
        except Exception as exc:  # noqa: BLE001
            rows.append({**row, **empty, "status": "error", "error": describe_exception(exc),
                         "wall_s": time.perf_counter() - t0})
            continue
        rows.append({**row, **result.metrics, "status": "ok", "error": "",
                     "wall_s": time.perf_counter() - t0 + sim_wall / len(task.methods)})
        if task.keep_series:
            with np.errstate(over="ignore"):  # beyond float32's range (a lost run's NEES): stored as inf, no warning
                series[method] = {k: np.asarray(result.series[k], dtype=np.float32) for k in SERIES_COLUMNS}
    return TaskResult(cell_id=task.cell_id, run=task.run, rows=rows, series=series, code=code)
