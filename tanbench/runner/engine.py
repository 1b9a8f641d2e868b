"""Running a sweep: validate, plan, fan out, store each finished task, summarise.

The parent process owns the results directory: workers return their rows and series,
the parent writes one file per finished task (atomically), so killing a sweep at any
moment loses at most the tasks in flight, and re-running the same command resumes:
tasks whose every row is stored with status "ok" are skipped (``--force`` recomputes the
sweep's tasks and keeps stored runs outside its range).
When every task is done, the series summary and the tables are rebuilt from what is
stored for the sweep's current cells.
"""

from __future__ import annotations

import json
import os
import re
import sys
import time
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from tanbench.config import Scenario, flatten
from tanbench.errors import TanbenchError
from tanbench import store
from tanbench.runner.sweep import Sweep
from tanbench.runner.tasks import Task, TaskResult, execute
from tanbench.schema import rows_table

SERIES_MODES = ("none", "summary", "full")
# Time model of `tanbench plan` (calibration: docs/results.md, "How long a sweep takes").
# Costs on one uncontended core of the 2-core development machine; the estimate divides
# them by the share of a core each process gets at the current load average.
# (each method's cost per particle-step is in its registry record: tanbench.methods.registry)
SIMULATION_S = 0.1  # one run's vehicle data (1190 s at 100 Hz, ray-cast sonar)
COMPILE_S = 127.0  # numba compiling every kernel (cold on-disk cache), one idle core of the 2-core dev machine (2 Dec 2026)
WARM_START_S = 1.5  # a worker process importing tanbench and loading the cached kernels
FIXED_S = 3.0  # validation, worlds, merging and tables around the tasks


@dataclass
class Plan:
    """What a sweep will do in a results directory."""

    sweep: Sweep
    out: Path
    tasks: list[Task]
    done: set
    workers: int
    terrain_hashes: dict = field(default_factory=dict)  # cell -> map files' content hash

    @property
    def todo(self) -> list[Task]:
        return [t for t in self.tasks if t.key not in self.done]

    def estimate_seconds(self, tasks=None) -> float:
        """Wall seconds of running ``tasks`` (default: what is left to do), compilation included."""
        return sum(self.estimate_parts(tasks).values())

    def estimate_parts(self, tasks=None, load: float | None = None, warm: bool | None = None) -> dict[str, float]:
        """The estimate in parts: ``compile`` (or loading the cached kernels), ``tasks`` and ``fixed``.

        ``load`` is the machine's load average before the sweep starts (default: now) and
        ``warm`` whether numba's on-disk cache holds the kernels (default: looked up).
        """
        tasks = self.todo if tasks is None else tasks
        if not tasks:
            return {"compile": 0.0, "tasks": 0.0, "fixed": 0.0}
        load = current_load() if load is None else load
        warm = numba_cache_is_warm() if warm is None else warm
        workers = max(1, min(self.workers, len(tasks)))
        cores = default_workers()
        share_one = min(1.0, cores / (load + 1))  # the parent alone (compiling)
        share_all = min(1.0, cores / (load + workers))  # every worker busy
        start = (0.0 if warm else COMPILE_S / share_one) + WARM_START_S / share_all
        return {"compile": start, "tasks": longest_first_makespan([task_cost(t) for t in tasks], workers) / share_all,
                "fixed": FIXED_S / share_one}


@dataclass
class RunReport:
    """Counts and timings of a sweep run."""

    finished: int = 0
    failed_rows: int = 0
    skipped: int = 0
    wall_s: float = 0.0
    errors: list[str] = field(default_factory=list)
    interrupted: bool = False


def longest_first_makespan(costs, workers: int) -> float:
    """Seconds until the last of ``costs`` finishes when each goes, longest first, to the
    worker that frees up first (how ``run`` schedules them)."""
    import heapq

    loads = [0.0] * max(1, min(workers, len(costs)))
    for cost in sorted(costs, reverse=True):
        heapq.heappush(loads, heapq.heappop(loads) + cost)
    return max(loads) if costs else 0.0


def task_cost(task: Task) -> float:
    """Estimated single-core seconds of a task (simulation + every method)."""
    from tanbench.methods.registry import get

    scenario = _scenario_of(task.scenario_json)
    return SIMULATION_S + sum(get(m).estimate_seconds(scenario) for m in task.methods)


@lru_cache(maxsize=256)
def _scenario_of(scenario_json: str) -> Scenario:
    return Scenario(**json.loads(scenario_json))


