"""Where tasks run: a local process pool or a Dask cluster, through one interface.

Both give a ``concurrent.futures.Executor``: the local one is a
``ProcessPoolExecutor`` (workers forked where that is safe, else spawned: :func:`local_context`);
the Dask one is ``Client.get_executor`` (``pure=False``) on an existing scheduler (``tcp://host:8786``) or on a
``LocalCluster`` started for the sweep (``local-dask``). Every worker runs single
threaded (numba and BLAS threads = 1, so parallelism is one task per worker) and
compiles (or loads from the on-disk cache) the numba kernels once, in its initialiser.
Workers of an existing Dask cluster are started by their operator: start them with
``NUMBA_NUM_THREADS=1 OMP_NUM_THREADS=1`` (tanbench only warms them up).

Workers never read the user's files: the truth maps of a sweep's file terrains, read
once by the client, go to every worker (through the local pool's initialiser, or a Dask
worker plugin that also reaches workers joining later) and are installed there with
:func:`tanbench.terrain.install_truth_maps`.

Local workers die with the process that started them, however it dies (``kill -9``, a
closed terminal): on Linux the kernel kills them (``PR_SET_PDEATHSIG``); workers of a
fork server, and elsewhere, a thread of theirs watches the parent (:func:`die_with_parent`). They ignore Ctrl-C and SIGHUP, which the parent
handles (it stops them).
"""

from __future__ import annotations

import ctypes
import hashlib
import multiprocessing
import os
import pickle
import signal
import sys
import threading
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

from tanbench.errors import TanbenchError

THREAD_VARS = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
CONNECT_TIMEOUT_S = 10
STOP_JOIN_S = 10  # how long a stopped worker process is given to exit


SINGLE_THREAD_ENV = {var: "1" for var in THREAD_VARS}
# the modules that read the thread variables when they load (numpy's and scipy's BLAS, numba)
NUMERICAL_MODULES = ("numpy", "scipy", "numba")
_numerics_single_threaded = False


def single_thread_environment() -> None:
    """Make this process use one thread per library; call it before numpy/numba are imported.

    Spawned worker processes call it first thing (their initialiser runs before any numerical
    import); the CLI calls it when it starts, so that its own numerics and the workers it forks
    (:func:`local_context`) run one thread each. It has no effect on a library loaded before it
    (a BLAS reads its thread count when it loads): :func:`numerics_single_threaded` then stays
    False, unless the variables already said 1 thread before (the process was started so).
    """
    global _numerics_single_threaded
    preset = all(os.environ.get(var) == value for var, value in SINGLE_THREAD_ENV.items())
    os.environ.update(SINGLE_THREAD_ENV)
    if preset or not any(name in sys.modules for name in NUMERICAL_MODULES):
        _numerics_single_threaded = True


def numerics_single_threaded() -> bool:
    """Whether this process's numerical libraries loaded with one thread each (:func:`single_thread_environment`)."""
    return _numerics_single_threaded


# what the fork server imports once, before it forks workers: the task's code (methods, filters, scoring)
FORKSERVER_PRELOAD = ["tanbench.runner.tasks"]


def local_context():
    """How this process starts local worker processes (and the compile helpers).

    On Linux, forked from this process when that is safe and gives the same results: it runs no
    other Python thread (a lock held by one would stay locked in the child) and its numerical
    libraries run one thread each (a forked worker keeps its parent's BLAS threads, and another
    thread count can change a matrix product's last bits). A forked worker does not import again
    what this process has imported (about 1.8 s of CPU per worker that a spawned one spends).
    Otherwise on Linux (a notebook, a test runner: threads), forked from multiprocessing's fork
    server (:func:`_fork_server_context`), which imports the task's code once, single threaded,
    for every pool this process starts. Elsewhere spawned: a fresh interpreter, single threaded
    before it imports anything.
    """
    if not sys.platform.startswith("linux"):
        return multiprocessing.get_context("spawn")
    if threading.active_count() == 1 and numerics_single_threaded():
        return multiprocessing.get_context("fork")
    return _fork_server_context()


