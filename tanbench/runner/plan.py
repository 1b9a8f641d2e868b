"""Planning a sweep: its tasks, what each costs, and how long the rest will take here.

Linear in the sweep's size: a task's cost depends on its cell alone, so it is computed
once per cell (``tanbench plan`` of a 10,000-cell grid answers in seconds).
"""

from __future__ import annotations

import functools
import heapq
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from tanbench import kernel_cache
from tanbench.config import FilterSpec
from tanbench.errors import TanbenchError
from tanbench.filters.tight import loop_options, readings_of, tight_resampling_of
from tanbench.methods.loose import loop_kind as loose_loop_kind
from tanbench.methods.registry import builtin_names, get
from tanbench.runner.tasks import Task
from tanbench.sweep import Sweep

SERIES_MODES = ("none", "summary", "full")
# Time model of `tanbench plan` (calibration: docs/results.md, "How long a sweep takes").
# Costs on one uncontended core of the 2-core development machine; the estimate divides
# them by the share of a core each process gets at the current load average.
# (each method's cost per particle-step is in its registry record: tanbench.methods.registry)
SIMULATION_S = 0.022  # one run's vehicle data (1190 s at 100 Hz; the world's ray-cast sonar is per world)
# numba compiling a sweep's kernels on a cold on-disk cache: thread CPU seconds, one method after another
# in this order in one process on the 2-core dev machine: the run's simulation (strapdown navigation, IMU
# errors), then each method family's kernels (a family: the methods named FAMILY-sensor, which run the same
# kernels with the same types; the first, tight, includes the random numbers, resampling, propagation and
# likelihood passes the later ones reuse). A sweep compiles only the families it names.
# tight and loose until 5 Dec 2026 (replaced below): the values measured after issue 27's first compile cuts
# (3 Dec 2026, load 1.7-6: tight 54.0, loose after it 27.4, loose alone 55.7) times the ratio new/old of cold compiles of the code
# before and after the rare variants were made lazy, old and new compiled side by side on a loaded machine
# (3 Dec 2026, docs/speed.md "3 December, fifth session"): tight 0.77 (2 pairs: 0.768, 0.778), loose after
# tight 0.86 (0.829, 0.883), loose alone 0.81 (1 pair). pmf, mpf, ekf and tercom: measured again on 3 Dec 2026
# (seventh session, docs/speed.md) in one process on a fresh cache after the simulation, in this order, without
# the tight family: 15.32, 11.68, 7.78 and 4.67 s of thread CPU on that VM, over its speed factor 0.481.
# The simulation, tight and loose measured again on 5 Dec 2026 (nineteenth session, docs/speed.md; the likely cause
# of the change, not measured apart: the tight loop's tempering and adaptive-count paths, loose-dvl's gates): one
# process on an empty cache, thread CPU over the machine's speed factor (0.48-0.50): the simulation 7.6, 7.4, 7.0;
# tight 64.1, 62.4; loose after tight 29.7, 29.5; loose alone 64.4 (after the simulation).
COMPILE_SHARED_S = 7.3
COMPILE_FAMILY_S = {"tight": 63.3, "loose": 29.6, "pmf": 31.8, "mpf": 24.3, "ekf": 16.2, "tercom": 9.7}
# a family compiled in a process without the family whose kernels it reuses (a side-by-side helper):
# loose-dvl after the simulation only, on a fresh cache; what it shares with that family is the difference
# (shared_compile_s), which side-by-side processes split between them when they are staged (compile_stages)
COMPILE_REUSES = {"loose": "tight"}
COMPILE_ALONE_S = {"loose": 64.4}
COMPILE_OTHER_FAMILY_S = 30.0  # a built-in family not measured yet
# another variant of a family's kernels (:func:`kernel_variant`) compiled after one of them (its callees
# then load from the cache): the jitted loop once more, COMPILE_LOOP_S (also the default variant compiled
# after another), plus each option's own kernels, COMPILE_OPTION_S (the Euler step and its inputs, the
# shared resampling kernel, numpy's stream fills). Thread CPU s of one process on a fresh cache, 3 Dec 2026
# at load average 4.7-8.8 (docs/speed.md, "3 December, sixth session"), each scaled by the process's
# own ratio to the default family it compiled first (COMPILE_SHARED_S + tight, 47.0 s): the loop 4.7, 4.1
# and 4.5 s; the Euler step's variant 8.0 and 7.9, the shared kernel's 6.7 and 6.6, numpy's 7.6 (tight)
# and 8.0 (tight and loose, per family). A variant with several options counts each one's kernels once.
COMPILE_LOOP_S = 4.4
# loose-dvl's other loops (sixth session, the lead; thread CPU at load average 3.5-4.0, scaled as above by the
# process's own loose-dvl compiled alone, COMPILE_SHARED_S + COMPILE_ALONE_S = 50.4 s): the first one compiled
# after the default, fix-only 10.7 s and kalman 12.2 s (one process each), less the loop's COMPILE_LOOP_S; the
# second after it costs less (3.4 and 6.6 s: they share kernels), which this count overestimates
COMPILE_OPTION_S = {"euler": 3.5, "shared-resampling": 2.3, "numpy-rng": 3.4, "loose-fix-only": 6.3, "loose-kalman": 7.8}
COMPILE_OTHER_OPTION_S = 20.0  # an option not measured yet (a guess)
# a process loading a family's cached kernels (and the simulation's) before it compiles only another variant
# of it (a cache warmed by another sweep): thread CPU 1.30 and 1.33 s, load average 5.7-5.8, 3 Dec 2026
COMPILE_LOAD_S = 1.3
# a helper process starting (spawn, imports: 1.5-1.6 s CPU) and the parent loading the kernels it
# compiled afterwards (0.1 s), measured 3 Dec 2026
COMPILE_JOIN_S = 1.7
# a worker forked from the parent (its imports done) loading the cached kernels: `make bench`'s fixed costs,
# 0.42-0.48 s of CPU (5 Dec 2026); where workers are spawned (not Linux: executors.local_context) a worker also
# imports: 1.13-1.32 s there
WARM_START_S = 0.5
SPAWN_START_S = 1.3
# around the tasks: the parent's imports (0.81-0.86 s, `make bench`), validating the worlds (0.57 s) and merging
# and the tables (0.56 s; a py-spy profile of the CI-size sweep's parent), 5 Dec 2026
FIXED_S = 2.0
LARGE_SWEEP_CELLS = 2000  # `plan`, `validate` and `run` warn past this many cells


