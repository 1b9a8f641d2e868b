"""Running a sweep: validate, read what is stored, fan the tasks out, store each finished one.

The parent process owns the results directory: workers return their rows and series,
the parent writes one file per finished task (atomically), so killing a sweep at any
moment loses at most the tasks in flight, and re-running the same command resumes
(:mod:`tanbench.runner.resume` says what is done and what is stale). A worker process
that dies (``kill -9``, the out-of-memory killer) costs only the tasks it held: they are
not stored, and run again in new worker processes (or by the next rerun). When every
task is done, the series summary and the tables are rebuilt from what is stored for the
sweep's current cells.

The steps live in their own modules: :mod:`~tanbench.runner.validate` (``run``'s first
step), :mod:`~tanbench.runner.plan` (tasks and their cost), :mod:`~tanbench.runner.resume`
(the store, read once), :mod:`~tanbench.runner.executors` (where tasks run).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import queue
import sys
import time
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
from tqdm import tqdm

from tanbench import __version__, kernel_cache, store
from tanbench.config import flatten
from tanbench.errors import TanbenchError, describe_exception
from tanbench.runner.executors import check_scheduler_address, open_executor, warm_up, warm_up_side_by_side
from tanbench.runner.plan import (Plan, builtin_methods, cell_kernels, check_series_mode, compile_groups,
                                  compile_processes, cpu_load_now, machine_compile_seconds, make_plan, share_of_each)
from tanbench.runner.resume import ResumeState
from tanbench.runner.stop_requests import POLL_S, noted_stop_requests
from tanbench.runner.tasks import Task, TaskResult, cell_scenario, execute
from tanbench.runner.validate import check_output, validate_sweep
from tanbench.schema import METRIC_COLUMNS, rows_table
from tanbench.simulation import PRELOAD_WORLDS_MAX, noise_free_world
from tanbench.sweep import Sweep
from tanbench.terrain import sweep_truth_maps
from tanbench.results import build_outputs

MAX_POOL_STARTS = 3  # worker pools started for one session: the first, and two more after a worker died


@dataclass
class RunReport:
    """Counts and timings of a sweep run."""

    finished: int = 0
    failed_rows: int = 0
    skipped: int = 0
    wall_s: float = 0.0
    errors: list[str] = field(default_factory=list)
    interrupted: bool = False
    lost: int = 0  # tasks left unfinished because worker processes kept dying (nothing stored of them)
    lost_reason: str = ""
    tables: dict = field(default_factory=dict)  # the sweep's summary tables as written (none if interrupted)


def cell_columns(sweep: Sweep) -> dict[str, dict]:
    """Per cell: its tables and every scenario parameter as a flat column."""
    out = {}
    for cell in sweep.cells:
        out[cell.cell_id] = {"tables": ",".join(cell.tables), **flatten(cell.scenario.normalized())}
    return out


def _other_code_rows(result: TaskResult, expected: dict[str, str]) -> TaskResult:
    """The result with the rows of user methods whose worker ran other code than this process
    expects turned into failures (their runs would be stored under the wrong identity)."""
    wrong = {m for m, code in result.code.items() if expected.get(m) != code}
    if not wrong:
        return result
    rows = [r if r["method"] not in wrong else
            {**r, **{k: float("nan") for k in METRIC_COLUMNS}, "status": "error",
             "error": f"the worker ran other code of {r['method']} ({result.code[r['method']]}) than this "
                      f"process has ({expected.get(r['method'])}): give the workers the same version"}
            for r in result.rows]
    return TaskResult(result.cell_id, result.run, rows, {m: s for m, s in result.series.items() if m not in wrong},
                      {m: c for m, c in result.code.items() if m not in wrong})


@lru_cache(maxsize=1)
def _string_type() -> pa.DataType:
    """The Arrow type pandas' conversion gives a column of Python strings (large_string in
    newer pandas, string before)."""
    return pa.Table.from_pandas(pd.DataFrame({"s": ["x"]}), preserve_index=False).schema.field("s").type


def series_table(result: TaskResult) -> pa.Table:
    """A task's series as one Arrow table: columns run, method, then the series, the methods'
    rows one after the other. The table ``pa.Table.from_pandas`` makes of the frames
    ``{"run", "method", **series}`` concatenated (NaN stored as null as pandas' conversion
    does, the same types), without building them: the file written is the same."""
    items = list(result.series.items())
    keys = list(items[0][1])
    if any(list(s) != keys for _, s in items[1:]):  # methods with other series: pandas aligns them
        frames = [pd.DataFrame({"run": result.run, "method": m, **s}) for m, s in items]
        return pa.Table.from_pandas(pd.concat(frames, ignore_index=True), preserve_index=False)
    lengths = [len(next(iter(s.values()))) if s else 0 for _, s in items]
    columns = {"run": pa.array(np.full(sum(lengths), result.run, dtype=np.int64)),
               "method": pa.array(np.repeat(np.array([m for m, _ in items], dtype=object), lengths),
                                 _string_type())}
    for key in keys:
        columns[key] = pa.array(np.concatenate([np.asarray(s[key]) for _, s in items]), from_pandas=True)
    return pa.table(columns)


def store_result(result: TaskResult, plan: Plan, state: ResumeState, columns: dict, meta: dict,
                 full_series: bool, written: SeriesWritten | None = None) -> TaskResult:
    """Write a finished task's rows (and series) atomically, with what identifies them in the
    file's metadata: a file terrain's content hash and the user methods' code. Returns the
    result as stored; ``written`` keeps the series frame as written (for the summary)."""
    result = _other_code_rows(result, state.codes)
    out = plan.out
    if result.cell_id in state.terrain:
        meta = {**meta, store.TERRAIN_META: state.terrain[result.cell_id]}
    if result.code:
        meta = {**meta, store.CODE_META: result.code}
    if result.series:
        table = series_table(result)
        path = store.series_file(out, result.cell_id, result.run, full_series)
        store.write_table(table, path, meta, **store.TASK_SERIES)
        if written is not None:
            written.keep(path, table)
    # a recomputed run leaves no older series of itself under the other --series mode
    store.series_file(out, result.cell_id, result.run, not full_series).unlink(missing_ok=True)
    rows = [{"sweep": plan.sweep.name, **columns[result.cell_id],
             **{k: v for k, v in row.items() if k != "cell_id"}} for row in result.rows]
    path = store.run_file(out, result.cell_id, result.run)
    store.write_table(rows_table(rows), path, meta, **store.TASK_ROWS)
    if written is not None:
        written.keep_rows(path, rows, meta)
    return result


SERIES_KEPT_MAX_BYTES = 256 * 2**20  # series frames a session keeps in memory for the summary
RUN_VALUES_KEPT_MAX = 2_000_000  # run-row values a session keeps for merging its cells' files (~3,700 tasks of 3 methods)


class SeriesWritten:
    """The series tables this session wrote, by file, so that the series summary is built
    from memory instead of reading every file back (:func:`tanbench.results.build_outputs`
    reads only the others: stored by earlier sessions, or past :data:`SERIES_KEPT_MAX_BYTES`).
    A table is what its file holds: it converts to pandas as the file read back does."""

    def __init__(self, max_bytes: int = SERIES_KEPT_MAX_BYTES):
        self.tables: dict[Path, pa.Table] = {}
        self.room = max_bytes
        self.runs: dict[Path, tuple[list[dict], dict]] = {}
        self.run_values_room = RUN_VALUES_KEPT_MAX

    def keep(self, path: Path, table: pa.Table) -> None:
        self.tables.pop(path, None)
        if table.nbytes <= self.room:
            self.tables[path] = table
            self.room -= table.nbytes

    def keep_rows(self, path: Path, rows: list[dict], meta: dict) -> None:
        """Keep a task's run rows and file metadata as written, so that merging the cell's files
        (:func:`tanbench.store.compact_cells`) builds its table from them instead of reading it back
        (up to :data:`RUN_VALUES_KEPT_MAX` values)."""
        self.runs.pop(path, None)
        values = sum(len(row) for row in rows)
        if values <= self.run_values_room:
            self.runs[path] = (rows, json.loads(json.dumps(meta)))  # the metadata as the file reads it back
            self.run_values_room -= values


def _to_stderr(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def run_sweep(sweep: Sweep, out: Path, workers: int | None = None, scheduler: str | None = None,
              series: str = "summary", force: bool = False, progress: bool = True, echo=print,
              add: bool = False, note=_to_stderr) -> RunReport:
    """Run (or resume) ``sweep`` into ``out``; returns a :class:`RunReport`.

    ``note`` prints what the sweep will recompute and why (stderr by default).
    """
    check_series_mode(series)
    check_scheduler_address(scheduler)
    validate_sweep(sweep)
    check_output(sweep, out)
    created = not out.exists()
    store.check_writable(out)
    try:
        with store.directory_lock(out):  # one writer at a time
            return _run_into(sweep, out, workers, scheduler, series, force, progress, echo, add, note)
    except TanbenchError:
        if created:  # refused before anything was stored (e.g. a scheduler that does not answer): leave no trace
            try:
                out.rmdir()
            except OSError:
                pass
        raise


def _run_into(sweep: Sweep, out: Path, workers, scheduler, series, force, progress, echo, add, note) -> RunReport:
    """:func:`run_sweep` once ``out`` is checked and writable."""
    store.remove_stale_temporaries(out)
    state = ResumeState.read(sweep, out, series)
    for line in state.check(force=force, add=add):
        note(line)
    state.set_aside_damaged()
    plan = make_plan(sweep, out, state, workers, series, force=force)
    missing = state.missing_series(plan.tasks) if series != "none" and not force else 0
    if missing:
        note(f"note: {missing} stored run(s) have no series file here (deleted, run with --series none, or a "
             f"clone of committed results): recomputing them, so that the series summary covers every run")
    meta = store.provenance(sweep.text, sweep.name, sweep.spec.seed)
    todo = plan.todo
    if not todo:  # with tasks to run, sweep.yaml is written once the executor is up (a scheduler that
        store.write_text(sweep.text, out / "sweep.yaml")  # does not answer changes nothing stored)
    report = RunReport(skipped=len(plan.tasks) - len(todo))
    written = SeriesWritten()
    started = time.perf_counter()
    if todo:
        _execute(plan, state, todo, scheduler, meta, series == "full", progress, report, note, written)
    report.wall_s = time.perf_counter() - started
    log_session(out, report, plan, scheduler)
    if not report.interrupted:
        store.compact_cells(out, [c.cell_id for c in sweep.cells], written.runs)
        report.tables = build_outputs(out, sweep, series, written.tables)
    return report


def log_session(out: Path, report: RunReport, plan: Plan, scheduler) -> None:
    """Append this session's wall time and counts to ``DIR/sessions.jsonl`` (for reports)."""
    entry = {
        "started": (_dt.datetime.now(_dt.timezone.utc) - _dt.timedelta(seconds=report.wall_s)).isoformat(
            timespec="seconds"),
        "wall_s": round(report.wall_s, 2), "tasks_run": report.finished, "tasks_skipped": report.skipped,
        "failed_rows": report.failed_rows, "interrupted": report.interrupted, "sweep": plan.sweep.name,
        "runs": plan.sweep.spec.runs,
        "workers": plan.workers,
        "scheduler": scheduler or "local", "cpu_count": os.cpu_count(), "tanbench_version": __version__,
    }
    try:
        with open(out / "sessions.jsonl", "a") as fh:
            fh.write(json.dumps(entry) + "\n")
    except OSError:
        pass