def _fork_server_context():
    """multiprocessing's ``forkserver`` context, its server (one per process, started once, or again if
    it died) started with the thread variables at 1 (:data:`SINGLE_THREAD_ENV`, for the server only)
    and :data:`FORKSERVER_PRELOAD` imported, unless this process had started it before for
    something else: its workers then import what it did not (thread variables set first)."""
    from multiprocessing import forkserver

    context = multiprocessing.get_context("forkserver")
    if getattr(forkserver._forkserver, "_forkserver_pid", None) is None:  # no public handle on the server
        context.set_forkserver_preload(FORKSERVER_PRELOAD)
    saved = {var: os.environ.get(var) for var in THREAD_VARS}
    os.environ.update(SINGLE_THREAD_ENV)
    try:
        forkserver.ensure_running()  # here, so that a server started (or restarted) now has the variables
    finally:
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value
    return context


def warm_up(scenario_json: str | None = None, methods=None, share=()) -> None:
    """Compile (or load from cache) the jitted kernels of ``methods`` with a tiny run of each.

    ``methods``: the sweep's method names (default: every built-in); only built-in methods
    are warmed (a user method's code runs only in its tasks). ``scenario_json`` (a cell of
    the sweep) sets the terrain and filter options of the tiny run, so a worker warms up
    the kernels the sweep uses (e.g. the ``FastRng`` specialisations) on a map it has been
    given, instead of synthesising the default one. A sweep of three particle filters thus
    never compiles nor loads the point-mass, marginalized, EKF and TERCOM kernels. Marks each
    method's kernels warm in the cell's variant (:func:`tanbench.runner.plan.cell_kernels`).
    ``share``: kernels compiled first, on their own (:func:`tanbench.runner.compile_stages.compile_share`:
    this process's part of what side-by-side compile processes share).
    """
    import json

    import numpy as np

    from tanbench import kernel_cache
    from tanbench.config import Scenario
    from tanbench.methods import run_method
    from tanbench.methods.registry import builtin_names
    from tanbench.runner.plan import cell_kernels
    from tanbench.simulation import simulate_vehicle

    if share:
        from tanbench.runner.compile_stages import compile_share

        compile_share(share)
    builtin = builtin_names()
    names = builtin if methods is None else tuple(m for m in methods if m in builtin)
    spec = json.loads(scenario_json) if scenario_json else {}
    sensors = spec.get("sensors") or {}
    if not sensors.get("multibeam_beams"):  # the multibeam methods warm up on a small fan (no other number changes)
        spec = {**spec, "sensors": {**sensors, "multibeam_beams": 4,
                                    "multibeam_rate_hz": sensors.get("sonar_rate_hz", 1.0)}}
    scenario = Scenario(**{**spec, "duration_s": 3.0, "particles": 16})
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(0))
    for method in names:
        run_method(scenario, method, vehicle, np.random.SeedSequence(1))
    kernel_cache.mark_warm(cell_kernels(scenario, names))


def warm_up_side_by_side(scenario_json: str | None, groups, truth_maps: dict | None = None) -> None:
    """Compile the kernels of ``groups`` of methods (:func:`tanbench.runner.plan.compile_groups`) side by
    side: this process warms up the first group while one spawned helper process per other group warms
    up its own, into the same on-disk cache (numba writes each file whole, then renames it); then this
    process warms up every group's methods, loading what the helpers compiled and compiling anything
    they did not store (a helper that failed, or an index entry lost to a simultaneous write).
    Each process first compiles its share of the kernels the groups share
    (:func:`tanbench.runner.compile_stages.shares_for`), so that each of those compiles once.
    A helper starts as a local worker does (:func:`_local_worker_init`: single threaded, given the
    truth maps, ending with this process)."""
    groups = [tuple(g) for g in groups if g]
    everything = tuple(m for g in groups for m in g)
    if len(groups) <= 1:
        warm_up(scenario_json, everything)
        return
    shares = _shares_of(scenario_json, groups)
    maps_pickle = pickle.dumps(truth_maps or {}, protocol=pickle.HIGHEST_PROTOCOL)
    context = local_context()
    helpers = [context.Process(target=_local_worker_init, name=f"tanbench-compile-{i}", daemon=True,
                               args=(os.getpid(), maps_pickle, b"", scenario_json, group, shares[i]))
               for i, group in enumerate(groups[1:], start=1)]
    for helper in helpers:
        helper.start()
    try:
        warm_up(scenario_json, groups[0], shares[0])
        for helper in helpers:
            helper.join()
    finally:
        for helper in helpers:
            if helper.is_alive():  # this process was interrupted: the helpers' work is no longer wanted
                helper.terminate()
                helper.join(STOP_JOIN_S)
    warm_up(scenario_json, everything)


