"""Helpers shared by the sweep-engine and input-handling tests (CLI in a subprocess).

Plain functions, no fixtures: write a sweep YAML from a dict, run ``python -m
tanbench.cli`` with the project on PYTHONPATH, compare results while ignoring wall
times. Sweeps are tiny (a few particles, a short run) so a CLI run takes seconds.
"""

from __future__ import annotations

import copy
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import yaml

from tanbench.runner.executors import SINGLE_THREAD_ENV

ROOT = Path(__file__).resolve().parents[1]
METHODS = ["tight-dvl", "tight-sbe", "loose-dvl"]
# columns that depend on the machine's speed, not on the inputs
WALL_COLUMNS = ["wall_s", "filter_wall_s"]
RUN_COLUMNS = [
    "sweep", "cell_id", "tables", "method", "run", "seed", "area", "map_resolution_m", "noise_m",
    "sampling_time_s", "particles", "final_horizontal_error_m", "mean_horizontal_error_m",
    "final_heading_error_deg", "status", "error", "wall_s",
]
TABLE_COLUMNS = ["table", "method", "n_runs", "mean_final_error_m", "min_final_error_m", "max_final_error_m"]

TINY = {
    "name": "tiny",
    "seed": 20240601,
    "runs": 3,
    "methods": METHODS,
    "scenario": {"particles": 60, "duration_s": 60},
    "tables": {"map_resolution": {"map_resolution_m": [10, 20]},
               "particles": {"particles": [60, 80]}},
}


def sweep_dict(**changes) -> dict:
    """A copy of the tiny sweep with top-level keys replaced (``scenario=`` merges)."""
    data = copy.deepcopy(TINY)
    for key, value in changes.items():
        if key == "scenario":
            data["scenario"].update(value)
        else:
            data[key] = value
    return data


def write_sweep(path: Path, data: dict) -> Path:
    """Write ``data`` as a sweep YAML file at ``path``."""
    path = Path(path)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def cli_env(extra_path: Path | None = None) -> dict:
    """The environment of a CLI subprocess: tanbench importable, single-threaded numerics."""
    env = dict(os.environ)
    parts = [str(extra_path)] if extra_path else []
    parts.append(str(ROOT))
    if env.get("PYTHONPATH"):
        parts.append(env["PYTHONPATH"])
    env["PYTHONPATH"] = os.pathsep.join(parts)
    # every numerical library single threaded from the start, as the CLI makes itself (so it forks its workers)
    env.update(SINGLE_THREAD_ENV, COLUMNS="200", NO_COLOR="1")
    return env


def cli(*args, timeout: float = 300, extra_path: Path | None = None, cwd=None) -> subprocess.CompletedProcess:
    """Run ``python -m tanbench.cli ARGS`` in a process of its own and capture its output.

    The process is forked from :mod:`cli_forkserver` (the libraries already imported) when the
    command's environment is the one that server started with, or differs only by ``extra_path``
    (a plug-in's directory) put first on PYTHONPATH; else it is started as a plain subprocess.
    """
    cmd = [sys.executable, "-m", "tanbench.cli", *[str(a) for a in args]]
    env = cli_env(extra_path)
    server = _forkserver()
    prefix = None if server is None else server.path_prefix(env)
    if prefix is not None:
        return server.run(cmd, timeout, env, str(cwd or ROOT), prefix)
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, cwd=cwd or ROOT)