def build_tasks(sweep: Sweep, keep_series: bool) -> list[Task]:
    """Every (cell, run) task of the sweep, run-major so early results cover every cell."""
    methods = tuple(sweep.spec.methods)
    cells = [(c.cell_id, json.dumps(c.scenario.normalized(), sort_keys=True)) for c in sweep.cells]
    return [Task(cell_id, spec, run, methods, sweep.spec.seed, keep_series)
            for run in range(sweep.spec.runs) for cell_id, spec in cells]


def cell_costs(sweep: Sweep) -> dict[str, float]:
    """Estimated single-core seconds of one task (simulation + every method) of each cell."""
    records = [get(m) for m in sweep.spec.methods]
    return {c.cell_id: SIMULATION_S + sum(r.estimate_seconds(c.scenario) for r in records) for c in sweep.cells}


def builtin_methods(methods) -> list[str]:
    """The built-in methods among ``methods`` (the ones with kernels to compile and warm up)."""
    builtin = builtin_names()
    return [m for m in methods if m in builtin]


# the families whose jitted loops draw from filters.rng.loop_rng: its type follows filter.random_numbers
RNG_FAMILIES = ("tight", "loose")


def kernel_variant(method: str, scenario) -> str:
    """The variant of built-in ``method``'s kernels a cell of ``scenario`` compiles: "" for the default,
    else the options that give its jitted loop other argument types (numba compiles it once more for
    each), joined by "+": ``numpy-rng`` (``filter.random_numbers: numpy``:
    :func:`tanbench.filters.rng.loop_rng` gives the loop numpy's stream), and for the tight loop
    ``euler`` and ``shared-resampling``, from :func:`tanbench.filters.tight.loop_options`, which
    also decides whether :func:`tanbench.filters.tight.tight_filter_loop` passes ``euler_in`` and
    ``shared_rs`` as None (the Euler step and the shared kernel then compile); for loose-dvl a loop
    other than the default's, ``loose-kalman`` or ``loose-fix-only``
    (:func:`tanbench.methods.loose.loop_kind`, which also picks the loop it runs). Other options run
    in branches compiled either way. The global search (``filter.recovery: global``) is no variant: every
    tight cell compiles the loop without it, and a run compiles the search on its first need
    (:func:`tanbench.filters.tight.tight_filter_loop`)."""
    family = family_of(method)
    f = scenario.filter
    parts = []
    if family in RNG_FAMILIES and f.random_numbers != "fast":
        parts.append(f"{f.random_numbers}-rng")
    if family == "tight":
        euler_step, shared_resampling = loop_options(readings_of(f, scenario.sampling_time_s), tight_resampling_of(f))
        parts += ["euler"] * euler_step + ["shared-resampling"] * shared_resampling
    if family == "loose" and loose_loop_kind(f) != DEFAULT_LOOSE_LOOP:
        parts.append(f"loose-{loose_loop_kind(f)}")
    return "+".join(parts)


