"""Killing a sweep (SIGKILL, Ctrl-C or SIGTERM) at any point and re-running the same command completes it exactly.

The CLI runs in its own process group (``start_new_session``) so the signal reaches it
and its worker processes together, as a terminal's Ctrl-C or an OOM/cluster kill would.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pyarrow.parquet as pq
import pytest

from sweep_support import (
    counted,
    assert_same_runs, cli, finished_runs, kill_group, load_tables, start_cli, sweep_dict, wait_for_runs,
    write_sweep,
)
from tanbench import results

RUNS = 12
N_TASKS = 2 * RUNS  # two cells (map resolution 10 and 20 m)
# long enough runs (a few tenths of a second per task) that there is time to kill part-way
SWEEP = sweep_dict(name="resume", runs=RUNS, scenario={"particles": 3000, "duration_s": 600},
                   tables={"map_resolution": {"map_resolution_m": [10, 20]}})


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The sweep run without interruption: (sweep file, results directory)."""
    root = tmp_path_factory.mktemp("reference")
    sweep = write_sweep(root / "resume.yaml", SWEEP)
    out = root / "out"
    proc = cli("run", sweep, "--out", out, "--workers", 2, "-q")
    assert proc.returncode == 0, proc.stderr
    return sweep, out


def assert_clean_and_readable(out) -> None:
    """Every Parquet file under ``out`` reads and carries our metadata; no temporary file is left."""
    parquet = [p for p in out.rglob("*.parquet")]
    assert parquet
    for path in parquet:
        assert b"tanbench" in pq.read_schema(path).metadata, path
        pq.read_table(path)
    assert [p for p in out.rglob("*") if p.name.endswith(".tmp") or p.name.startswith(".write-test")] == []


def assert_finished_like(out, reference_out) -> None:
    """The same runs table (wall times aside) and the same tables as the uninterrupted sweep."""
    assert_same_runs(results.load(out), results.load(reference_out))
    ref_tables = load_tables(reference_out)
    tables = load_tables(out)
    assert set(tables) == set(ref_tables)
    for name in tables:
        pd.testing.assert_frame_equal(tables[name], ref_tables[name])
    pd.testing.assert_frame_equal(pd.read_parquet(out / "series" / "summary.parquet"),
                                  pd.read_parquet(reference_out / "series" / "summary.parquet"))


def wait_group_gone(pgid: int, timeout: float = 30) -> bool:
    """Whether every process of the group has exited within ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def dead_pid() -> int:
    """The pid of a process that has exited (for a stale temporary file's name)."""
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    return int(proc.stdout)


@pytest.mark.parametrize("after", [1, N_TASKS // 2, N_TASKS - 2], ids=["after-1", "half-way", "near-the-end"])
def test_sigkill_then_resume_matches_uninterrupted(reference, tmp_path, after):
    """SIGKILL of the CLI and its workers after some tasks; the same command resumes to identical results."""
    sweep, ref_out = reference
    out = tmp_path / "out"
    args = ("run", sweep, "--out", out, "--workers", 2, "-q")
    proc = start_cli(*args)
    seen = wait_for_runs(proc, out, after)
    kill_group(proc, signal.SIGKILL)
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL, "the sweep ended before it could be killed"
    assert wait_group_gone(proc.pid)
    stored = finished_runs(out)
    assert after <= seen <= stored < N_TASKS
    for path in (out / "runs").glob("*/run-*.parquet"):  # what was stored is whole
        pq.read_table(path)
    stale = out / "runs" / f".run-99999.parquet.{dead_pid()}.tmp"  # as a kill mid-write leaves
    stale.parent.mkdir(parents=True, exist_ok=True)
    stale.write_bytes(b"PAR1 half a file")

    again = cli(*args)
    assert again.returncode == 0, again.stderr
    assert f"{counted(N_TASKS - stored)} run, {counted(stored)} already done" in again.stdout
    assert not stale.exists()
    assert_clean_and_readable(out)
    assert_finished_like(out, ref_out)


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm-to-the-cli"])
def test_ctrl_c_stops_promptly_keeps_runs_and_resumes(reference, tmp_path, how):
    """Ctrl-C (SIGINT to the group), or SIGTERM to the CLI process alone (``kill PID``, a batch
    scheduler's stop), stops the sweep within seconds with exit 130 and a resume hint, and takes
    the worker processes with it."""
    sweep, ref_out = reference
    out = tmp_path / "out"
    args = ("run", sweep, "--out", out, "--workers", 2)
    proc = start_cli(*args)
    seen = wait_for_runs(proc, out, N_TASKS // 3)
    if how == "ctrl-c":
        kill_group(proc, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGTERM)
    try:
        stdout, stderr = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        kill_group(proc, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"the sweep did not stop within 30 s of {how}")
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    hint = [line for line in stderr.splitlines() if line.startswith("interrupted:")]
    assert len(hint) == 1 and f"resume with: tanbench run {sweep} --out {out} --workers 2" in hint[0]
    assert wait_group_gone(proc.pid), "worker processes outlived the CLI"
    stored = finished_runs(out)
    assert seen <= stored < N_TASKS
    for path in (out / "runs").glob("*/run-*.parquet"):
        pq.read_table(path)

    again = cli(*args, "-q")
    assert again.returncode == 0, again.stderr
    assert f"{counted(N_TASKS - stored)} run, {counted(stored)} already done" in again.stdout
    assert_clean_and_readable(out)
    assert_finished_like(out, ref_out)


STOP_WITH_HALF_A_RESULT = """
import sys, time
from pathlib import Path
sys.path.insert(0, {tests!r})
from half_message import send_half_a_result
from tanbench.runner.executors import open_executor

with open_executor(1, None) as handle:
    handle.executor.submit(send_half_a_result, {sent!r})
    while not Path({sent!r}).exists():
        time.sleep(0.05)
    time.sleep(1)  # the pool's manager thread reads the header and waits for the rest
    handle.stop_now()
print("stopped", flush=True)
"""


def test_stop_now_with_half_a_result_in_the_pipe_exits(tmp_path):
    """A worker stopped while it sends its result leaves half a message in the result pipe;
    stopping the pool must not leave its manager thread waiting for the rest (the CLI hung
    at exit, after its resume hint, when SIGTERM caught a worker mid-send)."""
    from sweep_support import ROOT, cli_env

    script = STOP_WITH_HALF_A_RESULT.format(tests=str(ROOT / "tests"), sent=str(tmp_path / "sent"))
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=cli_env(), start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail("the process did not exit after stop_now()")
    assert proc.returncode == 0, stderr
    assert "stopped" in stdout