def current_load() -> float:
    """The 1-minute load average (runnable processes), 0 where the system does not report it."""
    try:
        return os.getloadavg()[0]
    except (OSError, AttributeError):
        return 0.0


def numba_cache_is_warm() -> bool:
    """Whether numba's on-disk cache holds this tanbench's kernels.

    Warm when the filters' module has cache index files (``__pycache__/<module>.*.nbi``)
    and no module's index is older than its source (numba rejects such an index and
    compiles again). Modules whose kernels are only called from other kernels have no
    index of their own and are not looked at (numba does not track them either).
    """
    cache_dir = os.environ.get("NUMBA_CACHE_DIR")
    newest = {}
    for source in jit_modules():
        indexes = list((source.parent / "__pycache__").glob(f"{source.stem}.*.nbi"))
        if cache_dir:
            indexes += list(Path(cache_dir).rglob(f"{source.stem}.*.nbi"))
        if indexes:
            newest[source] = max(p.stat().st_mtime for p in indexes)
            if newest[source] < source.stat().st_mtime:
                return False
    return any(source.name == "tight.py" for source in newest)


@lru_cache(maxsize=1)
def jit_modules() -> tuple[Path, ...]:
    """The tanbench source files that define cached numba kernels."""
    package = Path(__file__).resolve().parents[1]
    return tuple(p for p in sorted(package.rglob("*.py"))
                 if re.search(r"njit\(\s*cache\s*=\s*True", p.read_text(errors="ignore")))


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def build_tasks(sweep: Sweep, keep_series: bool) -> list[Task]:
    """Every (cell, run) task of the sweep, run-major so early results cover every cell."""
    methods = tuple(sweep.spec.methods)
    cells = [(c.cell_id, json.dumps(c.scenario.normalized(), sort_keys=True)) for c in sweep.cells]
    return [Task(cell_id, spec, run, methods, sweep.spec.seed, keep_series)
            for run in range(sweep.spec.runs) for cell_id, spec in cells]


def expected_seeds(tasks: list[Task]) -> dict:
    """Per task (cell_id, run): {method: (vehicle seed, filter seed)} as stored in its rows."""
    from tanbench.runner.seeds import filter_seed, seed_number, vehicle_seed

    out = {}
    for task in tasks:
        scenario = _scenario_of(task.scenario_json)
        vseed = seed_number(vehicle_seed(task.root_seed, scenario, task.run))
        out[task.key] = {m: (vseed, seed_number(filter_seed(task.root_seed, scenario, m, task.run)))
                         for m in task.methods}
    return out


def check_directory_owner(sweep: Sweep, out: Path, add: bool) -> None:
    """A results directory belongs to one sweep: refuse another sweep's name unless ``add``."""
    path = out / "sweep.yaml"
    if add or not path.exists() or not store.run_files(out):
        return
    try:
        import yaml

        previous = (yaml.safe_load(path.read_text()) or {}).get("name")
    except (OSError, ValueError, AttributeError):
        previous = None
    if previous is not None and previous != sweep.name:
        raise TanbenchError(f"{out} holds the results of sweep {previous!r}, not {sweep.name!r}: use another --out, "
                            f"or --add to add this sweep's cells to it")


def terrain_hashes(sweep: Sweep) -> dict[str, str]:
    """Per cell with a file terrain: the content hash of its map files (stored with its runs)."""
    from tanbench.terrain.files import terrain_content_hash

    out = {}
    for cell in sweep.cells:
        digest = terrain_content_hash(cell.scenario.terrain)
        if digest is not None:
            out[cell.cell_id] = digest
    return out


def changed_map_cells(sweep: Sweep, out: Path) -> list[str]:
    """Cells whose stored runs were made from map files with other content than today's."""
    current = terrain_hashes(sweep)
    stored = store.stored_terrain_hashes(out, current)
    return sorted(cell for cell, hashes in stored.items() if hashes - {current[cell]})