class _ForkServer:
    """One :mod:`cli_forkserver` process of this test process (see its docstring)."""

    def __init__(self):
        import tempfile

        self.env = cli_env()
        self.dir = Path(tempfile.mkdtemp(prefix="tanbench-cli-"))
        read_fd, self.reply_fd = os.pipe()
        self.errors = self.dir / "server.err"
        with open(self.errors, "wb") as err:
            self.proc = subprocess.Popen([sys.executable, str(Path(__file__).with_name("cli_forkserver.py")),
                                          str(self.reply_fd)], stdin=subprocess.PIPE, stdout=err, stderr=err,
                                         env=self.env, cwd=ROOT, pass_fds=(self.reply_fd,), text=True)
        os.close(self.reply_fd)
        self.replies = os.fdopen(read_fd, "r")
        self.count = 0

    def ready(self) -> bool:
        """Whether the server imported without a word on stderr and without starting a thread (but
        jemalloc's background thread, see :mod:`cli_forkserver`)."""
        line = self.replies.readline()
        if not line:
            return False
        threads = json.loads(line)["threads"]
        return set(threads) <= {"jemalloc_bg_thd"} and self.errors.read_bytes() == b""

    def path_prefix(self, env: dict) -> list[str] | None:
        """The directories ``env``'s PYTHONPATH puts before the server's (``cli(extra_path=)``: a
        plug-in's directory), if that is all that differs from the server's environment; None if
        anything else differs, or if such a directory is not absolute, is on the server's path
        already, or holds what a fresh process reads at start-up and a forked one would not: a
        ``sitecustomize``/``usercustomize`` module, or an installed distribution (its entry points,
        read by the server already). The forked command puts them where ``python -m`` does (right
        after the working directory), so it imports from them what a fresh process would."""
        ignore = ("PYTEST_CURRENT_TEST", "PYTHONPATH")
        if _without(env, *ignore) != _without(self.env, *ignore):
            return None
        path, base = env.get("PYTHONPATH", ""), self.env.get("PYTHONPATH", "")
        if path == base:
            return []
        if not path.endswith(os.pathsep + base):
            return None
        prefix = path[: -len(os.pathsep + base)].split(os.pathsep)
        for entry in prefix:
            folder = Path(entry)
            read_at_start_up = [folder / f"{name}{suffix}" for name in ("sitecustomize", "usercustomize")
                                for suffix in (".py", "", ".pyc")]
            if (not folder.is_absolute() or entry in base.split(os.pathsep) or any(p.exists() for p in read_at_start_up)
                    or any(folder.glob("*.dist-info")) or any(folder.glob("*.egg-info"))):
                return None
        return prefix

    def run(self, cmd: list[str], timeout: float, env: dict, cwd: str, path: list[str]) -> subprocess.CompletedProcess:
        """Fork ``cmd`` from the server with ``env`` and ``cwd``, ``path`` (:meth:`path_prefix`) first on its path."""
        import select

        self.count += 1
        out, err = self.dir / f"{self.count}.out", self.dir / f"{self.count}.err"
        self.proc.stdin.write(json.dumps({"args": cmd[3:], "env": env, "cwd": cwd, "path": path,
                                          "stdout": str(out), "stderr": str(err)}) + "\n")
        self.proc.stdin.flush()
        pid = json.loads(self.replies.readline())["pid"]
        if not select.select([self.replies], [], [], timeout)[0]:
            os.kill(pid, signal.SIGKILL)
            self.replies.readline()
            raise subprocess.TimeoutExpired(cmd, timeout, _text(out), _text(err))
        code = os.waitstatus_to_exitcode(json.loads(self.replies.readline())["status"])
        stdout, stderr = _text(out), _text(err)
        out.unlink()
        err.unlink()
        return subprocess.CompletedProcess(cmd, code, stdout, stderr)

    def close(self) -> None:
        import shutil

        self.proc.stdin.close()
        self.proc.wait(timeout=30)
        shutil.rmtree(self.dir, ignore_errors=True)


def _without(env: dict, *names: str) -> dict:
    return {k: v for k, v in env.items() if k not in names}


def _text(path: Path) -> str:
    """A captured stream as ``subprocess.run(text=True)`` gives it (locale encoding, newlines translated)."""
    import locale

    data = path.read_bytes() if path.exists() else b""
    return data.decode(locale.getpreferredencoding(False)).replace("\r\n", "\n").replace("\r", "\n")


_SERVER: list = []