DEFAULT_LOOSE_LOOP = loose_loop_kind(FilterSpec())


def cell_kernels(scenario, methods) -> list[str]:
    """The kernel names (:func:`tanbench.kernel_cache.kernel_name`) a cell of ``scenario`` runs: each
    built-in method among ``methods`` with its :func:`kernel_variant`."""
    return [kernel_cache.kernel_name(m, kernel_variant(m, scenario)) for m in builtin_methods(methods)]


def sweep_kernels(scenarios, methods) -> list[str]:
    """The distinct kernel names of cells of these ``scenarios`` (:func:`cell_kernels`), in order of first appearance."""
    return list(dict.fromkeys(k for scenario in scenarios for k in cell_kernels(scenario, methods)))


def _cold_and_warm(kernels, cold) -> tuple[list[str], list[str]]:
    """The cold built-in ``kernels`` (those ``cold`` names, or else those the cache does not mark warm)
    and the warm ones (``kernels`` outside ``cold``, or else every kernel the cache marks warm)."""
    builtin = builtin_names()
    kernels = [k for k in kernels if kernel_cache.method_of(k) in builtin]
    if cold is None:
        return kernel_cache.cold_methods(kernels), kernel_cache.warm_kernels()
    cold = set(cold)
    return [k for k in kernels if k in cold], [k for k in kernels if k not in cold]


def compile_groups(methods, processes: int = 1, cold=None) -> list[list[str]]:
    """The methods of the families ``methods`` (kernel names, :func:`cell_kernels`) compile from nothing
    (a cold kernel, :func:`tanbench.kernel_cache.cold_methods` unless ``cold`` names them, of a family
    with no warm kernel) in at most ``processes`` groups compiled side by side, one process each: whole
    families (their methods share kernels), the longest first (``COMPILE_FAMILY_S``), each to the group
    that ends up shortest with it (:func:`group_compile_s`: a family without the one whose kernels it
    reuses costs more). The first group, the longest, is the parent's. The other variants of a family
    compile after (:func:`variant_compile_s`)."""
    cold, warm = _cold_and_warm(methods, cold)
    warm_families = {family_of(kernel_cache.method_of(k)) for k in warm}
    families: dict[str, list[str]] = {}
    for k in cold:
        m = kernel_cache.method_of(k)
        if family_of(m) not in warm_families and m not in families.get(family_of(m), []):
            families.setdefault(family_of(m), []).append(m)
    groups = [(set(), []) for _ in range(max(1, min(processes, len(families))))]
    for family in sorted(families, key=lambda f: -family_compile_s(f)):
        least = min(groups, key=lambda g: group_compile_s(g[0] | {family}))
        least[0].add(family)
        least[1].extend(families[family])
    return [g[1] for g in sorted(groups, key=lambda g: -group_compile_s(g[0])) if g[1]]


def variant_seconds(variant: str) -> float:
    """Seconds one more ``variant`` of a family's kernels compiles in, after another variant of the family:
    :data:`COMPILE_LOOP_S` plus each option's :data:`COMPILE_OPTION_S`."""
    options = variant.split("+") if variant else []
    return COMPILE_LOOP_S + sum(COMPILE_OPTION_S.get(o, COMPILE_OTHER_OPTION_S) for o in options)