def check_not_stale(sweep: Sweep, out: Path, force: bool) -> None:
    """Refuse to mix stored runs that this sweep would compute differently (another root seed,
    edited map files)."""
    if force or not store.run_files(out):
        return
    edited = changed_map_cells(sweep, out)
    if edited:
        raise TanbenchError(
            f"{out} holds runs of {len(edited)} of this sweep's cells made from map files whose content has "
            f"changed since ({', '.join(edited)}); they would come out differently now: rerun with --force "
            f"to recompute those cells, or use another --out")
    stale = store.stale_rows(out, expected_seeds(build_tasks(sweep, keep_series=False)))
    if len(stale):
        cells = stale["cell_id"].nunique()
        raise TanbenchError(
            f"{out} holds {len(stale)} run(s) of {cells} of this sweep's cells made with other seeds (was the "
            f"sweep's root seed {sweep.spec.seed} changed?); they would come out differently now: rerun with "
            f"--force to recompute those cells, or use another --out")


def stale_cells(sweep: Sweep, out: Path) -> list[str]:
    """This sweep's cells with stored runs (any run index) made with other seeds than it would use."""
    if not store.run_files(out):
        return []
    rows = store.stored_rows(out, {c.cell_id for c in sweep.cells})
    if rows.empty:
        return []
    wide = sweep.with_runs(max(sweep.spec.runs, int(rows["run"].max()) + 1))
    stale = store.stale_rows(out, expected_seeds(build_tasks(wide, keep_series=False)))
    return sorted(set(stale["cell_id"]) | set(changed_map_cells(sweep, out)))


def validate_worlds(sweep: Sweep) -> None:
    """Check every cell against its terrain: maps, track, sonar and initial uncertainty."""
    from tanbench.methods.api import check_start_on_map
    from tanbench.simulation import motion_plan, noise_free_world
    from tanbench.terrain import navigation_map

    seen = set()
    for cell in sweep.cells:
        sc = cell.scenario
        varied = ', '.join(f'{k}={v}' for k, v in cell.varied.items()) or 'defaults'
        label = f"{sweep.path or sweep.name}: cell {cell.cell_id} ({varied})"
        try:
            length = motion_plan(sc).duration
            if sc.sampling_time_s > length + 1e-9:
                raise ValueError(f"sampling_time_s ({sc.sampling_time_s:g} s) is longer than the run "
                                 f"({length:g} s): the filter would not update after the start")
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


def make_plan(sweep: Sweep, out: Path, workers: int | None = None, series: str = "summary",
              force: bool = False) -> Plan:
    """The tasks of ``sweep`` and which of them ``out`` already holds (none with ``force``)."""
    if series not in SERIES_MODES:
        raise TanbenchError(f"--series must be one of {', '.join(SERIES_MODES)}")
    tasks = build_tasks(sweep, keep_series=series != "none")
    done = store.completed_tasks(out, expected_seeds(tasks)) if (out / "runs").is_dir() and not force else set()
    return Plan(sweep=sweep, out=out, tasks=tasks, done=done, workers=workers or default_workers(),
                terrain_hashes=terrain_hashes(sweep))


def cell_columns(sweep: Sweep) -> dict[str, dict]:
    """Per cell: its tables and every scenario parameter as a flat column."""
    out = {}
    for cell in sweep.cells:
        out[cell.cell_id] = {"tables": ",".join(cell.tables), **flatten(cell.scenario.normalized())}
    return out


def store_result(result: TaskResult, plan: Plan, columns: dict, meta: dict, full_series: bool) -> None:
    """Write a finished task's rows (and series) atomically; a file terrain's content hash
    goes into the metadata (``terrain_sha256``), for resume to notice edited maps."""
    out = plan.out
    if result.cell_id in plan.terrain_hashes:
        meta = {**meta, "terrain_sha256": plan.terrain_hashes[result.cell_id]}
    if result.series:
        frames = [pd.DataFrame({"run": result.run, "method": m, **s}) for m, s in result.series.items()]
        store.write_parquet(pd.concat(frames, ignore_index=True),
                            store.series_file(out, result.cell_id, result.run, full_series), meta)
    # a recomputed run (--force) leaves no older series of itself under the other --series mode
    store.series_file(out, result.cell_id, result.run, not full_series).unlink(missing_ok=True)
    rows = [{"sweep": plan.sweep.name, **columns[result.cell_id],
             **{k: v for k, v in row.items() if k != "cell_id"}} for row in result.rows]
    store.write_table(rows_table(rows), store.run_file(out, result.cell_id, result.run), meta)