def _shares_of(scenario_json: str | None, groups) -> list[list]:
    """:func:`tanbench.runner.compile_stages.shares_for` the cell ``scenario_json`` (none for a cell that
    does not build: its warm-up reports it)."""
    import json

    from tanbench.config import Scenario
    from tanbench.runner.compile_stages import shares_for

    try:
        scenario = Scenario(**json.loads(scenario_json)) if scenario_json else Scenario()
    except Exception:  # noqa: BLE001 - a cell that cannot run reports itself in its task
        return [[] for _ in groups]
    return shares_for(groups, scenario)


def install_worker_maps(maps: dict) -> None:
    """Install shipped truth maps in this worker; drop worlds simulated on earlier ones."""
    from tanbench.simulation import noise_free_world
    from tanbench.terrain import install_truth_maps

    install_truth_maps(maps)
    noise_free_world.cache_clear()


PR_SET_PDEATHSIG = 1  # linux/prctl.h
PR_SET_NAME = 15
WORKER_NAME = b"tanbench-worker"  # what `ps -o comm`, top and /proc/PID/comm show for a local worker (Linux)


def _prctl(option: int, value) -> bool:
    """Linux's ``prctl(option, value)``; whether it succeeded (False elsewhere, or without libc)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        return ctypes.CDLL(None, use_errno=True).prctl(option, value, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def name_this_process(name: bytes) -> None:
    """Give this process's name (Linux: at most 15 bytes) for ``ps`` and ``top``; a forked worker
    would otherwise show its parent's name. Elsewhere nothing."""
    _prctl(PR_SET_NAME, ctypes.c_char_p(name[:15]))


def die_with_parent(parent_pid: int) -> None:
    """End this process when ``parent_pid`` (the process that started it) dies, however it dies.

    A child of ``parent_pid`` (forked or spawned) on Linux: the kernel kills it when its parent
    dies (``PR_SET_PDEATHSIG``). Otherwise (forked by a fork server, whose life a worker's open
    pipe prolongs; or not Linux) a thread of its own waits on multiprocessing's parent sentinel,
    which a dying ``parent_pid`` closes, and ends the process. (Called in a process multiprocessing
    started, which has that sentinel.)"""
    if os.getppid() == parent_pid and _prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL)):
        if os.getppid() != parent_pid:  # it died before the line above
            os._exit(1)
        return
    sentinel = multiprocessing.parent_process().sentinel

    def watch():
        from multiprocessing.connection import wait

        wait([sentinel])
        os._exit(1)

    threading.Thread(target=watch, name="tanbench-parent-watch", daemon=True).start()


def _local_worker_init(parent_pid: int, maps_pickle: bytes, worlds_pickle: bytes = b"",
                       scenario_json: str | None = None, methods=None, share=()) -> None:
    die_with_parent(parent_pid)
    name_this_process(WORKER_NAME)
    for name in ("SIGINT", "SIGHUP"):  # the parent handles Ctrl-C and a closed terminal, and stops us
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_IGN)
    # a forked worker has its parent's handler (the CLI's: SIGTERM as Ctrl-C); the parent stops us with it
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    single_thread_environment()
    # the maps come pickled so that numpy is imported only after the line above
    install_worker_maps(pickle.loads(maps_pickle))
    if worlds_pickle:
        from tanbench.simulation import preload_worlds

        preload_worlds(pickle.loads(worlds_pickle))
    try:
        warm_up(scenario_json, methods, share)
    except Exception:  # noqa: BLE001 - a cell that cannot run reports itself in its task
        warm_up(None, methods)


def _dask_worker_init(methods=None) -> None:
    warm_up(None, methods)


class ExecutorHandle:
    """An open executor plus how to stop it at once (Ctrl-C)."""

    def __init__(self, executor, description: str, stop_now):
        self.executor = executor
        self.description = description
        self._stop_now = stop_now

    def stop_now(self) -> None:
        self._stop_now()