def shared_inputs(sweep: Sweep) -> tuple[dict, dict]:
    """What every worker is given at start instead of building it again: the cells' truth
    maps (file and synthetic) and, for a sweep of at most ``PRELOAD_WORLDS_MAX`` worlds,
    their noise-free simulations (all built already by ``validate_worlds`` in this
    process). Identical to what a worker would build, so results do not change."""
    maps = sweep_truth_maps(c.scenario.terrain for c in sweep.cells)
    worlds = sorted({json.dumps(c.scenario.world_spec(), sort_keys=True) for c in sweep.cells})
    shared_worlds = {w: noise_free_world(w) for w in worlds} if len(worlds) <= PRELOAD_WORLDS_MAX else {}
    return maps, shared_worlds


def filter_variants(todo: list[Task]) -> list[str]:
    """One cell (its scenario JSON) per distinct ``filter`` block among ``todo``, in order of first
    appearance: a kernel compiles once per option that changes its argument types (e.g. the tight
    loop's Euler step), so warming up on the first cell only would leave the others to each worker."""
    by_filter = {}
    for cell in dict.fromkeys(task.scenario_json for task in todo):  # each cell parsed once, not each run
        by_filter.setdefault(json.dumps(json.loads(cell).get("filter"), sort_keys=True), cell)
    return list(by_filter.values())