def run_sweep(sweep: Sweep, out: Path, workers: int | None = None, scheduler: str | None = None,
              series: str = "summary", force: bool = False, progress: bool = True, echo=print,
              add: bool = False) -> RunReport:
    """Run (or resume) ``sweep`` into ``out``; returns a :class:`RunReport`."""
    from tanbench.results import build_outputs

    store.check_writable(out)
    store.remove_stale_temporaries(out)
    store.check_existing_schema(out)
    validate_worlds(sweep)
    check_directory_owner(sweep, out, add)
    check_not_stale(sweep, out, force)
    # --force recomputes the tasks of this sweep (runs 0..runs-1 of its cells) and nothing
    # else: each new result replaces its stored run when the cell is merged, and runs
    # outside the range (e.g. runs 1-2 after `--runs 1 --force` on a 3-run sweep) are kept,
    # unless they were made with other seeds: then the cell's stored runs are deleted, and said
    if force:
        stale = stale_cells(sweep, out)
        if stale:
            echo(f"--force: deleting every stored run of {len(stale)} cell(s) whose runs were made with other "
                 f"seeds or from edited map files: {', '.join(stale)}")
            store.remove_cells(out, stale)
    plan = make_plan(sweep, out, workers, series, force=force)
    meta = store.provenance(sweep.text, sweep.name, sweep.spec.seed)
    todo = plan.todo
    if not todo:  # with tasks to run, sweep.yaml is written once the executor is up (a scheduler that
        store.write_text(sweep.text, out / "sweep.yaml")  # does not answer changes nothing stored)
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


def shared_inputs(sweep: Sweep) -> tuple[dict, dict]:
    """What every worker is given at start instead of building it again: the cells' truth
    maps (file and synthetic) and, for a sweep of at most ``PRELOAD_WORLDS_MAX`` worlds,
    their noise-free simulations (all built already by ``validate_worlds`` in this
    process). Identical to what a worker would build, so results do not change."""
    from tanbench.simulation import PRELOAD_WORLDS_MAX, noise_free_world
    from tanbench.terrain import sweep_truth_maps

    maps = sweep_truth_maps(c.scenario.terrain for c in sweep.cells)
    worlds = sorted({json.dumps(c.scenario.world_spec(), sort_keys=True) for c in sweep.cells})
    shared_worlds = {w: noise_free_world(w) for w in worlds} if len(worlds) <= PRELOAD_WORLDS_MAX else {}
    return maps, shared_worlds


def _execute(plan: Plan, todo: list[Task], scheduler, meta, full_series, progress, report: RunReport, echo):
    from tqdm import tqdm

    from tanbench.runner.executors import open_executor

    from tanbench.runner.executors import warm_up

    columns = cell_columns(plan.sweep)
    n_methods = len(plan.sweep.spec.methods)
    workers = min(plan.workers, len(todo)) if scheduler is None else plan.workers
    # longest first: the last tasks to start are the short ones, so no worker idles while
    # another finishes a long task at the end (results do not depend on the order)
    todo = sorted(todo, key=task_cost, reverse=True)
    if scheduler in (None, "local-dask") and not numba_cache_is_warm():
        # compile once here, into numba's on-disk cache, so the workers only load it (a
        # progress bar at 0 % for a minute would look like a hang)
        guess = plan.estimate_parts(todo, warm=False)["compile"]
        if progress:
            print(f"compiling the numba kernels (once per install or code change; about {guess:.0f} s on this "
                  f"machine now)...", file=sys.stderr, flush=True)
        started = time.perf_counter()
        warm_up(todo[0].scenario_json)
        if progress:
            print(f"compiled in {time.perf_counter() - started:.0f} s; starting {workers} worker(s)",
                  file=sys.stderr, flush=True)
    # built or read here (validate_worlds did), shipped to the workers: they never read map
    # files nor synthesise a seafloor or a noise-free world again (shared_inputs)
    truth_maps, worlds = shared_inputs(plan.sweep)
    # the executor first: if it cannot start (a Dask address that does not answer), the
    # user sees its one error line and no half-drawn progress bar
    with open_executor(workers, scheduler, truth_maps, worlds, todo[0].scenario_json) as handle:
        store.write_text(plan.sweep.text, plan.out / "sweep.yaml")
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
    from tanbench.schema import METRIC_COLUMNS

    msg = f"worker failed: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
    rows = [{"cell_id": task.cell_id, "run": task.run, "seed": -1, "method": m, "filter_seed": -1,
             **{k: np.nan for k in METRIC_COLUMNS}, "status": "error", "error": msg, "wall_s": np.nan}
            for m in task.methods]
    return TaskResult(task.cell_id, task.run, rows, {})
