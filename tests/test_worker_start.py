"""How local workers start (tanbench.runner.executors.local_context): forked only where that is safe
and gives the same numbers, spawned otherwise."""

from __future__ import annotations

import subprocess
import sys

import pytest

from sweep_support import ROOT

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


def test_a_process_whose_blas_loaded_with_its_default_threads_spawns():
    """numpy loaded before the thread variables were set: a forked worker would keep its BLAS threads."""
    assert start_method("import numpy\nfrom tanbench.runner.executors import single_thread_environment\n"
                        "single_thread_environment()") == "spawn"
    assert start_method("import numpy") == "spawn"


def test_the_thread_variables_set_before_start_count_as_single_threaded():
    env = {**CLEAN_ENV, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    assert start_method("import numpy\nfrom tanbench.runner.executors import single_thread_environment\n"
                        "single_thread_environment()", env) == "fork"


def test_a_process_running_another_thread_spawns():
    """A lock held by another thread at the fork would stay locked in the child."""
    code = ("import threading, time, tanbench.cli\n"
            "threading.Thread(target=time.sleep, args=(30,), daemon=True).start()")
    assert start_method(code) == "spawn"
