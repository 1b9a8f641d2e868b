"""Killing a sweep (SIGKILL, Ctrl-C, SIGTERM, SIGHUP) at any point and re-running the same command completes it exactly.

The CLI runs in its own process group (``start_new_session``) so the signal reaches it
and its worker processes together, as a terminal's Ctrl-C or an OOM/cluster kill would.
A worker that dies alone costs only its tasks (run again, never stored as failures), and
the workers die with the CLI however it dies.
"""

from __future__ import annotations

import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from sweep_support import (
    ROOT, counted,
    assert_same_runs, child_pids, cli, cli_env, finished_runs, gone, kill_group, load_tables, start_cli, sweep_dict,
    wait_for_runs, write_sweep,
)
from tanbench import results, store
from tanbench.runner.executors import WORKER_NAME
from tanbench.sweep import load_sweep

RUNS = 8  # 16 tasks: room to kill after 1, half-way and 2 before the end
N_TASKS = 2 * RUNS  # two cells (map resolution 10 and 20 m)
# long enough runs (about 0.3 s of CPU per task, the 3 methods of one run) that there is time to kill part-way
SWEEP = sweep_dict(name="resume", runs=RUNS, scenario={"particles": 1500, "duration_s": 600},
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


@pytest.mark.parametrize("how", ["ctrl-c", "sigterm-to-the-cli", "sighup-to-the-cli"])
def test_ctrl_c_stops_promptly_keeps_runs_and_resumes(reference, tmp_path, how):
    """Ctrl-C (SIGINT to the group), SIGTERM to the CLI process alone (``kill PID``, a batch
    scheduler's stop) or SIGHUP (its terminal closed) stops the sweep within seconds with exit
    130 and a resume hint, and takes the worker processes with it.

    The SIGTERM case also checks that the hint is a command that works: its results directory
    has a space in its name, and the sweep is resumed by pasting the hint into a shell."""
    sweep, ref_out = reference
    out = tmp_path / ("my results" if how == "sigterm-to-the-cli" else "out")
    args = ("run", sweep, "--out", out, "--workers", 2)
    proc = start_cli(*args)
    seen = wait_for_runs(proc, out, N_TASKS // 3)
    if how == "ctrl-c":
        kill_group(proc, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGTERM if how == "sigterm-to-the-cli" else signal.SIGHUP)
    try:
        stdout, stderr = proc.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        kill_group(proc, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"the sweep did not stop within 30 s of {how}")
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    hint = [line for line in stderr.splitlines() if line.startswith("interrupted:")]
    assert len(hint) == 1 and f"tanbench run {sweep} --out {shlex.quote(str(out))} --workers 2" in hint[0], stderr
    assert wait_group_gone(proc.pid), "worker processes outlived the CLI"
    stored = finished_runs(out)
    assert seen <= stored < N_TASKS
    for path in (out / "runs").glob("*/run-*.parquet"):
        pq.read_table(path)

    again = resume_from_hint(hint[0], out) if how == "sigterm-to-the-cli" else cli(*args, "-q")
    assert again.returncode == 0, again.stderr
    assert f"{counted(N_TASKS - stored)} run, {counted(stored)} already done" in again.stdout
    assert_clean_and_readable(out)
    assert_finished_like(out, ref_out)


def resume_from_hint(hint: str, out: Path) -> subprocess.CompletedProcess:
    """The hint's command (plus ``-q``) run by bash, as a user pastes it: it quotes ``out`` (which has
    a space in its name) and keeps the PYTHONPATH the sweep ran with."""
    command = hint.split("resume with: ", 1)[1]
    assert f"--out '{out}'" in command and command.startswith("PYTHONPATH="), command
    env = cli_env()
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"  # the tanbench script
    return subprocess.run(["bash", "-c", command + " -q"], capture_output=True, text=True, env=env, cwd=ROOT,
                          timeout=600)


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


# ---- worker and parent deaths (issue 25) ------------------------------------------------------------


def worker_pids(pid: int) -> list[int]:
    """The pool's worker processes of the CLI process ``pid`` (Linux /proc): its children named
    ``tanbench-worker`` (local workers, forked or spawned) or spawned by multiprocessing (Dask's).

    Every thread's children: a Dask nanny starts its worker from the cluster's event-loop thread.
    """
    found = []
    for child in child_pids(pid):
        try:
            if (Path(f"/proc/{child}/comm").read_bytes().strip() == WORKER_NAME
                    or b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes()):
                found.append(child)
        except OSError:
            pass
    return found


needs_proc = pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="finds worker processes in /proc")


@needs_proc
def test_a_killed_worker_costs_only_its_tasks(reference, tmp_path):
    """kill -9 of one worker mid-sweep: its tasks run again in new worker processes, no run is stored as
    failed, and the sweep ends exactly as the uninterrupted one."""
    sweep, ref_out = reference
    out = tmp_path / "out"
    proc = start_cli("run", sweep, "--out", out, "--workers", 2, "-q")
    wait_for_runs(proc, out, 2)
    workers = worker_pids(proc.pid)
    assert workers, "no worker processes found"
    os.kill(workers[0], signal.SIGKILL)
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr
    notes = [line for line in stderr.splitlines() if line.startswith("note: a worker process ended abruptly")]
    assert len(notes) == 1 and "were not stored and run again in new worker processes" in notes[0], stderr
    assert (results.load(out)["status"] == "ok").all()
    assert_finished_like(out, ref_out)


@needs_proc
def test_workers_die_with_the_cli_however_it_dies(reference, tmp_path):
    """kill -9 of the CLI alone (not its group): its worker processes end too, at once (they used to
    stay, blocked on a pipe); the rerun resumes to identical results."""
    sweep, ref_out = reference
    out = tmp_path / "out"
    args = ("run", sweep, "--out", out, "--workers", 2, "-q")
    proc = start_cli(*args)
    wait_for_runs(proc, out, 2)
    workers = worker_pids(proc.pid)
    assert workers
    proc.kill()
    proc.wait(timeout=30)
    try:
        assert gone(workers, timeout=20), "worker processes outlived the CLI"
    finally:
        for pid in workers:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    again = cli(*args)
    assert again.returncode == 0, again.stderr
    assert_finished_like(out, ref_out)


@needs_proc
def test_local_dask_workers_die_with_the_cli(tmp_path):
    """kill -9 of the CLI running a local Dask cluster: the cluster's worker processes end too."""
    pytest.importorskip("distributed")
    sweep = write_sweep(tmp_path / "resume.yaml", SWEEP)
    out = tmp_path / "out"
    proc = start_cli("run", sweep, "--out", out, "--scheduler", "local-dask", "--workers", 2, "-q")
    wait_for_runs(proc, out, 1)
    workers = worker_pids(proc.pid)
    proc.kill()
    proc.wait(timeout=30)
    try:
        assert workers, "no worker processes found"
        assert gone(workers, timeout=20), "Dask worker processes outlived the CLI"
    finally:
        for pid in workers:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


# ---- what is stored stays consistent (issue 25) ---------------------------------------------------


TINY_RESUME = sweep_dict(name="tiny", runs=3, tables={"particles": {"particles": [60, 80]}})


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A tiny sweep (2 cells x 3 runs) run once: (sweep file, results). One worker process: the
    tests that use it are about what is stored, not about workers."""
    root = tmp_path_factory.mktemp("tiny")
    path = write_sweep(root / "tiny.yaml", TINY_RESUME)
    proc = cli("run", path, "--out", root / "out", "--workers", 1, "-q")
    assert proc.returncode == 0, proc.stderr
    return path, root / "out"


def copied(tiny, tmp_path):
    path, out = tiny
    shutil.copytree(out, tmp_path / "out")
    return path, tmp_path / "out"


def test_failure_rows_of_a_crash_never_block_the_rerun(tiny, tmp_path):
    """Rows stored as failed with seed -1 (how an older tanbench recorded a worker's death) are retried by
    a plain rerun; they are not "runs made with other seeds" that only --force would clear."""
    path, out = copied(tiny, tmp_path)
    merged = sorted((out / "runs").glob("cell_id=*/runs.parquet"))[0]
    table = pq.read_table(merged)
    df = table.to_pandas()
    df.loc[df["run"] == 2, ["seed", "filter_seed", "status", "error"]] = [-1, -1, "error", "worker failed"]
    pq.write_table(pa.Table.from_pandas(df, schema=table.schema, preserve_index=False), merged)
    again = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert again.returncode == 0, again.stderr
    assert f"{counted(1)} run, {counted(5)} already done" in again.stdout
    assert_same_runs(results.load(out), results.load(tiny[1]))


def test_a_deleted_series_file_makes_its_cell_incomplete_until_recomputed(tiny, tmp_path):
    path, out = copied(tiny, tmp_path)
    victim = sorted((out / ".work" / "series").glob("cell_id=*/run-00001.parquet"))[0]
    cell = victim.parent.name.split("=", 1)[1]
    victim.unlink()
    tables = cli("tables", out)
    assert tables.returncode == 0, tables.stderr
    warning = [line for line in tables.stderr.splitlines() if line.startswith("warning:")]
    assert len(warning) == 1 and f"cell {cell} (missing run 1's series file)" in warning[0], tables.stderr
    assert f"tanbench run {out / 'sweep.yaml'} --out {out}" in warning[0]
    again = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert again.returncode == 0, again.stderr
    assert "note: 1 stored run(s) have no series file" in again.stderr and f"{counted(1)} run" in again.stdout
    assert victim.exists()
    pd.testing.assert_frame_equal(pd.read_parquet(out / "series" / "summary.parquet"),
                                  pd.read_parquet(tiny[1] / "series" / "summary.parquet"))
    assert "warning" not in cli("tables", out).stderr


def test_a_deleted_runs_file_is_missing_everywhere_until_recomputed(tiny, tmp_path):
    path, out = copied(tiny, tmp_path)
    victim = sorted((out / "runs").glob("cell_id=*/runs.parquet"))[0]
    cell = victim.parent.name.split("=", 1)[1]
    victim.unlink()
    tables = cli("tables", out)
    assert f"warning: incomplete results: cell {cell} (no stored runs)" in tables.stderr, tables.stderr
    check = cli("check", out, tiny[1])
    assert check.returncode == 1 and f"missing: cell only in BASELINE: {cell}" in check.stdout, check.stdout
    again = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert again.returncode == 0 and f"{counted(3)} run, {counted(3)} already done" in again.stdout, again.stderr
    assert_same_runs(results.load(out), results.load(tiny[1]))


def test_an_unreadable_run_file_is_one_line_then_set_aside_and_recomputed(tiny, tmp_path):
    path, out = copied(tiny, tmp_path)
    victim = sorted((out / "runs").glob("cell_id=*/runs.parquet"))[0]
    victim.write_bytes(b"PAR1 not really")
    tables = cli("tables", out)
    lines = [line for line in tables.stderr.splitlines() if line.strip()]
    assert tables.returncode == 2 and len(lines) == 1 and "not a readable Parquet file" in lines[0], tables.stderr
    assert "sets a damaged run or series file, or series summary, aside and recomputes what it held" in lines[0]
    again = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert again.returncode == 0, again.stderr
    assert f"note: {victim} cannot be read" in again.stderr and victim.with_name(".runs.parquet.damaged").exists()
    assert_same_runs(results.load(out), results.load(tiny[1]))


@pytest.mark.parametrize("clone", [False, True], ids=["with-run-series", "clone-summary-only"])
def test_an_unreadable_series_summary_is_named_then_set_aside_and_rebuilt(tiny, tmp_path, clone):
    """A damaged series/summary.parquet: ``tables`` names it (with the command that mends it), ``run`` sets it aside
    and rebuilds it from the runs' series files, recomputing the runs that have none (a clone of committed
    results keeps only the summary); the rebuilt summary equals the one it replaces."""
    path, out = copied(tiny, tmp_path)
    if clone:
        shutil.rmtree(out / ".work")
    summary = out / "series" / "summary.parquet"
    summary.write_bytes(b"junk")
    tables = cli("tables", out)
    assert tables.returncode == 0 and "the series summary cannot be read" in tables.stderr, tables.stderr
    assert "plot" not in tables.stderr and f"tanbench run {out / 'sweep.yaml'} --out {out}" in tables.stderr
    plot = cli("plot", out)
    assert plot.returncode == 2 and "not a readable Parquet file" in plot.stderr and "series summary" in plot.stderr
    again = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert again.returncode == 0, again.stderr
    assert f"note: {summary} cannot be read" in again.stderr and summary.with_name(".summary.parquet.damaged").exists()
    assert f"{counted(6 if clone else 0)} run" in again.stdout
    pd.testing.assert_frame_equal(pd.read_parquet(summary), pd.read_parquet(tiny[1] / "series" / "summary.parquet"))
    assert "warning" not in cli("tables", out).stderr


def test_a_cell_with_fewer_runs_than_the_others_is_incomplete_and_the_command_keeps_the_run_count(tiny, tmp_path):
    """A sweep stopped part-way leaves cells with fewer runs than others: ``tables`` warns, and the command it prints
    asks for the run count the directory holds (``--runs``), not the sweep file's, so it recomputes only the missing
    runs."""
    path, out = copied(tiny, tmp_path)
    runs_file = sorted((out / "runs").glob("cell_id=*/runs.parquet"))[0]
    cell = runs_file.parent.name.split("=", 1)[1]
    table = pq.read_table(runs_file)
    df = table.to_pandas()
    pq.write_table(pa.Table.from_pandas(df[df["run"] < 2], schema=table.schema, preserve_index=False), runs_file)
    (out / ".work" / "series" / f"cell_id={cell}" / "run-00002.parquet").unlink()
    sweep_text = (out / "sweep.yaml").read_text()
    (out / "sweep.yaml").write_text(sweep_text.replace("runs: 3", "runs: 8"))  # the file's runs, not the stored count
    tables = cli("tables", out)
    assert f"cell {cell} (missing run 2 of " in tables.stderr and "--runs 3" in tables.stderr, tables.stderr
    again = cli("run", out / "sweep.yaml", "--out", out, "--workers", 1, "-q", "--runs", 3)
    assert again.returncode == 0 and f"{counted(1)} run, {counted(5)} already done" in again.stdout, again.stderr


def snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_another_seed_is_refused_even_with_force_and_nothing_is_deleted(tiny, tmp_path):
    """A sweep with another root seed sharing a cell with the stored one: --add is refused without
    advice that loses data, and --add --force is refused too (it used to delete the stored runs)."""
    path, out = copied(tiny, tmp_path)
    other = write_sweep(tmp_path / "b.yaml", sweep_dict(name="b", seed=7, runs=3,
                                                        tables={"particles": {"particles": [80, 90]}}))
    before = snapshot(out)
    for extra in ([], ["--force"]):
        proc = cli("run", other, "--out", out, "--workers", 1, "-q", "--add", *extra)
        lines = [line for line in proc.stderr.splitlines() if line.strip()]
        assert proc.returncode == 2 and len(lines) == 1, proc.stderr
        assert "one directory holds one root seed" in lines[0] and "--force" not in lines[0]
    assert snapshot(out) == before


def test_a_second_run_into_a_directory_being_written_is_refused_and_a_killed_writer_leaves_no_lock(tiny, tmp_path):
    """While a run holds a results directory's lock (store.directory_lock), another run into it is refused with one
    line and changes nothing; the lock dies with its process however it dies (kill -9), and a run that ends leaves no
    lock file behind."""
    path, out = copied(tiny, tmp_path)
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time; from pathlib import Path; from tanbench import store\n"
        "with store.directory_lock(Path(sys.argv[1])):\n"
        "    print('held', flush=True); time.sleep(600)\n"), str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        before = snapshot(out)
        refused = cli("run", path, "--out", out, "--workers", 1, "-q")
        lines = [line for line in refused.stderr.splitlines() if line.strip()]
        assert refused.returncode == 2 and len(lines) == 1, refused.stderr
        assert f"{out} is being written by another tanbench run (pid {holder.pid})" in lines[0]
        assert snapshot(out) == before
    finally:
        holder.kill()
        holder.wait()
    assert (out / store.LOCK_FILE).exists()  # killed: the file stays, the lock does not
    again = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert again.returncode == 0, again.stderr
    assert not (out / store.LOCK_FILE).exists()
    assert_same_runs(results.load(out), results.load(tiny[1]))


def test_with_series_none_an_unreadable_summary_is_left_as_it_is_and_still_named(tiny, tmp_path):
    """``run --series none`` rebuilds no summary, so it leaves an unreadable one where it is (no note that it would
    be rebuilt), and ``tables`` goes on naming it."""
    path, out = copied(tiny, tmp_path)
    summary = out / "series" / "summary.parquet"
    summary.write_bytes(b"junk")
    again = cli("run", path, "--out", out, "--workers", 1, "-q", "--series", "none")
    assert again.returncode == 0 and "summary.parquet cannot be read" not in again.stderr, again.stderr
    assert summary.read_bytes() == b"junk" and not summary.with_name(".summary.parquet.damaged").exists()
    assert "the series summary cannot be read" in cli("tables", out).stderr


def test_tables_asks_for_the_runs_of_the_last_session_even_where_no_cell_reached_them(tiny, tmp_path):
    """A session asked for 5 runs and stopped after the first 3 of every cell: the cells are even, yet incomplete;
    tables names them and asks for --runs 5 (the stored runs alone would say 3, and complete)."""
    path, out = copied(tiny, tmp_path)
    with open(out / "sessions.jsonl", "a") as fh:
        fh.write('{"sweep": "tiny", "runs": 5, "interrupted": true}\n')
    tables = cli("tables", out)
    assert "missing run 3 of" in tables.stderr and "--runs 5" in tables.stderr, tables.stderr
    (out / "sessions.jsonl").write_text('{"sweep": "tiny", "runs": 2}\n')  # fewer than stored: the stored count holds
    assert "warning" not in cli("tables", out).stderr


def test_the_run_count_of_a_directory_is_its_sweep_s_last_recorded_session(tmp_path):
    """``tables``' mending command takes ``--runs`` from the last session of the same sweep in sessions.jsonl: a
    session of a sweep added with --add, a damaged line and sessions of older versions (no runs) are passed over."""
    from tanbench.runner.resume import last_session_runs

    assert last_session_runs(tmp_path, "a") is None  # no sessions.jsonl
    (tmp_path / "sessions.jsonl").write_text("\n".join([
        '{"sweep": "a", "runs": 3}', '{"tasks_run": 4}', '{"sweep": "b", "runs": 50}', "not json", "[1, 2]", ""]))
    assert last_session_runs(tmp_path, "a") == 3
    assert last_session_runs(tmp_path, "b") == 50
    assert last_session_runs(tmp_path, "c") is None


def test_the_lock_of_a_directory_removed_meanwhile_is_one_clear_error(tmp_path):
    """store.directory_lock on a directory that is gone (removed by a refused run that had created it, between this
    run's check and its lock): one TanbenchError line, not a FileNotFoundError."""
    from tanbench.errors import TanbenchError

    with pytest.raises(TanbenchError, match="was removed while this run started"):
        with store.directory_lock(tmp_path / "gone"):
            pass