def variant_compile_s(methods, cold=None) -> float:
    """Seconds the variants of ``methods`` (kernel names) take after :func:`compile_groups`' families: each
    cold (family, variant) pair (no method of the family has the variant warm) costs
    :func:`variant_seconds`, except the first variant of a family compiled from nothing (its
    ``COMPILE_FAMILY_S`` counts it)."""
    cold, warm = _cold_and_warm(methods, cold)
    warm_pairs = {(family_of(kernel_cache.method_of(k)), kernel_cache.variant_of(k)) for k in warm}
    fresh = {family_of(m) for g in compile_groups(methods, 1, cold) for m in g}
    pairs = dict.fromkeys((family_of(kernel_cache.method_of(k)), kernel_cache.variant_of(k)) for k in cold)
    first = {}
    for family, variant in pairs:
        first.setdefault(family, variant)
    return sum(variant_seconds(v) for f, v in pairs
               if (f, v) not in warm_pairs and not (f in fresh and first[f] == v))


def family_of(method: str) -> str:
    """A built-in method's family: its name without the sensor (``tight-dvl`` -> ``tight``)."""
    return method.rsplit("-", 1)[0]


def family_compile_s(family: str) -> float:
    return COMPILE_FAMILY_S.get(family, COMPILE_OTHER_FAMILY_S)


# runner/compile_stages.py's table: the kernels side-by-side compile processes share, split between the families
STAGES_TABLE = Path(__file__).with_name("compile_stages.json")


@functools.lru_cache(maxsize=1)
def load_stages_table() -> dict:
    """The recorded table of ``runner/compile_stages.py`` (empty if there is none; read once per process,
    ``compile_stages.write_table`` clears it)."""
    try:
        return json.loads(STAGES_TABLE.read_text())
    except (OSError, ValueError):
        return {}


def staged_groups(groups, kernels=None) -> bool:
    """Whether side-by-side compile ``groups`` (lists of method names, :func:`compile_groups`) are staged by the
    table: more than one group, every family of the table in a group of its own, and (given the compiled
    ``kernels``, names with their variants in the cells' order, :func:`cell_kernels`) each method of the table's
    families first in its default variant, the one the table's argument types are of (``compile_stages.shares_for``
    asks it of the first cell with cold kernels, which ``run`` warms up on)."""
    table = load_stages_table().get("shares", {})
    group_of = {family_of(m): i for i, g in enumerate(groups) for m in g}  # compile_groups keeps a family whole
    first = {}  # each method's first kernel: the variant of the cell run warms up on (its first with cold kernels)
    for k in kernels or ():
        first.setdefault(kernel_cache.method_of(k), kernel_cache.variant_of(k))
    defaults = all(not variant for m, variant in first.items() if family_of(m) in table)
    return (len(groups) > 1 and bool(table) and defaults and all(f in group_of for f in table)
            and len({group_of[f] for f in table}) == len(table))


def shared_compile_s(family: str) -> float:
    """Seconds of the kernels ``family`` shares with the family whose kernels it reuses (``COMPILE_REUSES``):
    what it costs alone beyond what it costs after that family."""
    return COMPILE_ALONE_S[family] - family_compile_s(family)


def group_compile_s(families, staged_apart=frozenset()) -> float:
    """Seconds one process takes to compile ``families`` after the simulation: each family's
    ``COMPILE_FAMILY_S``, or its ``COMPILE_ALONE_S`` where the family whose kernels it reuses is not
    in the group (it then compiles them itself). ``staged_apart``: the families other processes compile
    side by side with this one, staged (``runner/compile_stages.py``: each process first compiles its share of
    the kernels their families share, and loads the rest): half of what a family here shares with one of
    them is compiled there."""
    families, total = set(families), 0.0
    for f in families:
        alone = f in COMPILE_ALONE_S and COMPILE_REUSES[f] not in families
        total += COMPILE_ALONE_S[f] if alone else family_compile_s(f)
        if alone and COMPILE_REUSES[f] in staged_apart:
            total -= shared_compile_s(f) / 2  # the two processes split what they share (about: the table balances)
        total -= sum(shared_compile_s(g) / 2 for g in staged_apart if g in COMPILE_REUSES and COMPILE_REUSES[g] == f)
    return total


