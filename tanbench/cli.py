"""The ``tanbench`` command line (Typer).

Every command prints one clear ``error:`` line and exits 2 on bad input; a traceback
is shown only with ``--debug``. Exit codes: 0 success, 1 failed runs or an unexpected
error, 2 bad input, 130 interrupted.
"""

from __future__ import annotations

import json
import os
import shlex
import signal
import sys
from pathlib import Path
from typing import Optional

import typer

from tanbench import __version__
from tanbench.errors import TanbenchError
from tanbench.options import MAX_SEED
from tanbench.runner.executors import single_thread_environment

# before numpy, scipy or numba load: the CLI's numerics run one thread each, as its workers do, and it
# can fork its workers (executors.local_context); its kernels are not parallel
single_thread_environment()

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False, rich_markup_mode=None,
                  help="tanbench: Monte Carlo benchmark for underwater terrain-aided navigation.")
terrain_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None, help="Inspect the terrain: along-track depth and roughness.")
app.add_typer(terrain_app, name="terrain")

EXAMPLE = "\n\nExample: {}"


def _version(value: bool):
    if value:
        typer.echo(f"tanbench {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version."),
    debug: bool = typer.Option(False, "--debug", help="Show tracebacks instead of one-line errors."),
):
    """tanbench: Monte Carlo benchmark for underwater terrain-aided navigation."""


def _default_out(sweep) -> Path:
    return Path("results") / sweep.name


def _out_path(out: Optional[str], sweep) -> Path:
    """``--out`` as a path (default ``results/<name>``); an empty one is refused, not read as ``.``."""
    if out is None:
        return _default_out(sweep)
    if not out.strip():
        raise TanbenchError("--out '': give the results directory a name")
    return Path(out)


def _terminate_as_interrupt(signum, frame) -> None:
    """SIGTERM (``kill PID``, a batch scheduler's stop) and SIGHUP (the terminal closed) end a
    sweep as Ctrl-C does: the finished runs stay stored, the workers are stopped, and the resume
    hint is printed. Without this the CLI would die at once and leave its worker processes running."""
    raise KeyboardInterrupt


STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))


def _count(tasks: int, n_methods: int) -> str:
    """'30 tasks (90 runs)': a task is one Monte Carlo run of a cell, with every method (the bar counts runs)."""
    return (f"{tasks} task{'s' if tasks != 1 else ''} ({tasks * n_methods} run{'s' if tasks * n_methods != 1 else ''})")


def _resume_command(sweep_file: Path, out: Path, options: dict) -> str:
    """The command that resumes a sweep: what selects its tasks, where their series go, and the
    ``PYTHONPATH`` (a plug-in's) it ran with; quoted for a POSIX shell."""
    words = ["tanbench", "run", str(sweep_file), "--out", str(out)]
    for flag, value in options.items():
        if value is True:
            words.append(flag)
        elif value not in (None, False):
            words += [flag, str(value)]
    command = " ".join(shlex.quote(w) for w in words)
    path = os.environ.get("PYTHONPATH")
    return f"PYTHONPATH={shlex.quote(path)} {command}" if path else command


def _loaded(sweep_file: Path, runs: Optional[int]):
    """The sweep file (with ``--runs``), and a warning line on stderr for a very large one."""
    from tanbench.runner.plan import size_warning
    from tanbench.sweep import load_sweep

    sweep = load_sweep(sweep_file)
    if runs is not None:
        sweep = sweep.with_runs(runs)
    warning = size_warning(sweep)
    if warning:
        typer.echo(warning, err=True)
    return sweep


def _err(line: str) -> None:
    """A line on stderr, if there is still a terminal to write it to (SIGHUP)."""
    try:
        typer.echo(line, err=True)
    except OSError:
        pass


@app.command(help="Run (or resume) a sweep: every cell x method x Monte Carlo run, into Parquet."
             + EXAMPLE.format("tanbench run configs/quick.yaml --workers 2"))