def _forkserver() -> _ForkServer | None:
    """This process's fork server, started at the first command; None where it cannot serve."""
    if not _SERVER:
        server = None
        if hasattr(os, "fork") and Path("/proc/self/task").is_dir() and not os.environ.get("TANBENCH_TEST_NO_FORKSERVER"):
            server = _ForkServer()
            if not server.ready():
                server.close()
                server = None
            else:
                import atexit

                atexit.register(server.close)
        _SERVER.append(server)
    return _SERVER[0]


def _default_sigint() -> None:
    """In the child before exec: Ctrl-C's default action, as a command started from a terminal has.

    A shell without job control starts background commands with SIGINT ignored, and the
    ignoring is inherited (pytest, then the CLI); the CLI would then never see the test's
    Ctrl-C. Restoring the default makes the test check tanbench, not how pytest was started.
    """
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def start_cli(*args, stdout=None, stderr=None) -> subprocess.Popen:
    """Start ``python -m tanbench.cli ARGS`` in its own process group (to signal it and its workers)."""
    cmd = [sys.executable, "-m", "tanbench.cli", *[str(a) for a in args]]
    return subprocess.Popen(cmd, env=cli_env(), cwd=ROOT, start_new_session=True, text=True,
                            preexec_fn=_default_sigint,
                            stdout=stdout or subprocess.PIPE, stderr=stderr or subprocess.PIPE)


def finished_runs(out: Path) -> int:
    """How many run files (finished tasks) a results directory holds."""
    return len(list((Path(out) / "runs").glob("*/run-*.parquet")))


def wait_for_runs(proc: subprocess.Popen, out: Path, count: int, timeout: float = 240) -> int:
    """Poll until ``out`` holds at least ``count`` run files (or the process ends); the count seen."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        n = finished_runs(out)
        if n >= count or proc.poll() is not None:
            return n
        time.sleep(0.01)
    raise AssertionError(f"no {count} finished runs in {out} after {timeout} s")


def kill_group(proc: subprocess.Popen, sig=signal.SIGKILL) -> None:
    """Send ``sig`` to the process group of ``proc`` (the CLI and its worker processes)."""
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass


def comparable(runs: pd.DataFrame) -> pd.DataFrame:
    """The runs table without wall times, sorted by (cell, method, run), for exact comparison."""
    df = runs.drop(columns=[c for c in WALL_COLUMNS if c in runs.columns])
    return df.sort_values(["cell_id", "method", "run"]).reset_index(drop=True)


def assert_same_runs(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Identical runs tables (every column but the wall times)."""
    pd.testing.assert_frame_equal(comparable(a), comparable(b))


def load_tables(directory: Path) -> dict[str, pd.DataFrame]:
    """Every ``tables/*.parquet`` of a results directory, by name."""
    return {p.stem: pd.read_parquet(p) for p in sorted((Path(directory) / "tables").glob("*.parquet"))}


def error_lines(stderr: str) -> list[str]:
    """The non-empty lines of a stderr text."""
    return [line for line in stderr.splitlines() if line.strip()]


def counted(tasks: int, n_methods: int = len(METHODS)) -> str:
    """How the CLI counts tasks: '6 tasks (18 runs)' (a task is one run of a cell with every method)."""
    runs = tasks * n_methods
    return f"{tasks} task{'s' if tasks != 1 else ''} ({runs} run{'s' if runs != 1 else ''})"


def child_pids(pid: int) -> list[int]:
    """The child processes of process ``pid``, those of every thread of it (Linux /proc)."""
    children = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            children += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return children


def gone(pids, timeout: float = 30) -> bool:
    """Whether the processes ``pids`` all end (or are zombies) within ``timeout`` seconds (Linux /proc)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        alive = [p for p in pids if Path(f"/proc/{p}").exists() and b"State:\tZ" not in _status(p)]
        if not alive:
            return True
        time.sleep(0.1)
    return False


def _status(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/status").read_bytes()
    except OSError:
        return b"State:\tZ"