def compile_seconds(methods, cold=None, processes: int = 1) -> float:
    """Seconds numba takes to compile the kernels of ``methods`` (kernel names, :func:`cell_kernels`;
    the cold ones, :func:`tanbench.kernel_cache.cold_methods`, unless ``cold`` names them) on this
    machine idle, with ``processes`` processes compiling groups of families side by side
    (:func:`compile_groups`): the longest group's families (:func:`group_compile_s`, less what staged processes
    compile for one another, :func:`tanbench.runner.compile_stages.shares_for`) plus the shared
    simulation kernels (every process compiles those), plus starting the helpers and loading their
    kernels afterwards; then, in the parent, the families' other variants (:func:`variant_compile_s`;
    with no family to compile, after loading the cached ones, :data:`COMPILE_LOAD_S`).
    One process: the sum of all."""
    groups = compile_groups(methods, processes, cold)
    variants = variant_compile_s(methods, cold)
    if not groups:  # only variants: the parent loads their families first
        return COMPILE_LOAD_S + variants if variants else 0.0
    families = [{family_of(m) for m in g} for g in groups]
    # the families whose processes first compile a share of runner/compile_stages.py's table (none in one process)
    staged = set(load_stages_table().get("shares", {})) if staged_groups(groups, _cold_and_warm(methods, cold)[0]) \
        else set()
    longest = max(group_compile_s(fams, frozenset(staged - fams)) for fams in families)
    # the simulation's kernels are in the staged shares too: split between the staged processes
    simulation = COMPILE_SHARED_S / len(staged) if staged else COMPILE_SHARED_S
    return simulation + longest + (COMPILE_JOIN_S if len(groups) > 1 else 0.0) + variants


def machine_compile_seconds(methods, cold=None, processes: int = 1) -> float:
    """:func:`compile_seconds` on this machine's core: times :func:`machine_speed_factor`, which is
    measured (about 0.2 s, once per process) only when there is something to compile."""
    seconds = compile_seconds(methods, cold, processes)
    return seconds * machine_speed_factor() if seconds > 0 else 0.0


def size_warning(sweep: Sweep) -> str | None:
    """A warning line for a sweep past :data:`LARGE_SWEEP_CELLS` cells (None below)."""
    n = len(sweep.cells)
    if n <= LARGE_SWEEP_CELLS:
        return None
    return (f"warning: {sweep.path or sweep.name} expands to {n} cells (x {sweep.spec.runs} runs x "
            f"{len(sweep.spec.methods)} methods): a grid's values multiply; check that this is the design you mean")


@dataclass
class Plan:
    """What a sweep will do in a results directory."""

    sweep: Sweep
    out: Path
    tasks: list[Task]
    done: set
    workers: int
    costs: dict[str, float] = field(default_factory=dict)  # cell -> one task's single-core seconds

    @property
    def todo(self) -> list[Task]:
        return [t for t in self.tasks if t.key not in self.done]

    def task_cost(self, task: Task) -> float:
        return self.costs[task.cell_id]

    def kernels(self, tasks=None) -> list[str]:
        """The kernel names (:func:`cell_kernels`) of the cells of ``tasks`` (default: what is left to do),
        in the order ``run`` warms them up (its tasks' order: the costliest cell first)."""
        tasks = self.todo if tasks is None else tasks
        cells = {c.cell_id: c.scenario for c in self.sweep.cells}
        order = dict.fromkeys(t.cell_id for t in sorted(tasks, key=self.task_cost, reverse=True))
        return sweep_kernels((cells[c] for c in order), self.sweep.spec.methods)

    def estimate_seconds(self, tasks=None) -> float:
        """Wall seconds of running ``tasks`` (default: what is left to do), compilation included."""
        return sum(self.estimate_parts(tasks).values())

    def estimate_parts(self, tasks=None, load: float | None = None, warm: bool | None = None) -> dict[str, float]:
        """The estimate in parts: ``compile`` (or loading the cached kernels), ``tasks`` and ``fixed``.

        ``load`` is the machine's load average before the sweep starts (default: now) and
        ``warm`` whether numba's on-disk cache holds the kernels the tasks run (:meth:`kernels`;
        default: looked up per method and variant; False: none of them, True: all).
        """
        tasks = self.todo if tasks is None else tasks
        if not tasks:
            return {"compile": 0.0, "tasks": 0.0, "fixed": 0.0}
        load = current_load() if load is None else load
        kernels = self.kernels(tasks)
        workers = max(1, min(self.workers, len(tasks)))
        cores = default_workers()
        processes = compile_processes(self.workers)
        compile_s = machine_compile_seconds(kernels, None if warm is None else [] if warm else kernels, processes)
        share_one = min(1.0, cores / (load + 1))  # the parent alone (validation, tables)
        share_compile = min(1.0, cores / (load + processes))  # the processes compiling side by side
        share_all = min(1.0, cores / (load + workers))  # every worker busy
        start = compile_s / share_compile + worker_start_s() / share_all
        return {"compile": start,
                "tasks": longest_first_makespan([self.task_cost(t) for t in tasks], workers) / share_all,
                "fixed": FIXED_S / share_one}


