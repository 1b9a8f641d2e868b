"""Running a sweep: validate, plan, fan out, store each finished task, summarise.

The parent process owns the results directory: workers return their rows and series,
the parent writes one file per finished task (atomically), so killing a sweep at any
moment loses at most the tasks in flight, and re-running the same command resumes:
tasks whose every row is stored with status "ok" are skipped (``--force`` recomputes).
When every task is done, the series summary and the tables are rebuilt from what is
stored for the sweep's current cells.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import types
import typing
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
from pydantic import BaseModel

from tanbench.config import Scenario, flatten
from tanbench.errors import TanbenchError
from tanbench.runner import store
from tanbench.runner.sweep import Sweep
from tanbench.runner.tasks import Task, TaskResult, execute

SERIES_MODES = ("none", "summary", "full")
# rough single-core cost of one particle-step, ns (``tanbench bench`` measures it here)
NS_PER_PARTICLE_STEP = {"tight-dvl": 130.0, "tight-sbe": 100.0, "loose-dvl": 60.0}
SIMULATION_S = 0.1


@dataclass
class Plan:
    """What a sweep will do in a results directory."""

    sweep: Sweep
    out: Path
    tasks: list[Task]
    done: set
    workers: int

    @property
    def todo(self) -> list[Task]:
        return [t for t in self.tasks if t.key not in self.done]

    def estimate_seconds(self, tasks=None) -> float:
        tasks = self.todo if tasks is None else tasks
        total = sum(task_cost(t) for t in tasks)
        return total / max(1, min(self.workers, max(1, len(tasks))))


@dataclass
class RunReport:
    """Counts and timings of a sweep run."""

    finished: int = 0
    failed_rows: int = 0
    skipped: int = 0
    wall_s: float = 0.0
    errors: list[str] = field(default_factory=list)
    interrupted: bool = False


def task_cost(task: Task) -> float:
    """Estimated single-core seconds of a task (simulation + every method)."""
    s = json.loads(task.scenario_json)
    steps = (s.get("duration_s") or 1190.0) / s["sampling_time_s"]
    return SIMULATION_S + sum(NS_PER_PARTICLE_STEP[m] * 1e-9 * s["particles"] * steps for m in task.methods)


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def build_tasks(sweep: Sweep, keep_series: bool) -> list[Task]:
    """Every (cell, run) task of the sweep, run-major so early results cover every cell."""
    methods = tuple(sweep.spec.methods)
    cells = [(c.cell_id, json.dumps(c.scenario.normalized(), sort_keys=True)) for c in sweep.cells]
    return [Task(cell_id, spec, run, methods, sweep.spec.seed, keep_series)
            for run in range(sweep.spec.runs) for cell_id, spec in cells]


def validate_worlds(sweep: Sweep) -> None:
    """Check every cell against its terrain: maps, track, sonar and initial uncertainty."""
    from tanbench.filters.run import check_start_on_map
    from tanbench.simulation import noise_free_world
    from tanbench.terrain import navigation_map

    seen = set()
    for cell in sweep.cells:
        sc = cell.scenario
        varied = ', '.join(f'{k}={v}' for k, v in cell.varied.items()) or 'defaults'
        label = f"{sweep.path or sweep.name}: cell {cell.cell_id} ({varied})"
        try:
            world = json.dumps(sc.world_spec(), sort_keys=True)
            if world not in seen:
                noise_free_world(world)
                seen.add(world)
            nmap = navigation_map(sc.terrain, sc.map_resolution_m)
            check_start_on_map(sc, nmap)
        except ValueError as exc:
            raise TanbenchError(f"{label}: {exc}") from None
        except TanbenchError as exc:
            raise TanbenchError(f"{label}: {exc}") from None


def make_plan(sweep: Sweep, out: Path, workers: int | None = None, series: str = "summary") -> Plan:
    """The tasks of ``sweep`` and which of them ``out`` already holds."""
    if series not in SERIES_MODES:
        raise TanbenchError(f"--series must be one of {', '.join(SERIES_MODES)}")
    tasks = build_tasks(sweep, keep_series=series != "none")
    done = store.completed_tasks(out) if (out / "runs").is_dir() else set()
    return Plan(sweep=sweep, out=out, tasks=tasks, done=done, workers=workers or default_workers())


# Arrow types of a run row's columns. They are fixed (the scenario parameters' from the
# Scenario model's annotations), so every run file has the same schema whatever its
# values (a failed run's missing metrics, a parameter left at None) and
# ``pd.read_parquet(DIR / "runs")`` can read them together. Metrics not listed are float64.
# (``cell_id`` is not among them: it is the Hive partition, in the directory name)
ID_TYPES = {"sweep": pa.string(), "tables": pa.string(), "method": pa.string(),
            "run": pa.int64(), "seed": pa.int64(), "filter_seed": pa.int64()}
METRIC_TYPES = {"diverged": pa.bool_(), "reinitialisations": pa.int64()}
TAIL_TYPES = {"status": pa.string(), "error": pa.string(), "wall_s": pa.float64()}


def _arrow_type(annotation) -> pa.DataType:
    """bool, int64, float64, or string (plain for str, JSON text for tuples and mixed types)."""
    union = typing.get_origin(annotation) in (typing.Union, types.UnionType)
    kinds = set()
    for arg in typing.get_args(annotation) if union else (annotation,):
        if arg is type(None):
            continue
        if arg is bool:
            kinds.add("bool")
        elif arg is int:
            kinds.add("int")
        elif arg is float:
            kinds.add("float")
        elif arg is str or typing.get_origin(arg) is typing.Literal:
            kinds.add("str")
        else:
            kinds.add("json")
    if kinds == {"bool"}:
        return pa.bool_()
    if kinds == {"int"}:
        return pa.int64()
    if kinds and kinds <= {"int", "float"}:
        return pa.float64()
    return pa.string()


@lru_cache(maxsize=1)
def scenario_column_types() -> dict[str, pa.DataType]:
    """Every flattened scenario parameter (``filter.resampling``) and its Arrow type, in model order."""
    def walk(model, prefix):
        out = {}
        for name, info in model.model_fields.items():
            ann = info.annotation
            if isinstance(ann, type) and issubclass(ann, BaseModel):
                out.update(walk(ann, f"{prefix}{name}."))
            else:
                out[f"{prefix}{name}"] = _arrow_type(ann)
        return out

    return walk(Scenario, "")


def run_schema(rows: list[dict]) -> pa.Schema:
    """The schema of a run file: the known columns in a fixed order, then any other (inferred)."""
    from tanbench.filters.run import METRIC_COLUMNS

    metrics = {m: METRIC_TYPES.get(m, pa.float64()) for m in METRIC_COLUMNS}
    known = {**ID_TYPES, **scenario_column_types(), **metrics, **TAIL_TYPES}
    fields = [pa.field(k, t) for k, t in known.items()]
    for k in dict.fromkeys(k for row in rows for k in row):
        if k not in known:
            inferred = pa.array([row.get(k) for row in rows], from_pandas=True).type
            fields.append(pa.field(k, pa.float64() if pa.types.is_null(inferred) else inferred))
    return pa.schema(fields)


def _coerce(value, typ: pa.DataType):
    """A row value as the column's type takes it: NaN is null outside float columns, JSON for lists."""
    if value is None or (isinstance(value, float) and math.isnan(value) and not pa.types.is_floating(typ)):
        return None
    if pa.types.is_string(typ) and not isinstance(value, str):
        return json.dumps(value)
    return value