def run(
    sweep_file: Path = typer.Argument(..., help="Sweep YAML file."),
    out: Optional[str] = typer.Option(None, "--out", "-o", metavar="DIR",
                                      help="Results directory [default: results/<name>]."),
    workers: Optional[int] = typer.Option(None, "--workers", "-w", min=1,
                                          help="Worker processes [default: the cores available]."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler",
                                            help="Dask scheduler address (tcp://host:8786) or 'local-dask'."),
    runs: Optional[int] = typer.Option(None, "--runs", min=1, help="Override the sweep's runs per cell."),
    force: bool = typer.Option(False, "--force", help="Recompute the sweep's runs 0..runs-1 even if stored, and "
                               "any stored run that would come out differently now; other stored runs are kept."),
    add: bool = typer.Option(False, "--add", help="Add to a results directory that holds another sweep's runs "
                             "(made with the same root seed)."),
    series: str = typer.Option("summary", "--series", help="Per-update series to keep: none, summary or full."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
):
    from tanbench.results import to_markdown
    from tanbench.runner.engine import MAX_POOL_STARTS, run_sweep

    sweep = _loaded(sweep_file, runs)
    out = _out_path(out, sweep)
    again = _resume_command(sweep_file, out, {"--workers": workers, "--scheduler": scheduler, "--runs": runs,
                                              "--series": series if series != "summary" else None,
                                              "--add": add, "--force": force})
    n_m = len(sweep.spec.methods)
    before = {sig: signal.signal(sig, _terminate_as_interrupt) for sig in STOP_SIGNALS}
    try:
        report = run_sweep(sweep, out, workers=workers, scheduler=scheduler, series=series, force=force, add=add,
                           progress=not quiet, echo=typer.echo, note=_err)
    except KeyboardInterrupt:  # before the tasks (validation) or after them (tables): nothing half-done
        _err(f"interrupted; resume with: {again}")
        raise typer.Exit(130) from None
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
    if report.interrupted:
        _err(f"interrupted: {_count(report.finished, n_m)} finished in this session are stored in {out}; "
             f"resume with: {again}")
        raise typer.Exit(130)
    typer.echo(f"{sweep.name}: {_count(report.finished, n_m)} run, {_count(report.skipped, n_m)} already done, "
               f"{report.wall_s:.1f} s; results in {out}")
    for name, table in report.tables.items():
        typer.echo(to_markdown(_compact(table), title=name))
    if report.failed_rows:
        for line in report.errors[:10]:
            typer.echo(f"failed: {line}", err=True)
        typer.echo(f"{report.failed_rows} run(s) failed (recorded with their errors; rerun to retry)", err=True)
    if report.lost:
        typer.echo(f"{_count(report.lost, n_m)} left unfinished: worker processes ended abruptly "
                   f"{MAX_POOL_STARTS} times ({report.lost_reason}); nothing of them is stored; rerun to retry: "
                   f"{again}", err=True)
    if report.failed_rows or report.lost:
        raise typer.Exit(1)


def _warn_incomplete(sweep, directory: Path) -> None:
    """One line on stderr naming the cells whose stored runs are not whole, and the command that completes them."""
    from tanbench.runner.resume import incomplete_cells

    missing, count = incomplete_cells(sweep, directory)
    if missing:
        cell, what = next(iter(missing.items()))
        more = f" and {len(missing) - 1} more cell(s)" if len(missing) > 1 else ""
        # the run count the directory was run with, where it is not its sweep file's (run with --runs)
        runs = {"--runs": count} if count and count != sweep.spec.runs else {}
        command = _resume_command(directory / "sweep.yaml", directory, runs)
        typer.echo(f"warning: incomplete results: cell {cell} ({what}){more}; recompute what is missing with: "
                   f"{command}", err=True)


def _compact(table):
    keep = [c for c in table.columns if c not in ("ci95_low_m", "ci95_high_m", "min_time_avg_error_m",
                                                   "max_time_avg_error_m", "std_final_error_m", "nees_below_95",
                                                   "time_avg_ci95_low_m", "time_avg_ci95_high_m", "n_diverged")]
    return table[keep]


@app.command(help="Show what a sweep will run: cells x methods x runs, what is done, a time estimate."
             + EXAMPLE.format("tanbench plan configs/zhou2017.yaml"))
def plan(
    sweep_file: Path = typer.Argument(..., help="Sweep YAML file."),
    out: Optional[str] = typer.Option(None, "--out", "-o", metavar="DIR",
                                      help="Results directory [default: results/<name>]."),
    workers: Optional[int] = typer.Option(None, "--workers", "-w", min=1,
                                          help="Worker processes to plan for [default: the cores available]."),
    runs: Optional[int] = typer.Option(None, "--runs", min=1,
                                       help="Override the sweep's runs per cell [default: the sweep's runs]."),
):
    from collections import Counter

    from tanbench import kernel_cache
    from tanbench.runner.plan import current_load, default_workers, make_plan
    from tanbench.runner.resume import ResumeState
    from tanbench.runner.validate import check_methods

    from tanbench.store import check_directory_path

    sweep = _loaded(sweep_file, runs)
    check_methods(sweep)
    out = _out_path(out, sweep)
    check_directory_path(out)  # as run would refuse it
    p = make_plan(sweep, out, ResumeState.read(sweep, out), workers)
    n_m = len(sweep.spec.methods)
    typer.echo(f"sweep {sweep.name}: {len(sweep.cells)} cell(s) x {n_m} method(s) x {sweep.spec.runs} run(s) "
               f"= {len(sweep.cells) * n_m * sweep.spec.runs} runs in {len(p.tasks)} task(s) (a task: one run "
               f"of a cell with every method)")
    done = Counter(cell for cell, run in p.done if run < sweep.spec.runs)
    for cell in sweep.cells:
        varied = ", ".join(f"{k}={v}" for k, v in cell.varied.items()) or "defaults"
        typer.echo(f"  {cell.cell_id}  [{', '.join(cell.tables)}]  {varied}: {done[cell.cell_id]}/{sweep.spec.runs} "
                   f"done, ~{p.costs[cell.cell_id] * sweep.spec.runs:.0f} core-s")
    todo = p.todo
    if not todo:
        typer.echo(f"to do: nothing, every task is stored in {out} ({_count(0, n_m)} left)")
        return
    warm = kernel_cache.is_warm(p.kernels())  # each method in each variant its cells compile
    parts = p.estimate_parts()
    start = (f"{parts['compile']:.0f} s compiling the numba kernels (cold cache) and starting workers"
             if not warm else f"{parts['compile']:.0f} s starting workers (kernels cached)")
    typer.echo(f"to do: {_count(len(todo), n_m)}, about {sum(parts.values()):.0f} s on {min(p.workers, max(1, len(todo)))} "
               f"worker(s) ({start}, {parts['tasks']:.0f} s running, {parts['fixed']:.0f} s around; "
               f"load average {current_load():.1f} on {default_workers()} core(s)); results in {out}")


@app.command(help="Validate a sweep file: keys, types, values, methods and their options, terrain, track, "
                  "sonar, memory, initial uncertainty (everything `run` checks before its first task)."
             + EXAMPLE.format("tanbench validate configs/zhou2017.yaml"))
def validate(sweep_file: Path = typer.Argument(..., help="Sweep YAML file.")):
    from tanbench.profiles import describe_profile, profile_settings
    from tanbench.config import flatten
    from tanbench.runner.validate import validate_sweep

    sweep = _loaded(sweep_file, None)
    validate_sweep(sweep)
    if sweep.spec.profile is not None:
        for line in describe_profile(sweep.spec.profile):
            typer.echo(line)
        given = flatten(sweep.spec.scenario)
        for key, value in profile_settings(sweep.spec.profile).items():
            if key in given and given[key] != value:
                typer.echo(f"  overridden by the sweep's scenario: {key} = {given[key]!r} (the profile's "
                           f"{value!r} is not used)")
    typer.echo(f"{sweep_file}: ok ({len(sweep.cells)} cell(s), {len(sweep.spec.methods)} method(s), "
               f"{sweep.spec.runs} run(s) per cell)")


@app.command("methods", help="List the TAN methods a sweep can name, with their options."
             + EXAMPLE.format("tanbench methods --options"))
def methods_command(
    options: bool = typer.Option(False, "--options", help="Show every option with its default."),
    extra: list[str] = typer.Argument(None, help="User methods to describe (package.module:function)."),
):
    from tanbench.methods.registry import get, names

    for name in [*names(), *(extra or [])]:
        record = get(name)
        typer.echo(f"{record.name:<12} {record.summary}")
        if not options:
            continue
        typer.echo(f"{'':<12} states: {', '.join(record.states)}; seed id {record.seed_id}; "
                   f"plan cost {record.cost_ns:g} ns per unit")
        if record.options is None:
            typer.echo(f"{'':<12} options: the scenario's filter.* settings (tanbench validate shows them)")
            continue
        for key, info in record.options.model_fields.items():
            typer.echo(f"{'':<12} method_options.{record.name}.{key} = {info.default!r}"
                       + (f"  {info.description}" if info.description else ""))


@app.command(help="Print the summary tables of a results directory."
             + EXAMPLE.format("tanbench tables results/zhou2017 --compare-paper"))
def tables(
    directory: Path = typer.Argument(..., help="Results directory."),
    fmt: str = typer.Option("md", "--format", "-f", help="md or csv."),
    compare_paper: bool = typer.Option(False, "--compare-paper", help="Beside the paper's published values."),
):
    from tanbench.results import load, sweep_tables, to_markdown
    from tanbench.sweep import load_results_sweep

    if fmt not in ("md", "csv"):
        raise TanbenchError(f"--format must be md or csv, not {fmt!r}")
    sweep = load_results_sweep(directory)
    result = sweep_tables(load(directory), sweep)
    _warn_incomplete(sweep, directory)
    if not result:
        raise TanbenchError(f"{directory}: no runs of the cells of {directory / 'sweep.yaml'} are stored "
                            f"(run the sweep first)")
    if compare_paper:
        from tanbench.paper import PAPER_TABLES, compare_with_paper

        result = compare_with_paper(result)
        if not any("paper_mean_final_error_m" in t or "paper_mean_time_avg_error_m" in t for t in result.values()):
            typer.echo(f"note: --compare-paper: none of this sweep's tables ({', '.join(result)}) is one of the "
                       f"paper's ({', '.join(PAPER_TABLES)}, as in configs/zhou2017.yaml); no paper column to show",
                       err=True)
    if fmt == "csv":
        # one CSV (every table's rows; the `table` column tells them apart), so it parses as one file
        import pandas as pd

        typer.echo(pd.concat(list(result.values()), ignore_index=True).to_csv(index=False), nl=False)
        return
    for name, table in result.items():
        typer.echo(to_markdown(table if compare_paper else _compact(table), title=name))


@app.command(help="The reproduction criterion (docs/model.md section 11): pass probabilities of a faithful copy "
                  "of Zhou et al. 2017, simulated from the paper's numbers, as Markdown."
             + EXAMPLE.format("tanbench criterion --out results/criterion/CRITERION.md"))
def criterion(
    out: Optional[Path] = typer.Option(None, "--out", help="Write the Markdown here (default: print it)."),
    reps: int = typer.Option(2000, "--reps", min=100, help="Simulated copies per scenario."),
):
    from tanbench import store
    from tanbench.report import faithful_markdown

    text, table = faithful_markdown(reps=reps)
    if out is None:
        typer.echo(text, nl=False)
        return
    out.parent.mkdir(parents=True, exist_ok=True)
    store.write_text(text, out)
    csv = out.with_name("faithful.csv")
    store.write_text(table.to_csv(index=False, float_format="%.4f"), csv)
    typer.echo(f"wrote {out} and {csv}")


@app.command(help="Simulate one run (truth, sensors, navigation system) and write it as Parquet or CSV, or as a "
             "mission log that `tanbench replay` reads (docs/missions.md)."
             + EXAMPLE.format("tanbench simulate --area A --seed 1 --out run.parquet"))
def simulate(
    area: Optional[str] = typer.Option(None, "--area", help="A, B or vehicle [default: A]."),
    seed: int = typer.Option(1, "--seed", min=0, max=MAX_SEED, help="Seed of the run's vehicle data (0 to 2**63 - 1)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="File to write: .parquet or .csv."),
    duration: Optional[float] = typer.Option(None, "--duration", help="Seconds [default: the whole run]."),
    every: int = typer.Option(1, "--every", min=1, help="Keep every n-th IMU sample (--out only)."),
    sweep_file: Optional[Path] = typer.Option(None, "--sweep", help="Simulate the first cell of this sweep's "
                                              "scenario instead of an --area."),
    log: Optional[Path] = typer.Option(None, "--log", help="Also write the run as a mission log into this directory, "
                                       "with its navigation map (map.npz) and method settings (settings.yaml)."),
    lonlat: bool = typer.Option(False, "--lonlat", help="The mission log's positions in WGS84 lon/lat (the terrain "
                                "must be georeferenced)."),
    log_format: str = typer.Option("parquet", "--log-format", help="The mission log's tables: parquet or csv."),
    force: bool = typer.Option(False, "--force", help="Overwrite the mission log already in --log DIR, if it is a "
                               "simulated one (a recorded log is never overwritten)."),
):
    import math

    import numpy as np
    from pydantic import ValidationError

    from tanbench.config import Scenario
    from tanbench.config import format_validation_error
    from tanbench.simulation import motion_plan, simulate_vehicle, vehicle_frame

    if area is not None and area not in ("A", "B", "vehicle"):
        raise TanbenchError(f"--area must be A, B or vehicle, not {area!r}")
    if area is not None and sweep_file is not None:
        raise TanbenchError("give --area or --sweep, not both")
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise TanbenchError(f"--duration must be a positive number of seconds, not {duration:g}")
    if out is not None and out.suffix.lower() not in (".parquet", ".csv"):
        raise TanbenchError(f"--out {out}: use a .parquet or .csv file name")
    if log_format not in ("parquet", "csv"):
        raise TanbenchError(f"--log-format must be parquet or csv, not {log_format!r}")
    if lonlat and log is None:
        raise TanbenchError("--lonlat applies to the mission log: give --log DIR")
    if force and log is None:
        raise TanbenchError("--force applies to the mission log: give --log DIR")
    if log is not None:
        from tanbench.missions.logfile import check_log_directory

        check_log_directory(log, force)  # before the simulation, not after it
    if sweep_file is not None:
        from tanbench.sweep import load_sweep

        base = load_sweep(sweep_file).cells[0].scenario.normalized()
        label = f"{sweep_file}"
    else:
        base, label = {"area": area or "A"}, f"area {area or 'A'}"
    try:
        scenario = Scenario(**{**base, "duration_s": duration if duration is not None else base.get("duration_s")})
    except ValidationError as exc:
        raise TanbenchError(f"--duration: {format_validation_error(exc)}") from None
    try:
        motion_plan(scenario)
    except TanbenchError as exc:  # a duration longer than the trajectory
        raise TanbenchError(f"--duration: {exc}") from None
    if lonlat:
        from tanbench.missions.simulated import lonlat_frame

        lonlat_frame(scenario)  # refuses a terrain without geographic georeferencing, before simulating
    vehicle = simulate_vehicle(scenario, np.random.SeedSequence(seed))
    df = vehicle_frame(vehicle, every)
    err = np.hypot(df["nav_e"] - df["truth_e"], df["nav_n"] - df["truth_n"])
    typer.echo(f"{label}, seed {seed}: {df['t'].iloc[-1]:.0f} s, {len(vehicle.obs.ping_idx)} sonar pings; "
               f"navigation system final horizontal error {err.iloc[-1]:.1f} m (max {err.max():.1f} m), "
               f"heading error {vehicle.initial_heading_error_deg:+.0f} deg at start, "
               f"{(df['nav_heading_deg'] - df['truth_heading_deg'] + 180).mod(360).iloc[-1] - 180:+.1f} deg at end")
    if log is not None:
        _write_mission_log(scenario, vehicle, seed, log, lonlat, log_format, force)
    if out is not None:
        from tanbench import store

        try:
            if out.suffix.lower() == ".csv":
                store.write_text(df.to_csv(index=False), out)
            else:
                store.write_parquet(df, out, {"schema_version": store.SCHEMA_VERSION, "kind": "simulation",
                                              "scenario": scenario.normalized(), "seed": seed})
        except OSError as exc:
            raise TanbenchError(f"cannot write {out}: {exc.strerror or exc}") from None
        typer.echo(f"wrote {out} ({len(df)} rows x {len(df.columns)} columns)")


def _write_mission_log(scenario, vehicle, seed: int, log: Path, lonlat: bool, log_format: str,
                       force: bool = False) -> None:
    """``simulate --log``: the mission log, the navigation map and the method settings of the run."""
    from tanbench import store
    from tanbench.missions.logfile import write_log
    from tanbench.missions.simulated import MAP_FILE, SETTINGS_FILE, settings_text, simulated_log, write_map
    from tanbench.terrain import navigation_map

    mission = simulated_log(scenario, vehicle, seed, lonlat)
    files = write_log(log, mission, log_format, overwrite=force)
    write_map(navigation_map(scenario.terrain, scenario.map_resolution_m), log / MAP_FILE)
    store.write_text(settings_text(scenario, lonlat), log / SETTINGS_FILE)
    typer.echo(f"wrote the mission log {log} ({len(files) - 1} tables, {'lon/lat' if lonlat else 'map-frame'} "
               f"positions), its navigation map {log / MAP_FILE} and method settings {log / SETTINGS_FILE}")


@app.command(help="Run methods over a recorded mission log (docs/missions.md) and a map; score them against the "
             "log's reference track when it has one, else write their estimates only."
             + EXAMPLE.format("tanbench replay mission --map mission/map.npz --methods tight-dvl,pmf-dvl"))
def replay(
    log: Path = typer.Argument(..., help="Mission-log directory."),
    map_path: Optional[str] = typer.Option(None, "--map", help="The navigation map: a bathymetry file, files or "
                                           "glob of tiles (docs/maps.md) [default: map.path of --settings]."),
    methods: Optional[list[str]] = typer.Option(None, "--methods", "-m", help="Methods, comma-separated or "
                                                "repeated [default: tight-dvl,tight-sbe,loose-dvl]."),
    settings: Optional[Path] = typer.Option(None, "--settings", help="YAML of the methods' settings (profile, "
                                            "particles, sampling_time_s, filter, method_options) and the map's "
                                            "options (map: crs, rows, map_error_m, ...)."),
    seed: int = typer.Option(0, "--seed", min=0, max=MAX_SEED, help="Seed of the methods' random numbers (0 to 2**63 - 1)."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Results directory [default: results/replay-<log>]."),
):
    import pandas as pd

    from tanbench.missions.replay import replay as replay_log
    from tanbench.results import to_markdown

    report = replay_log(log, map_path, methods, settings, seed, out, echo=lambda m: typer.echo(m, err=True))
    for note in report.notes:
        typer.echo(f"note: {note}", err=True)
    rows = pd.DataFrame(report.rows)
    if report.has_reference:
        keep = ["method", "status", "final_horizontal_error_m", "mean_horizontal_error_m", "rmse_after_convergence_m",
                "final_heading_error_deg", "diverged", "filter_wall_s"]
        title = "scored against the log's reference track"
    else:
        keep = ["method", "status", "filter_wall_s"]
        title = "no reference track: estimates only"
    typer.echo(to_markdown(rows[[c for c in keep if c in rows.columns]], title=f"{log}: {title}"))
    typer.echo(f"results in {report.out} (runs.parquet, estimates.parquet"
               f"{', series.parquet' if report.has_reference else ''})")
    if report.failed:
        for row in report.failed:
            typer.echo(f"failed: {row['method']}: {row['error']}", err=True)
        raise typer.Exit(1)


@terrain_app.command("stats", help="Depth and roughness under the tracks (the paper's Section 4.2 statistics)."
                     + EXAMPLE.format("tanbench terrain stats --sweep configs/monterey.yaml"))
def terrain_stats(
    sweep_file: Optional[Path] = typer.Option(None, "--sweep", help="Use the worlds of this sweep."),
    fmt: str = typer.Option("md", "--format", "-f", help="md, csv or json."),
):
    import warnings

    import pandas as pd

    from tanbench.config import Scenario
    from tanbench.results import to_markdown
    from tanbench.simulation import motion_plan
    from tanbench.terrain import navigation_map, truth_map
    from tanbench.terrain.stats import track_statistics
    from tanbench.vehicle.trajectory import sample_path

    if fmt not in ("md", "csv", "json"):
        raise TanbenchError(f"--format must be md, csv or json, not {fmt!r}")
    if sweep_file is not None:
        from tanbench.sweep import load_sweep

        scenarios = [c.scenario for c in load_sweep(sweep_file).cells]
    else:
        scenarios = [Scenario(area="A"), Scenario(area="B"), Scenario(area="vehicle")]
    rows, seen, seams = [], set(), []
    for sc in scenarios:
        key = sc.world_key()
        if key in seen:
            continue
        seen.add(key)
        truth = truth_map(sc.terrain)
        _, pos = sample_path(motion_plan(sc), 1.0)
        maps = {}
        for res in sorted({10.0, 20.0, 30.0, sc.map_resolution_m}):
            if res >= truth.resolution - 1e-9:
                try:
                    maps[res] = navigation_map(sc.terrain, res)
                except ValueError:
                    pass
        with warnings.catch_warnings():  # statistics of the on-map points only; all off the map is refused below
            warnings.simplefilter("ignore", RuntimeWarning)
            stats = track_statistics(truth, pos[:, :2], maps)
        if stats["off_map_points"] == stats["points"]:
            raise TanbenchError(
                f"{sweep_file or 'area ' + sc.area}: the track (area {sc.area}, trajectory {sc.trajectory.kind}) "
                f"lies entirely off the map {truth.name}; nothing to measure (check the trajectory's start or "
                f"centre against the map's extent)")
        if stats["off_map_points"]:
            seams.append(f"note: {stats['off_map_points']} of {stats['points']} track points of area {sc.area} "
                         f"are off the map {truth.name} (left out of the statistics)")
        rows.append({"area": sc.area, "terrain": truth.name, **stats})
        for seam in truth.meta.get("seams", []):
            tiles = " / ".join(Path(str(t)).name for t in seam.get("tiles", ()))
            seams.append(f"seam {tiles} ({seam.get('kind')}): mean step "
                         f"{seam.get('mean_abs_step', float('nan')):.2f} m, max {seam.get('max_abs_step', float('nan')):.2f} m")
    df = pd.DataFrame(rows)
    if fmt == "json":
        typer.echo(df.to_json(orient="records", indent=1))
    elif fmt == "csv":
        typer.echo(df.to_csv(index=False), nl=False)
    else:
        typer.echo(to_markdown(df, title="seafloor under the track (nadir, 1 Hz)"))
        typer.echo("A flat track (small depth std and slope) is not an error, but TAN has little to work with.")
        for line in seams:
            typer.echo(line)


def _metres(value: float) -> str:
    """An elevation for ``terrain info``: one decimal, or 6 significant digits past 1e9 m (absurd, but shown)."""
    return f"{value:.1f}" if abs(value) < 1e9 else f"{value:.6g}"


@terrain_app.command("info", help="A map's nodes, spacing, extent in tanbench's frame (where a trajectory's "
                     "start_en_m or centre_en_m goes) and elevations, as a sweep's terrain reads it."
                     + EXAMPLE.format("tanbench terrain info '../shared/data/monterey/MontereyBay.R_*.tif'"))
def terrain_info(
    path: Optional[str] = typer.Argument(None, help="A map file or a quoted glob of tiles (terrain kind file)."),
    sweep_file: Optional[Path] = typer.Option(None, "--sweep", help="The maps of this sweep's worlds instead."),
    rows: str = typer.Option("auto", "--rows", help="terrain.rows for a map file: auto, south_to_north or "
                                                   "north_to_south."),
    crs: Optional[str] = typer.Option(None, "--crs", help="terrain.crs for a map file [default: from the file]."),
):
    import numpy as np
    from pydantic import ValidationError

    from tanbench.config import TerrainSpec, format_validation_error
    from tanbench.terrain import truth_map

    if (path is None) == (sweep_file is None):
        raise TanbenchError("give a map file (or a glob of tiles) or --sweep FILE, one of them")
    if sweep_file is not None:
        from tanbench.sweep import load_sweep

        specs = list({c.scenario.terrain.model_dump_json(): c.scenario.terrain
                      for c in load_sweep(sweep_file).cells}.values())
    else:
        try:
            specs = [TerrainSpec(kind="file", path=path, rows=rows, crs=crs)]
        except ValidationError as exc:
            raise TanbenchError(f"terrain: {format_validation_error(exc)}") from None
    frames = {"local": "local (lon/lat projected about the map's origin)", "metric": "metric (metres)"}
    for spec in specs:
        try:
            m = truth_map(spec)
        except TanbenchError as exc:
            if sweep_file is not None or "georeferenc" not in str(exc):
                raise
            raise TanbenchError(f"{exc} (terrain info takes --rows and --crs; for other terrain options write them "
                                f"in a sweep's terrain and give --sweep)") from None
        ny, nx = m.shape
        finite = m.z[np.isfinite(m.z)]
        frame = m.meta.get("crs", "metric")
        where = ""
        if frame == "local":  # lon/lat projected: where the frame's corners are on the globe
            from tanbench.terrain.georef import local_to_lonlat

            lon, lat = local_to_lonlat(m, [m.e0, m.e_max], [m.n0, m.n_max])
            where = f" (E {m.e0:.1f}, N {m.n0:.1f} m is lon {lon[0]:.5f}, lat {lat[0]:.5f}; E {m.e_max:.1f}, " \
                    f"N {m.n_max:.1f} m is lon {lon[1]:.5f}, lat {lat[1]:.5f})"
        low, high = finite.min(), finite.max()
        with np.errstate(over="ignore", invalid="ignore"):
            mean = finite.mean()
            if not np.isfinite(mean):  # the sum overflowed (elevations near the float limit): a scaled mean
                top = max(abs(low), abs(high))
                mean = np.mean(finite / top) * top
        typer.echo(f"{m.name or spec.kind}: {nx} x {ny} nodes at {m.res_e:.2f} x {m.res_n:.2f} m; "
                   f"E {m.e0:.1f} .. {m.e_max:.1f} m, N {m.n0:.1f} .. {m.n_max:.1f} m; elevation (up positive) "
                   f"{_metres(low)} .. {_metres(high)} m, mean {_metres(mean)}; "
                   f"{m.z.size - finite.size} holes; frame {frames.get(frame, frame)}{where}")
    typer.echo("E and N are the frame of a trajectory's start_en_m and centre_en_m (docs/maps.md).")


@terrain_app.command("suitability", help="Per-node TAN suitability of a map (predicted position std after N "
                     "pings, slope std, roughness, terrain entropy) as GeoTIFF and PNG with the tracks drawn."
                     + EXAMPLE.format("tanbench terrain suitability configs/zhou2017.yaml --track"))
def terrain_suitability(
    target: Path = typer.Argument(..., help="A bathymetry file (the map as it is) or a sweep YAML."),
    sensor: str = typer.Option("dvl", "--sensor", help="dvl (4 Janus beams), sbe (one nadir beam) or mbe (a "
                                                      "multibeam fan: --beams, --swath)."),
    beams: int = typer.Option(64, "--beams", help="mbe: beams in the fan."),
    swath: float = typer.Option(120.0, "--swath", help="mbe: the fan's full angle across track, deg."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Output directory [default: results/suitability]."),
    pings: int = typer.Option(10, "--pings", min=1, help="Pings of the predicted position std."),
    track: bool = typer.Option(False, "--track", help="Print the measures' means along the sweep's tracks."),
    altitude: Optional[float] = typer.Option(None, "--altitude", min=0.1,
                                             help="Altitude above the seafloor, m [default: the tracks' median, "
                                                  "or 30 m for a map file]."),
    noise: Optional[float] = typer.Option(None, "--noise", min=0.0,
                                          help="Range-noise half-width, m [default: the sweep's, or 1 m]."),
    window: float = typer.Option(50.0, "--window", min=1.0, help="Window side of the classical measures, m."),
):
    import pandas as pd

    from tanbench.results import to_markdown
    from tanbench.suitability import (MEASURES, plot_suitability, sensor_beams, sources_from, suitability,
                                              track_summary, write_geotiff)

    if sensor not in ("dvl", "sbe", "mbe"):
        raise TanbenchError(f"--sensor must be dvl, sbe or mbe, not {sensor!r}")
    fan = None
    if sensor == "mbe":
        from pydantic import ValidationError

        from tanbench.config import SensorSpec, format_validation_error

        try:
            fan = SensorSpec(multibeam_beams=beams, multibeam_swath_deg=swath)
        except ValidationError as exc:
            raise TanbenchError("--beams/--swath: " + format_validation_error(exc)) from None
        if beams < 1:
            raise TanbenchError(f"--beams must be at least 1, not {beams}")
    sources = sources_from(target, altitude, noise)
    if track and not any(s.tracks for s in sources):
        raise TanbenchError(f"{target}: --track needs a sweep file (a map file has no tracks)")
    if any(s.noise_m <= 0 for s in sources):
        raise TanbenchError("the range noise is zero: a ping's information is unbounded; give --noise > 0")
    out = out or Path("results") / "suitability"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise TanbenchError(f"cannot create {out}: {exc.strerror or exc}") from None
    rows = []
    for src in sources:
        # the multibeam's range std is its own (sensors.multibeam_range_noise_m) unless --noise is given
        std = fan.multibeam_range_noise_m if fan is not None and noise is None else src.noise_m / 3 ** 0.5
        result = suitability(src.grid, sensor_beams(sensor, sensors=fan), src.altitude_m, std, pings,
                             src.initial_area_m, window, sensor)
        stem = f"{src.label}-{sensor}"
        for name in MEASURES:
            write_geotiff(result.layers[name], src.grid, out / f"{stem}-{name}.tif")
        plot_suitability(result, src.tracks, out / f"{stem}.png")
        typer.echo(f"{src.label}: {src.grid.shape[1]} x {src.grid.shape[0]} nodes, {sensor} at "
                   f"{src.altitude_m:.1f} m altitude; wrote {out / stem}.png and {len(MEASURES)} GeoTIFFs")
        if track:
            rows += [{"map": src.label, **r} for r in track_summary(result, src.tracks)]
    if track:
        typer.echo(to_markdown(pd.DataFrame(rows), title=f"suitability along the tracks ({sensor}, {pings} pings)"))


@app.command(help="Compare two results directories: did NEW's error statistics regress from BASELINE? "
             "Exit 0 nothing regressed, 1 something did or a cell, method or run is missing on either side, "
             "2 bad input."
             + EXAMPLE.format("tanbench check results/ci results/ci-baseline --report check.md"))
def check(
    new: Path = typer.Argument(..., help="Results directory under test."),
    baseline: Path = typer.Argument(..., help="Reference results directory."),
    margin_rel: float = typer.Option(0.10, "--margin-rel", min=0.0, help="Relative margin of the worse/better tests."),
    margin_abs: float = typer.Option(1.0, "--margin-abs", min=0.0, help="Absolute margin, metres."),
    alpha: float = typer.Option(0.05, "--alpha", min=1e-9, max=0.5, help="Level after Holm's correction."),
    report: Optional[Path] = typer.Option(None, "--report", help="Also write the table (.md, .json or .parquet)."),
    allow_missing: bool = typer.Option(False, "--allow-missing",
                                       help="Pass even if cells, methods or runs are in only one directory "
                                            "(they are still listed)."),
    allow_underpowered: bool = typer.Option(False, "--allow-underpowered",
                                            help="Pass even if rows could not detect their margin (twice the "
                                                 "margin; lost runs: --lost-detect) or have too few runs "
                                                 "(they are still listed as such)."),
    pool: str = typer.Option("none", "--pool", help="none, or method: the verdict pools each method over the "
                             "matched cells (values / the cell's baseline mean); cell rows shown for information."),
    lost_detect: float = typer.Option(0.05, "--lost-detect", min=1e-6, max=1.0,
                                      help="Increase of the lost-run rate every lost-run row must be able to "
                                           "detect (0.05: 5 more lost runs in 100)."),
    min_runs: int = typer.Option(10, "--min-runs", min=2, help="Fewer runs in a row: reported as too few runs."),
    nees: bool = typer.Option(False, "--nees", help="Also regress on consistency: the fraction of updates whose "
                              "NEES lies outside its 95 % chi-square bounds."),
    nees_margin: float = typer.Option(0.05, "--nees-margin", min=0.0, max=1.0,
                                      help="Absolute margin of the NEES metric (a fraction of updates)."),
    ignore: Optional[list[str]] = typer.Option(
        None, "--ignore", help="A scenario column left out of the cell match (repeat for several): compares cells "
                               "that differ only there, e.g. --ignore filter.random_numbers."),
    until_decisive: bool = typer.Option(False, "--until-decisive",
                                        help="Add runs to both directories (their own sweep.yaml, same seeds) in "
                                             "batches until every row is decided or --cap; alpha is spent "
                                             "evenly over the planned looks."),
    batch: int = typer.Option(30, "--batch", min=1, help="Runs per cell added at each look (--until-decisive)."),
    cap: int = typer.Option(300, "--cap", min=1, help="Most runs per cell (--until-decisive)."),
):
    from tanbench.check import CheckOptions, check_report_path, compare, render, write_report

    if report is not None:  # before any work: --until-decisive adds runs to both directories
        check_report_path(report)
    opts = CheckOptions(margin_rel=margin_rel, margin_abs=margin_abs, alpha=alpha, nees=nees,
                        nees_margin_abs=nees_margin, ignore=tuple(ignore or ()), pool=pool,
                        lost_detect=lost_detect, min_runs=min_runs)
    if until_decisive:
        from tanbench.runner.sequential import until_decisive as run_until

        result = run_until(new, baseline, opts, batch, cap, echo=typer.echo)
    else:
        result = compare(new, baseline, opts)
    typer.echo(render(result))
    if report is not None:
        write_report(result, report)
        typer.echo(f"wrote {report}")
    if result.missing and not allow_missing:
        typer.echo(f"check fails: {len(result.missing)} cell(s), method(s) or run(s) are in only one directory "
                   f"(listed above as 'missing:'; --allow-missing compares only what both hold)", err=True)
    if result.underpowered and not allow_underpowered:
        typer.echo("check fails: some rows could not have detected their margin (underpowered) or have too few "
                   "runs; add runs (--until-decisive) or pass --allow-underpowered to accept it", err=True)
    if (result.regressed or (result.missing and not allow_missing)
            or (result.underpowered and not allow_underpowered)):
        raise typer.Exit(1)


@app.command(help="Draw the figures of a results directory (PNG under DIR/figures/; needs the plot extra). "
             "Every figure's title names its cell; --cell picks the cells."
             + EXAMPLE.format("tanbench plot results/zhou2017 --cell all"))
def plot(
    directory: Path = typer.Argument(..., help="Results directory."),
    cell: Optional[list[str]] = typer.Option(
        None, "--cell", help="Cell id (or a unique prefix) to draw; repeat for several, 'all' for every cell "
                             "[default: the first cell of each area]."),
    frontier: bool = typer.Option(False, "--frontier",
                                  help="Only the accuracy-cost figure: mean final error against filter wall "
                                       "time per run, per method and cell."),
):
    from tanbench.plot import plot_frontier, plot_results, unstyled_methods

    written = [plot_frontier(directory)] if frontier else plot_results(directory, cell)
    for method in unstyled_methods(directory):
        typer.echo(f"note: method {method} cannot be imported here: drawn in a spare colour, not its record's "
                   f"style (put its package on PYTHONPATH)", err=True)
    typer.echo(f"wrote {len(written)} figure(s) under {directory / 'figures'}")


@app.command(help="Write REPORT.md for a reproduction of the paper: tables beside the paper, claims, figures."
             + EXAMPLE.format("tanbench report results/zhou2017"))
def report(
    directory: Path = typer.Argument(..., help="Results directory of configs/zhou2017.yaml."),
    discussion: Optional[Path] = typer.Option(Path("docs/zhou2017-discussion.md"), "--discussion",
                                              help="Hand-written discussion appended to the report."),
    literal: Optional[Path] = typer.Option(None, "--literal",
                                           help="Results of configs/zhou2017-literal.yaml, shown side by side."),
    anatomy: Optional[Path] = typer.Option(None, "--anatomy",
                                           help="Results of configs/zhou2017-anatomy.yaml (the anatomy table)."),
    other_seafloor: Optional[Path] = typer.Option(
        None, "--other-seafloor", help="Results of configs/zhou2017-literal-seed2.yaml (the literal profile on "
                                       "another seafloor: its fixed check)."),
    seafloors: Optional[Path] = typer.Option(
        None, "--seafloors", help="Directory of the many-seafloor sweeps (results/seafloors, make seafloors)."),
    family: Optional[list[Path]] = typer.Option(
        None, "--family", help="Results of the literal family (make literal-family); repeatable."),
    fitted: Optional[Path] = typer.Option(
        None, "--fitted", help="Results of configs/zhou2017-fitted.yaml (make fitted): the fitted profile's "
                               "held-out tables; its fit's scores are read from <DIR>-fit."),
):
    from tanbench.report import write_report

    for label, d in (("--literal", literal), ("--anatomy", anatomy), ("--other-seafloor", other_seafloor),
                     ("--fitted", fitted), *(("--family", f) for f in family or [])):
        if d is not None and not (d / "sweep.yaml").exists():
            raise TanbenchError(f"{label} {d}: not a tanbench results directory (no sweep.yaml)")
    if seafloors is not None and not seafloors.is_dir():
        raise TanbenchError(f"--seafloors {seafloors}: not a directory")
    path = write_report(directory, discussion, literal=literal, anatomy=anatomy, other_seafloor=other_seafloor,
                        seafloors=seafloors, family=family or None, fitted=fitted)
    typer.echo(f"wrote {path}")


@app.command("fit-profile", help="Score the fit of the zhou2017-fitted profile (docs/model.md 11.3) from the runs of "
                                  "configs/zhou2017-fitted-fit.yaml: writes DIR/FIT.md, scores.csv and targets.csv and "
                                  "checks that tanbench/profiles.py holds the selected values."
             + EXAMPLE.format("tanbench fit-profile results/zhou2017-fitted-fit"))
def fit_profile(directory: Path = typer.Argument(..., help="Results directory of configs/zhou2017-fitted-fit.yaml.")):
    from tanbench.fit import selected_settings, write_fit
    from tanbench.profiles import FITTED_SETTINGS

    scores, chosen = write_fit(directory)
    selected = selected_settings(scores)
    typer.echo(f"wrote {directory / 'FIT.md'}; selected {chosen}: "
               + ", ".join(f"{k} = {v!r}" for k, v in selected.items()))
    if selected != FITTED_SETTINGS:
        raise TanbenchError(f"the fit selects {selected} but tanbench/profiles.py's FITTED_SETTINGS holds "
                            f"{FITTED_SETTINGS}: set FITTED_SETTINGS to the selection before the held-out sweep")


@app.command(help="Prediction checked against outcome: Spearman rank correlations of the terrain suitability "
             "and the PCRB with each method's errors over results directories; a table and a scatter figure."
             + EXAMPLE.format("tanbench predict results/zhou2017 results/monterey --out results/prediction"))
def predict(
    directories: list[Path] = typer.Argument(..., help="Results directories."),
    out: Path = typer.Option(Path("results") / "prediction", "--out", "-o", help="Output directory."),
):
    from tanbench.prediction import write_prediction
    from tanbench.results import to_markdown

    cells, corr = write_prediction(directories, out)
    typer.echo(to_markdown(corr[corr["outcome"] == "mean_time_avg_error_m"],
                           title=f"Spearman rho over {len(cells)} (cell, method) pairs"))
    typer.echo(f"wrote {out / 'prediction.md'}, {out / 'prediction.parquet'}, {out / 'prediction.png'}")


@app.command(help="The anatomy of an anatomy (or any ablation) sweep: per key cell, switch and method, the mean "
                  "paired difference of the final error (or --column) from the <cell>__literal (or --baseline) "
                  "table, with a 95 % interval; writes DIR/tables/anatomy*.csv and prints Markdown."
             + EXAMPLE.format("tanbench anatomy results/zhou2017-anatomy"))
def anatomy(directory: Path = typer.Argument(..., help="Results directory of an anatomy sweep."),
            baseline: str = typer.Option("literal", "--baseline", help="The switch the others are compared with "
                                                                       "(tables <cell>__<baseline>)."),
            column: str = typer.Option("final_horizontal_error_m", "--column",
                                       help="The per-run metric compared (a column of the runs)."),
            digits: int = typer.Option(1, "--digits", min=0, max=6, help="Digits after the point.")):
    from tanbench.anatomy import anatomy_markdown, anatomy_table
    from tanbench.results import load
    from tanbench import store
    from tanbench.sweep import load_results_sweep

    runs = load(directory)
    if not runs.empty and column not in runs.columns:
        raise TanbenchError(f"--column {column}: not a column of {directory}'s runs")
    table = anatomy_table(runs, load_results_sweep(directory), column=column, baseline=baseline)
    if table.empty:
        raise TanbenchError(f"{directory}: no <cell>__{baseline} / <cell>__<switch> tables with runs "
                            f"(not an anatomy sweep, or not run yet)")
    name = "anatomy" if (baseline, column) == ("literal", "final_horizontal_error_m") else f"anatomy-{baseline}-{column}"
    (directory / "tables").mkdir(parents=True, exist_ok=True)
    store.write_text(table.to_csv(index=False), directory / "tables" / f"{name}.csv")
    switch_to = "switch to recommended" if baseline == "literal" else "switch"
    typer.echo(anatomy_markdown(table, baseline, switch_to, "m" if column.endswith("_m") else column, digits))


@app.command(help="Benchmark every method (ns per particle-step, run time, numpy ratio, kernels)."
             + EXAMPLE.format("tanbench bench --json"))
def bench(as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
          particles: int = typer.Option(3000, "--particles", min=16, help="Particles of the bench run."),
          repeats: int = typer.Option(3, "--repeats", min=1, help="Runs per figure (the best is kept)."),
          yardstick: str = typer.Option("../shared/tools/yardstick.py", "--yardstick",
                                        help="The naive numba filter step tight-dvl is timed against in the same "
                                             "run (a file with measure()); skipped if absent, '' to skip.")):
    from tanbench.bench import run_bench

    figures = run_bench(particles=particles, repeats=repeats, yardstick=yardstick or None)
    if as_json:
        typer.echo(json.dumps(figures))
        return
    typer.echo(f"area A, 10 m map, 4 DVL beams, {figures['particles']} particles, {figures['updates']} updates "
               f"(ns per cost unit: particle-step, grid cell, match or update; thread CPU / wall; best of {repeats})")
    typer.echo(f"  kernels compiled for {figures['target']}")
    numpy_cpu = {r["method"]: r["ns_per_unit_cpu"] for r in figures["runs"] if r["random_numbers"] == "numpy"}
    for r in figures["runs"]:
        frac = "" if r["resampled_fraction"] is None else f"  resampled {100 * r['resampled_fraction']:.0f} %"
        vs = (f"   numpy stream / this = {numpy_cpu[r['method']] / r['ns_per_unit_cpu']:4.2f}"
              if r["random_numbers"] != "numpy" and r["method"] in numpy_cpu and not r["options"] else "")
        stream = (f"{r['options']:<20}" if r["options"] else
                  f"random_numbers={r['random_numbers']:<5}" if r["stream"] else " " * 20)
        typer.echo(f"  {r['method']:<12} {stream} {r['ns_per_unit_cpu']:7.1f} / "
                   f"{r['ns_per_unit_wall']:7.1f} ns   run {r['run_wall_s']:6.2f} s "
                   f"({1e6 * r['run_wall_s'] / figures['updates']:7.1f} us per update){frac}{vs}")
    typer.echo("  one update step, jitted kernels against their numpy references:")
    for method, step in figures["steps"].items():
        typer.echo(f"    {method:<12} jitted {step['step_jit_us']:9.0f} us, numpy {step['step_numpy_us']:10.0f} us: "
                   f"numpy / jitted = {step['numpy_ratio']:6.1f} x")
    for method, kernels in figures["kernels"].items():
        typer.echo(f"  {method} passes (ns per particle, thread CPU, a mid-run cloud):")
        for name, ns in kernels.items():
            typer.echo(f"    {name:<58} {ns:7.1f}")
    f = figures["fixed"]
    typer.echo("  fixed costs of a sweep (CPU seconds; the default scenario, the CI sweep's three methods):")
    typer.echo(f"    start-up: the parent's imports {f['parent_start_s']:.2f} s; a worker's warm-up (cached kernels) "
               f"forked from it {f['worker_start_s']:.2f} s, spawned with its imports {f['worker_spawn_s']:.2f} s")
    typer.echo(f"    per world: its noise-free simulation and sonar ray-casting {f['world_s']:.2f} s; its seafloor: "
               f"synthesised {f['seafloor_synthesis_s']:.2f} s (once per machine and code version), read back from "
               f"the store {f['seafloor_read_s']:.3f} s")
    typer.echo(f"    per task: the run's vehicle data {f['simulation_s']:.3f} s, around each method's filter "
               f"{f['around_filter_s']:.3f} s, storing its rows and series {f['store_s']:.3f} s")
    mb = figures["multibeam"]
    typer.echo(f"  multibeam likelihood (tight PF pass, {mb['beams']}-beam fan, map-aware Student-t, thread CPU): "
               f"{mb['ns_per_particle_beam_jit']:.2f} ns per particle-beam jitted, "
               f"{mb['ns_per_particle_beam_numpy']:.2f} numpy ({mb['numpy_ratio']:.1f} x); the *-mbe runs above "
               f"use a 64-beam fan (tight-mbe's cost unit: particle-beam-step)")
    if figures["yardstick"]:
        typer.echo(f"  tight-dvl against the yardstick ({yardstick}), in turn in this process, thread CPU "
                   "ns per particle-step:")
        for r in figures["yardstick"]:
            typer.echo(f"    tight-dvl {r['tight_dvl_ns']:6.1f}, yardstick {r['yardstick_ns']:6.1f}: "
                       f"ratio {r['tight_dvl_ns'] / r['yardstick_ns']:.3f}")
    elif yardstick:
        typer.echo(f"  yardstick: no file {yardstick} (--yardstick PATH to time tight-dvl against it)")


def _usage_error_types() -> tuple[type, ...]:
    """Click's usage-error base class: typer's vendored copy (typer >= 0.20) and/or click's own."""
    found = []
    try:
        import click

        found.append(click.exceptions.ClickException)
    except ImportError:  # pragma: no cover - typer without the click package
        pass
    if hasattr(typer, "TyperException"):
        found.append(typer.TyperException)
    return tuple(found)


def main():
    """Console entry point: one-line errors (bad input and bad options alike) unless --debug."""
    debug = "--debug" in sys.argv[1:]
    try:
        code = app(standalone_mode=False)  # click usage errors reach us instead of a boxed message
    except TanbenchError as exc:
        if debug:
            raise
        typer.echo(f"error: {exc}", err=True)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        if debug:
            raise
        typer.echo("interrupted", err=True)
        sys.exit(130)
    except (MemoryError, RecursionError) as exc:
        if debug:
            raise
        what = "out of memory" if isinstance(exc, MemoryError) else "input nested too deeply"
        typer.echo(f"error: {what} ({type(exc).__name__}); check the sizes in the sweep (durations, grids, "
                   f"particles, maps) (run with --debug for the traceback)", err=True)
        sys.exit(2)
    except typer.Abort:
        typer.echo("aborted", err=True)
        sys.exit(1)
    except _usage_error_types() as exc:
        if type(exc).__name__ == "NoArgsIsHelpError" or not hasattr(exc, "format_message"):
            exc.show()  # a bare `tanbench` (or group) prints its help
        else:
            ctx = getattr(exc, "ctx", None)
            hint = f" (see: {ctx.command_path} --help)" if ctx is not None else ""
            typer.echo(f"error: {exc.format_message()}{hint}", err=True)
        sys.exit(getattr(exc, "exit_code", 2))
    except Exception as exc:  # noqa: BLE001 - the last line of defence against tracebacks
        if debug:
            raise
        typer.echo(f"error: unexpected {type(exc).__name__}: {exc} (run with --debug for the traceback)", err=True)
        sys.exit(1)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