def compile_processes(workers: int) -> int:
    """How many processes compile a cold cache's kernels side by side: the sweep's workers, at most the cores."""
    return max(1, min(workers, default_workers()))


def check_series_mode(series: str) -> None:
    if series not in SERIES_MODES:
        raise TanbenchError(f"--series must be one of {', '.join(SERIES_MODES)}")


def make_plan(sweep: Sweep, out: Path, state=None, workers: int | None = None, series: str = "summary",
              force: bool = False) -> Plan:
    """The tasks of ``sweep`` into ``out`` and which of them are done (none with ``force``).

    ``state`` (a :class:`tanbench.runner.resume.ResumeState`, None for an empty directory)
    says what is stored. Besides the sweep's runs 0..runs-1, stale stored runs outside that
    range are tasks too, so that nothing stale stays beside them.
    """
    check_series_mode(series)
    keep = series != "none"
    tasks = build_tasks(sweep, keep_series=keep)
    if state is not None:
        specs = {t.cell_id: t.scenario_json for t in tasks[:len(sweep.cells)]}
        tasks += [Task(cell, specs[cell], run, tuple(sweep.spec.methods), sweep.spec.seed, keep)
                  for cell, run in sorted(state.stale_runs_outside(sweep.spec.runs, force))]
    done = set() if force or state is None else state.done(tasks, need_series=keep)
    return Plan(sweep=sweep, out=out, tasks=tasks, done=done, workers=workers or default_workers(),
                costs=cell_costs(sweep))


def longest_first_makespan(costs, workers: int) -> float:
    """Seconds until the last of ``costs`` finishes when each goes, longest first, to the
    worker that frees up first (how ``run`` schedules them)."""
    loads = [0.0] * max(1, min(workers, len(costs)))
    for cost in sorted(costs, reverse=True):
        heapq.heappush(loads, heapq.heappop(loads) + cost)
    return max(loads) if costs else 0.0


# How fast this machine's core is against the one the COMPILE_* constants were measured on (docs/speed.md,
# "seventh session"): the least thread CPU of seven rounds of a fixed pure-Python workload (dicts, tuples, strings,
# the kind of work numba's typing and lowering do), over SPEED_REFERENCE_S. The reference was set once, from
# three cold compiles of configs/quick.yaml on the 3 December 2026 VM (an AMD EPYC with AVX-512; 28, 29 and 34 s
# against the constants' 52.1 s): that VM's probe time, 0.025 s (the median of 6), over 29 / 52.1.
SPEED_PROBE_ITEMS = 60_000
SPEED_REFERENCE_S = 0.0449


def _speed_probe_work(items: int) -> int:
    total = 0
    for i in range(items):
        d = {"a": i, "b": (i, i + 1), "c": [i] * 3}
        total += len(d["c"]) + d["b"][1] - d["a"] + len(f"v{i}")
    return total


def worker_start_s() -> float:
    """A worker's start with a warm cache: forked on Linux (:data:`WARM_START_S`), spawned elsewhere
    (:data:`SPAWN_START_S`), as ``executors.local_context`` starts them."""
    return WARM_START_S if sys.platform.startswith("linux") else SPAWN_START_S