def rows_table(rows: list[dict]) -> pa.Table:
    """Run rows as an Arrow table of the fixed run-file schema."""
    schema = run_schema(rows)
    data = {f.name: [_coerce(row.get(f.name), f.type) for row in rows] for f in schema}
    return pa.Table.from_pydict(data, schema=schema)


def cell_columns(sweep: Sweep) -> dict[str, dict]:
    """Per cell: its tables and every scenario parameter as a flat column."""
    out = {}
    for cell in sweep.cells:
        out[cell.cell_id] = {"tables": ",".join(cell.tables), **flatten(cell.scenario.normalized())}
    return out


def store_result(result: TaskResult, plan: Plan, columns: dict, meta: dict, full_series: bool) -> None:
    """Write a finished task's rows (and series) atomically."""
    out = plan.out
    if result.series:
        frames = [pd.DataFrame({"run": result.run, "method": m, **s}) for m, s in result.series.items()]
        store.write_parquet(pd.concat(frames, ignore_index=True),
                            store.series_file(out, result.cell_id, result.run, full_series), meta)
    rows = [{"sweep": plan.sweep.name, **columns[result.cell_id],
             **{k: v for k, v in row.items() if k != "cell_id"}} for row in result.rows]
    store.write_table(rows_table(rows), store.run_file(out, result.cell_id, result.run), meta)