def compile_kernels(plan: Plan, todo: list[Task], progress: bool, note, truth_maps: dict | None = None) -> None:
    """Compile the kernels the tasks ``todo`` run into numba's on-disk cache, unless it holds them
    (:func:`tanbench.kernel_cache.is_warm` of each method in each cell's variant,
    :func:`tanbench.runner.plan.cell_kernels`: the rule of ``plan``'s estimate too), so that the
    workers only load them (a progress bar at 0 % for a minute would look like a hang).
    One cell per distinct ``filter`` block (:func:`filter_variants`) that holds a cold kernel is warmed
    up: the first with up to one process per worker (at most the cores) compiling a group of the
    families new to the cache side by side (:func:`tanbench.runner.plan.compile_groups`,
    :func:`executors.warm_up_side_by_side`), then the others' cold methods in this process."""
    methods = builtin_methods(plan.sweep.spec.methods)
    cells = [(cell, cell_kernels(cell_scenario(cell)[0], methods)) for cell in filter_variants(todo)]
    kernels = list(dict.fromkeys(k for _, names in cells for k in names))
    cold = set(kernel_cache.cold_methods(kernels))
    if not cold:
        return
    processes = compile_processes(plan.workers)
    groups = compile_groups(kernels, processes)
    # the longest group's measured compile time, scaled to this machine's core, over the share of a core each
    # compiling process will get
    guess = machine_compile_seconds(kernels, processes=processes) / share_of_each(max(1, len(groups)), *cpu_load_now())
    if progress:
        side = f" in {len(groups)} processes" if len(groups) > 1 else ""
        note(f"compiling the numba kernels{side} (once per install or kernel code change; about {guess:.0f} s "
             f"on this machine now)...")
    started = time.perf_counter()
    jobs = [(cell, [kernel_cache.method_of(k) for k in names if k in cold]) for cell, names in cells
            if cold.intersection(names)]
    grouped = {m for g in groups for m in g}
    if groups:  # the families new to the cache
        warm_up_side_by_side(jobs[0][0], groups, truth_maps)
    jobs[0] = (jobs[0][0], [m for m in jobs[0][1] if m not in grouped])
    for cell, cold_methods in jobs:  # the other variants (e.g. the Euler step), in this process
        if cold_methods:
            warm_up(cell, cold_methods)
    if progress:
        note(f"compiled in {time.perf_counter() - started:.0f} s; starting the workers")


