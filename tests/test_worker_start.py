"""How local workers start (tanbench.runner.executors.local_context): on Linux forked from the process
where that is safe and gives the same numbers, else from a fork server; the numbers are the same."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sweep_support import ROOT, assert_same_runs, child_pids, cli, cli_env, gone, sweep_dict, write_sweep

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="workers are forked on Linux only")

CLEAN_ENV = {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(ROOT)}


def start_method(code: str, env: dict | None = None) -> str:
    """The start method ``local_context()`` picks in a fresh interpreter after ``code`` has run."""
    script = f"{code}\nfrom tanbench.runner.executors import local_context\nprint(local_context().get_start_method())"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env or CLEAN_ENV,
                          cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_the_cli_forks_its_workers_with_single_threaded_numerics():
    """The CLI makes its numerics single threaded before numpy loads, so it may fork."""
    assert start_method("import tanbench.cli, numpy, scipy.linalg") == "fork"
    assert start_method("import tanbench.cli, os; print(os.environ['OPENBLAS_NUM_THREADS'], end=' ')") == "1 fork"


def test_a_process_whose_blas_loaded_with_its_default_threads_uses_the_fork_server():
    """numpy loaded before the thread variables were set: a worker forked from it would keep its BLAS threads."""
    assert start_method("import numpy\nfrom tanbench.runner.executors import single_thread_environment\n"
                        "single_thread_environment()") == "forkserver"
    assert start_method("import numpy") == "forkserver"


def test_the_thread_variables_set_before_start_count_as_single_threaded():
    env = {**CLEAN_ENV, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    assert start_method("import numpy\nfrom tanbench.runner.executors import single_thread_environment\n"
                        "single_thread_environment()", env) == "fork"


def test_a_process_running_another_thread_uses_the_fork_server():
    """A lock held by another thread at the fork would stay locked in the child."""
    code = ("import threading, time, tanbench.cli\n"
            "threading.Thread(target=time.sleep, args=(30,), daemon=True).start()")
    assert start_method(code) == "forkserver"


def test_the_fork_server_starts_single_threaded_and_leaves_this_process_s_variables_alone():
    code = ("import os, numpy\nos.environ['OPENBLAS_NUM_THREADS'] = '4'\n"
            "from tanbench.runner.executors import local_context\n"
            "ctx = local_context()\n"
            "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ.get('MKL_NUM_THREADS'))\n"
            "with ctx.Pool(1) as pool:\n"
            "    print(pool.apply(os.getenv, ('OPENBLAS_NUM_THREADS',)), pool.apply(os.getenv, ('MKL_NUM_THREADS',)))")
    assert start_method(code).splitlines() == ["4 None", "1 1", "forkserver"]


def test_a_sweep_from_a_threaded_process_equals_the_cli_s(tmp_path):
    """The same sweep run by the CLI (workers forked from it) and by run_sweep in a process running
    another thread (workers forked from the fork server): the same runs, bit for bit."""
    sweep = write_sweep(tmp_path / "s.yaml", sweep_dict(runs=2))
    done = cli("run", sweep, "--out", tmp_path / "cli", "--workers", 2, "-q")
    assert done.returncode == 0, done.stderr
    script = ("import threading, time, sys\n"
              "threading.Thread(target=time.sleep, args=(600,), daemon=True).start()\n"
              "from pathlib import Path\n"
              "from tanbench.runner.engine import run_sweep\nfrom tanbench.runner.executors import local_context\n"
              "from tanbench.sweep import load_sweep\n"
              "assert local_context().get_start_method() == 'forkserver'\n"
              f"run_sweep(load_sweep(Path({str(sweep)!r})), Path({str(tmp_path / 'api')!r}), workers=2, progress=False)\n")
    api = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=cli_env(), cwd=ROOT,
                         timeout=300)
    assert api.returncode == 0, api.stderr
    import pandas as pd

    assert_same_runs(pd.read_parquet(tmp_path / "api" / "runs"), pd.read_parquet(tmp_path / "cli" / "runs"))


def _descendants_named(pid: int, name: bytes) -> list[int]:
    found, todo = [], [pid]
    while todo:
        children = child_pids(todo.pop())
        todo += children
        for child in children:
            try:
                if Path(f"/proc/{child}/comm").read_bytes().strip() == name:
                    found.append(child)
            except OSError:
                pass
    return found


def test_fork_server_workers_die_with_the_process_that_started_them(tmp_path):
    """kill -9 of a threaded process running a sweep: its workers (children of its fork server) end too."""
    from tanbench.runner.executors import WORKER_NAME

    sweep = write_sweep(tmp_path / "s.yaml", sweep_dict(runs=40, scenario={"particles": 2000, "duration_s": 300}))
    script = ("import threading, time\n"
              "threading.Thread(target=time.sleep, args=(600,), daemon=True).start()\n"
              "from pathlib import Path\nfrom tanbench.runner.engine import run_sweep\n"
              "from tanbench.sweep import load_sweep\n"
              f"run_sweep(load_sweep(Path({str(sweep)!r})), Path({str(tmp_path / 'out')!r}), workers=2, progress=False)\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=cli_env(), cwd=ROOT, start_new_session=True)
    workers = []
    try:
        deadline = time.monotonic() + 240
        while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            workers = _descendants_named(proc.pid, WORKER_NAME)
        assert len(workers) == 2, "the workers did not start"
        parents = {int(Path(f"/proc/{w}/stat").read_text().rsplit(")", 1)[1].split()[1]) for w in workers}
        assert proc.pid not in parents, "not forked from the fork server"
        proc.kill()
        proc.wait(timeout=30)
        assert gone(workers, timeout=20), "worker processes outlived the process that started them"
    finally:
        for pid in [proc.pid, *workers]:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