@contextmanager
def open_executor(workers: int, scheduler: str | None, truth_maps: dict | None = None,
                  worlds: dict | None = None, scenario_json: str | None = None, methods=None):
    """Yield an :class:`ExecutorHandle` for ``workers`` local processes or a Dask scheduler.

    ``truth_maps`` (from :func:`tanbench.terrain.sweep_truth_maps`) are installed on every
    worker before it runs a task; local workers also get ``worlds`` (noise-free worlds by
    world JSON, :func:`tanbench.simulation.preload_worlds`) and warm up on ``scenario_json``;
    every worker warms up the kernels of ``methods`` only (default: every built-in method).
    """
    maps_pickle = pickle.dumps(truth_maps or {}, protocol=pickle.HIGHEST_PROTOCOL)
    if scheduler is None:
        worlds_pickle = pickle.dumps(worlds, protocol=pickle.HIGHEST_PROTOCOL) if worlds else b""
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=local_context(),
                                   initializer=_local_worker_init,
                                   initargs=(os.getpid(), maps_pickle, worlds_pickle, scenario_json, methods))

        def stop_now():
            processes = list((getattr(pool, "_processes", None) or {}).values())
            for proc in processes:
                proc.terminate()
            for proc in processes:
                proc.join(STOP_JOIN_S)
            # A worker stopped while sending its result leaves half a message in the result
            # pipe; the pool's manager thread then waits in recv() for the rest, and since this
            # process holds the pipe's write end too, it would wait forever (and the
            # interpreter's exit joins that thread: the CLI would hang after its resume hint).
            # With every writer closed, the read ends (EOF) and the pool shuts down as broken.
            result_queue = getattr(pool, "_result_queue", None)
            if result_queue is not None:
                result_queue._writer.close()
            pool.shutdown(wait=True, cancel_futures=True)

        try:
            yield ExecutorHandle(pool, f"{workers} local worker process{'es' if workers > 1 else ''}", stop_now)
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        return
    with _dask_client(workers, scheduler) as (client, description):
        from tanbench.runner.dask_plugin import TruthMapsPlugin

        plugin_name = f"tanbench-truth-maps-{hashlib.sha256(maps_pickle).hexdigest()[:16]}"
        try:
            if truth_maps:
                client.register_plugin(TruthMapsPlugin(maps_pickle), name=plugin_name)
            client.run(_dask_worker_init, methods)
        except Exception as exc:  # noqa: BLE001 - a worker that cannot start is a user-facing problem
            raise TanbenchError(f"Dask workers at {scheduler} could not start tanbench: {exc}") from None
        executor = client.get_executor(pure=False)
        try:
            yield ExecutorHandle(executor, description, lambda: executor.shutdown(wait=False))
        finally:
            if truth_maps:
                try:
                    client.unregister_worker_plugin(plugin_name)
                except Exception:  # noqa: BLE001 - the cluster may be gone; the maps go with it
                    pass


NEEDS_DASK = "--scheduler needs Dask: pip install 'tanbench[dask]'"


def check_scheduler_address(scheduler: str | None) -> None:
    """Refuse a ``--scheduler`` that is not an address a Dask client could connect to (nor ``local-dask``), before
    anything is created: a malformed address is a mistake to name, not a scheduler that did not answer."""
    if scheduler is None or scheduler == "local-dask":
        return
    try:
        from distributed.comm.addressing import parse_address, parse_host_port
        from distributed.comm.registry import backends
    except ImportError:
        raise TanbenchError(NEEDS_DASK) from None
    try:
        if any(c.isspace() for c in scheduler):
            raise ValueError("it holds a space")
        protocol, location = parse_address(scheduler)
        if protocol not in backends:
            raise ValueError(f"unknown protocol {protocol!r}; Dask knows {', '.join(sorted(backends))}")
        if protocol in ("tcp", "tls") and not parse_host_port(location)[0]:
            raise ValueError("no host")
    except ValueError as exc:
        raise TanbenchError(f"--scheduler {scheduler!r}: not a Dask scheduler address ({str(exc).splitlines()[0]}); "
                            f"give HOST:PORT, tcp://HOST:PORT or local-dask") from None


@contextmanager
def _dask_client(workers: int, scheduler: str):
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise TanbenchError(NEEDS_DASK) from None
    if scheduler == "local-dask":
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=None, env=SINGLE_THREAD_ENV)
        client = Client(cluster)
        try:
            yield client, f"a Dask LocalCluster of {workers} worker{'s' if workers > 1 else ''}"
        finally:
            client.close()
            cluster.close()
        return
    try:
        client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
    except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, ValueError from the address parser
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise TanbenchError(
            f"cannot reach the Dask scheduler at {scheduler} within {CONNECT_TIMEOUT_S} s ({reason})") from None
    try:
        n = len(client.scheduler_info().get("workers", {}))
        yield client, f"the Dask cluster at {scheduler} ({n} worker{'s' if n != 1 else ''})"
    finally:
        client.close()