def _execute(plan: Plan, state: ResumeState, todo: list[Task], scheduler, meta, full_series, progress,
             report: RunReport, note, written: SeriesWritten | None = None) -> None:
    """Run ``todo`` on the executor, storing each finished task; tasks a dead worker took with it
    run again in a new pool (at most :data:`MAX_POOL_STARTS` pools), else are left to a rerun."""
    columns = cell_columns(plan.sweep)
    n_methods = len(plan.sweep.spec.methods)
    workers = min(plan.workers, len(todo)) if scheduler is None else plan.workers
    # longest first: the last tasks to start are the short ones, so no worker idles while
    # another finishes a long task at the end (results do not depend on the order)
    remaining = sorted(todo, key=plan.task_cost, reverse=True)
    # built or read here (validate_worlds did), shipped to the workers: they never read map
    # files nor synthesise a seafloor or a noise-free world again (shared_inputs)
    truth_maps, worlds = shared_inputs(plan.sweep)
    if scheduler in (None, "local-dask"):
        compile_kernels(plan, remaining, progress, note, truth_maps)
    bar = None

    def store_one(task_result) -> None:
        result = store_result(task_result, plan, state, columns, meta, full_series, written)
        failed = [r for r in result.rows if r["status"] != "ok"]
        report.failed_rows += len(failed)
        report.errors += [f"{r['cell_id']} run {r['run']} {r['method']}: {r['error']}" for r in failed]
        report.finished += 1
        bar.update(n_methods)

    with noted_stop_requests() as stop:
        try:
            for start in range(1, MAX_POOL_STARTS + 1):
                # the executor first: if it cannot start (a Dask address that does not answer), the
                # user sees its one error line and no half-drawn progress bar
                with open_executor(workers, scheduler, truth_maps, worlds, remaining[0].scenario_json,
                                   tuple(plan.sweep.spec.methods)) as handle:
                    store.write_text(plan.sweep.text, plan.out / "sweep.yaml")
                    # submitted before the bar is drawn: a forked pool starts its workers at the first submit,
                    # and the bar starts a thread (executors.local_context forks only a single-threaded process)
                    pending, finished = _submit(handle.executor, remaining)
                    if bar is None:
                        bar = tqdm(total=len(todo) * n_methods, unit="run", disable=not progress, file=sys.stderr,
                                   dynamic_ncols=True, smoothing=0.05,
                                   desc=f"{plan.sweep.name} on {handle.description}")
                    lost, reason = _collect(pending, finished, stop, store_one)
                    if stop.requested:
                        report.interrupted = True
                        handle.stop_now()
                        return
                remaining = sorted(lost, key=plan.task_cost, reverse=True)
                if not remaining:
                    return
                if start < MAX_POOL_STARTS:
                    note(f"note: a worker process ended abruptly ({reason}); the {len(remaining)} task(s) it left "
                         f"unfinished were not stored and run again in new worker processes")
            report.lost, report.lost_reason = len(remaining), reason
        finally:
            if bar is not None:
                bar.close()