@functools.lru_cache(maxsize=1)
def machine_speed_factor() -> float:
    """This machine's compile seconds per second of the COMPILE_* constants' machine, measured once per
    process (about 0.2 s): the probe's least thread CPU time of seven rounds over ``SPEED_REFERENCE_S``,
    kept within [0.25, 4]. Thread CPU, so it reads how fast a core is, not how much of one we get
    (that is :func:`cpu_load_now`)."""
    best = math.inf
    for _ in range(7):
        t0 = time.thread_time()
        _speed_probe_work(SPEED_PROBE_ITEMS)
        best = min(best, time.thread_time() - t0)
    return max(0.25, min(4.0, best / SPEED_REFERENCE_S))


def busy_jiffies() -> tuple[int, int] | None:
    """(busy, total) clock ticks of all CPUs so far, from the first line of Linux's ``/proc/stat``: busy is
    user, system, interrupt and steal time; niced time counts as free (niced work yields to ours), as do
    idle and I/O wait. None where there is no such file."""
    try:
        fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()
    except OSError:
        return None
    if len(fields) < 9 or fields[0] != "cpu":
        return None
    user, nice, system, idle, iowait, irq, softirq, steal = (int(v) for v in fields[1:9])
    busy = user + system + irq + softirq + steal
    return busy, busy + nice + idle + iowait


def cpu_load_probe(probe_s: float = 0.25) -> tuple[float, float | None]:
    """(the share of a core this process gets now, the cores other work keeps busy now), measured over one
    short busy loop: its thread CPU over wall time, and (Linux) the machine's busy ticks during it
    (:func:`busy_jiffies`) less the loop's own; None for the second where the system does not report it.
    Unlike the load average, both see that niced jobs yield (on 2 December 2026 at a load average of 19.5,
    mostly niced jobs, the compile step got far more than 2 / 20.5 of a core); the second also sees a busy
    process on a core the loop did not need (docs/speed.md, seventh session)."""
    j0 = busy_jiffies()
    c0, w0 = time.thread_time(), time.perf_counter()
    while time.perf_counter() - w0 < probe_s:
        pass
    share = max(0.02, min(1.0, (time.thread_time() - c0) / (time.perf_counter() - w0)))
    j1 = busy_jiffies()
    if j0 is None or j1 is None or j1[1] <= j0[1]:
        return share, None
    busy_cores = default_workers() * (j1[0] - j0[0]) / (j1[1] - j0[1])
    return share, max(0.0, busy_cores - share)


LOAD_PROBES = 3
LOAD_PROBE_GAP_S = 0.1


def cpu_load_now(probe_s: float = 0.25, probes: int = LOAD_PROBES) -> tuple[float, float | None]:
    """The least load of ``probes`` :func:`cpu_load_probe` loops, :data:`LOAD_PROBE_GAP_S` apart: the largest
    share and the fewest other busy cores any of them saw. Load that lasts keeps every probe from its core; a
    burst shorter than the probes is not load a compile of half a minute meets (one probe read 1.2 other busy
    cores on an idle machine before a compile of 21 s: docs/speed.md, fourteenth session)."""
    share, others = 0.0, None
    for i in range(max(1, probes)):
        if i:
            time.sleep(LOAD_PROBE_GAP_S)
        one, busy = cpu_load_probe(probe_s)
        share = max(share, one)
        if busy is not None:
            others = busy if others is None else min(others, busy)
    return share, others


# a probe that got at least this share got a whole core: on the idle 2-core machine the probe reads
# 0.9995-1.0 (3 December 2026), which the formula below would read as one other busy process
WHOLE_CORE_SHARE = 0.98


def share_of_each(processes: int, share_one: float, others: float | None = None) -> float:
    """The share of a core each of ``processes`` busy processes gets on ``c`` cores, shared with the other
    load: ``others`` busy cores when measured (:func:`cpu_load_now`), else the load the share one process
    gets now implies, ``c / share_one - 1`` processes (none if it got a whole core, :data:`WHOLE_CORE_SHARE`)."""
    cores = default_workers()
    if others is None:
        others = 0.0 if share_one >= WHOLE_CORE_SHARE else cores / share_one - 1.0
    return max(0.02, min(1.0, cores / (others + processes)))


def current_load() -> float:
    """The 1-minute load average (runnable processes), 0 where the system does not report it."""
    try:
        return os.getloadavg()[0]
    except (OSError, AttributeError):
        return 0.0


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))