def run_sweep(sweep: Sweep, out: Path, workers: int | None = None, scheduler: str | None = None,
              series: str = "summary", force: bool = False, progress: bool = True, echo=print) -> RunReport:
    """Run (or resume) ``sweep`` into ``out``; returns a :class:`RunReport`."""
    from tanbench.results import build_outputs

    store.check_writable(out)
    store.remove_stale_temporaries(out)
    store.check_existing_schema(out)
    validate_worlds(sweep)
    if force:
        store.remove_cells(out, [c.cell_id for c in sweep.cells])
    plan = make_plan(sweep, out, workers, series)
    meta = store.provenance(sweep.text, sweep.name, sweep.spec.seed)
    store.write_text(sweep.text, out / "sweep.yaml")
    todo = plan.todo
    report = RunReport(skipped=len(plan.tasks) - len(todo))
    started = time.perf_counter()
    if todo:
        _execute(plan, todo, scheduler, meta, series == "full", progress, report, echo)
    report.wall_s = time.perf_counter() - started
    log_session(out, report, plan, scheduler)
    if not report.interrupted:
        store.compact_cells(out, [c.cell_id for c in sweep.cells])
        build_outputs(out, sweep, series)
    return report


def log_session(out: Path, report: "RunReport", plan: Plan, scheduler) -> None:
    """Append this session's wall time and counts to ``DIR/sessions.jsonl`` (for reports)."""
    import datetime as _dt

    from tanbench import __version__

    entry = {
        "started": (_dt.datetime.now(_dt.timezone.utc) - _dt.timedelta(seconds=report.wall_s)).isoformat(
            timespec="seconds"),
        "wall_s": round(report.wall_s, 2), "tasks_run": report.finished, "tasks_skipped": report.skipped,
        "failed_rows": report.failed_rows, "interrupted": report.interrupted, "workers": plan.workers,
        "scheduler": scheduler or "local", "cpu_count": os.cpu_count(), "tanbench_version": __version__,
    }
    try:
        with open(out / "sessions.jsonl", "a") as fh:
            fh.write(json.dumps(entry) + "\n")
    except OSError:
        pass


def _execute(plan: Plan, todo: list[Task], scheduler, meta, full_series, progress, report: RunReport, echo):
    from tqdm import tqdm

    from tanbench.runner.executors import open_executor

    columns = cell_columns(plan.sweep)
    n_methods = len(plan.sweep.spec.methods)
    workers = min(plan.workers, len(todo)) if scheduler is None else plan.workers
    # the executor first: if it cannot start (a Dask address that does not answer), the
    # user sees its one error line and no half-drawn progress bar
    with open_executor(workers, scheduler) as handle:
        bar = tqdm(total=len(todo) * n_methods, unit="run", disable=not progress, file=sys.stderr,
                   dynamic_ncols=True, smoothing=0.05, desc=f"{plan.sweep.name} on {handle.description}")
        pending = {}
        try:
            for task in todo:
                pending[handle.executor.submit(execute, task)] = task
            while pending:
                done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
                for fut in done:
                    task = pending.pop(fut)
                    try:
                        result = fut.result()
                    except Exception as exc:  # noqa: BLE001 - a crashed worker: record, keep going
                        result = _crashed(task, exc)
                    store_result(result, plan, columns, meta, full_series)
                    failed = [r for r in result.rows if r["status"] != "ok"]
                    report.failed_rows += len(failed)
                    report.errors += [f"{r['cell_id']} run {r['run']} {r['method']}: {r['error']}" for r in failed]
                    report.finished += 1
                    bar.update(n_methods)
        except KeyboardInterrupt:
            report.interrupted = True
            handle.stop_now()
        finally:
            bar.close()


def _crashed(task: Task, exc: BaseException) -> TaskResult:
    from tanbench.filters.run import METRIC_COLUMNS

    msg = f"worker failed: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
    rows = [{"cell_id": task.cell_id, "run": task.run, "seed": -1, "method": m, "filter_seed": -1,
             **{k: np.nan for k in METRIC_COLUMNS}, "status": "error", "error": msg, "wall_s": np.nan}
            for m in task.methods]
    return TaskResult(task.cell_id, task.run, rows, {})