def _submit(executor, tasks: list[Task]) -> tuple[dict, queue.SimpleQueue]:
    """Submit ``tasks``: (future -> task, the queue each future puts itself in when done, from the
    executor's thread), so that :func:`_collect` takes them one at a time, O(1) per wait however many
    are pending (``concurrent.futures.wait`` over 5000 pending futures took 5 ms per call)."""
    finished: queue.SimpleQueue = queue.SimpleQueue()
    pending = {}
    for task in tasks:
        future = executor.submit(execute, task)
        pending[future] = task
        future.add_done_callback(finished.put)
    return pending, finished


def _collect(pending: dict, finished: queue.SimpleQueue, stop, store_one) -> tuple[list[Task], str]:
    """Hand each finished task's result to ``store_one`` until none is pending or ``stop`` (a
    :class:`~tanbench.runner.stop_requests.StopRequest`) is set, seen within ``POLL_S``. Returns the
    tasks whose worker ended abruptly (not stored) and the first such reason."""
    lost, reason = [], ""
    while pending and not stop.requested:
        try:
            future = finished.get(timeout=POLL_S)
        except queue.Empty:
            continue
        task = pending.pop(future)
        failure = future.exception()  # execute never raises: this is the worker's end
        if failure is not None:
            lost.append(task)
            reason = reason or describe_exception(failure)
            continue
        store_one(future.result())
    return lost, reason
