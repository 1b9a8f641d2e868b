"""A CLI process started without paying for the imports again: ``python -m tanbench.cli`` forked from
a process that has imported the libraries once (the tests' :func:`sweep_support.cli`).

Every CLI subprocess of the tests spent about 1.7 s of CPU importing numpy, pandas, numba and
scipy before it did anything, a third of the suite's CPU over a few hundred commands. This
script is started once per test process (with the environment every ``cli()`` command gets);
it imports ``tanbench`` (which points numba's cache first, as any CLI start does) and those
libraries, never ``tanbench.cli``, then waits for requests. For each one it forks, and the child
becomes the command: the request's argv, environment and working directory, stdout and stderr
to files, stdin from /dev/null, then ``tanbench.cli`` run as ``__main__`` at the top level of
this script exactly as ``python -m`` runs it. So each command is still its own process with its
own exit code (an uncaught exception prints its traceback and exits 1, a signal is a negative
code), its own streams, and nothing one command changes reaches the next. It ends as the
interpreter's exit does (threads joined, ``atexit`` handlers run, streams flushed) but without
the last step, tearing down every module (:func:`_run_cli_and_exit`); the tests that start the
CLI as a plain subprocess (:func:`sweep_support.start_cli`, the signal and kill tests) see
that step too.

:func:`sweep_support.cli` uses it only for a command whose environment is the one the server
started with, or differs only by directories put before its PYTHONPATH (a plug-in's; the child
puts them on ``sys.path`` where ``python -m`` would, unless one holds a ``sitecustomize`` that a
fresh process would import at start-up); anything else, e.g. another NUMBA_CACHE_DIR, runs as a
plain subprocess. And only if the imports printed nothing (a warning would otherwise be
missed by a test that looks for one in the command's stderr) and started no thread but jemalloc's
background thread (pyarrow's allocator, started by importing pandas; jemalloc's fork handlers make
a fork safe for it, and the child starts its own when it needs one).

Protocol: one JSON line per request on stdin; on the reply pipe (fd given as argv[1]) the child's
pid, then its wait status, one line each.
"""

from __future__ import annotations

import json
import os
import sys


def _threads() -> list[str]:
    """The names of this process's threads but the main one (Linux /proc)."""
    names = []
    for task in os.listdir("/proc/self/task"):
        if int(task) != os.getpid():
            with open(f"/proc/self/task/{task}/comm") as comm:
                names.append(comm.read().strip())
    return names


def _serve(reply_fd: int) -> dict | None:
    """Answer requests until stdin closes (then None); in a forked child, return its request."""
    reply = os.fdopen(reply_fd, "w", buffering=1)
    reply.write(json.dumps({"ready": True, "threads": _threads()}) + "\n")
    for line in sys.stdin:
        request = json.loads(line)
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            reply.close()
            return request
        reply.write(json.dumps({"pid": pid}) + "\n")
        _, status = os.waitpid(pid, 0)
        reply.write(json.dumps({"status": status}) + "\n")
    return None


def _become(request: dict) -> None:
    """In the forked child: take the request's argv, environment, directory and streams."""
    os.environ.clear()
    os.environ.update(request["env"])
    os.chdir(request["cwd"])
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    for fd, path in ((1, request["stdout"]), (2, request["stderr"])):
        out = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(out, fd)
        os.close(out)
    os.close(null)
    sys.stdin = open(0, closefd=False)  # noqa: SIM115 - the process's own stdin, as at start-up
    sys.argv = ["-m", *request["args"]]  # runpy puts the module's path in argv[0], as `python -m` does
    sys.path[0] = os.getcwd()  # `python -m` puts the working directory first on the path
    sys.path[1:1] = request["path"]  # then PYTHONPATH: the directories before the server's own


def _exit_status(code) -> int:
    """The exit status Python gives ``sys.exit(code)``: None 0, an int itself, anything else printed, 1."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code & 0xFF
    print(code, file=sys.stderr)
    return 1


def _run_cli_and_exit() -> None:
    """Run ``tanbench.cli`` as ``__main__`` and end the process as the interpreter's exit does, but
    for its last step: a traceback for an uncaught exception (status 1), the other threads joined,
    the ``atexit`` handlers run, the streams flushed; then ``os._exit`` instead of tearing down
    every module and object of the libraries imported (about 0.55 s of CPU per command, measured
    on a ``--version``: 0.59-0.62 s against 0.04 s with this exit)."""
    import atexit
    import runpy
    import threading

    try:
        runpy.run_module("tanbench.cli", run_name="__main__", alter_sys=True)
        status = 0
    except SystemExit as done:
        status = _exit_status(done.code)
    except BaseException:  # noqa: BLE001 - what the interpreter does with an uncaught exception
        sys.excepthook(*sys.exc_info())
        status = 1
    threading._shutdown()  # the interpreter's first exit step: wait for the non-daemon threads
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(status)


# what `run`, `validate`, `plan`, `check`, `tables` and `report` import besides the above (the runner, the
# methods and their kernel modules, the check and report modules), measured with the modules a forked command
# added to sys.modules; never tanbench.cli (run as __main__), tanbench.plot or matplotlib (a fresh machine's
# first matplotlib import prints that it builds its font cache, and a server that printed anything serves no one)
PRELOAD = (
    "pyarrow.dataset", "tqdm", "concurrent.futures.process",
    "tanbench.runner.engine", "tanbench.runner.executors", "tanbench.runner.tasks", "tanbench.runner.resume",
    "tanbench.runner.plan", "tanbench.methods.tight", "tanbench.methods.loose", "tanbench.methods.pmf",
    "tanbench.methods.mpf", "tanbench.methods.ekf", "tanbench.methods.tercom", "tanbench.methods.multibeam",
    "tanbench.check", "tanbench.report", "tanbench.claims", "tanbench.criterion", "tanbench.anatomy", "tanbench.fit",
)


def _preload() -> None:
    """Import :data:`PRELOAD` and set up numba's typing and target contexts (the registries of its
    implementations, which a process sets up once, at its first kernel compiled or loaded from the cache):
    about 0.3-0.7 s of CPU less per forked ``run``, ``validate`` or ``plan`` (measured: a 1-task ``run``
    1.1-1.6 -> 0.7-0.9 s, ``validate`` of a sweep 1.0 -> 0.3 s). Nothing here reads the working directory or the
    environment beyond what the server started with (the same as the commands it serves)."""
    import importlib

    for name in PRELOAD:
        importlib.import_module(name)
    from numba.core.registry import cpu_target

    cpu_target.typing_context.refresh()
    cpu_target.target_context.refresh()


if __name__ == "__main__":
    reply_fd = int(sys.argv[1])
    del sys.path[0]  # this script's directory (tests/) is not on a CLI process's path
    import tanbench  # noqa: F401 - first, as in the CLI: it points numba's cache before numba is imported
    import numba  # noqa: F401
    import numpy  # noqa: F401
    import pandas  # noqa: F401
    import pyarrow.parquet  # noqa: F401
    import scipy.stats  # noqa: F401
    import typer  # noqa: F401
    import yaml  # noqa: F401

    import tanbench.config  # noqa: F401 - the package modules most commands import (never tanbench.cli)
    import tanbench.results  # noqa: F401
    import tanbench.runner.validate  # noqa: F401
    import tanbench.sweep  # noqa: F401
    _preload()

    sys.path.insert(0, "")
    request = _serve(reply_fd)
    if request is None:
        sys.exit(0)
    _become(request)
    del request
    _run_cli_and_exit()
