"""``run``'s first step, and all of ``validate``: everything that can be known before computing.

* the methods: each name a method, each one's options valid for every cell, and every
  ``method_options`` entry used (an option of a method the sweep does not run, or of no
  method at all, is refused);
* the worlds, each built once: the memory its vehicle data would take, the track on the
  map and in the water, sonar settings that leave pings with a bottom return for the
  sensors the methods weigh by, and the initial uncertainty on the navigation map;
* the output: a directory that is not empty and not inside another results directory,
  and file names the file system takes.

Each problem is one :class:`TanbenchError` line naming the sweep file, the cell and the
setting (or the path).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from tanbench.arrays import physical_memory
from tanbench.errors import TanbenchError, describe_exception
from tanbench.methods.api import check_start_on_map
from tanbench.methods.registry import get
from tanbench.simulation import motion_plan, noise_free_world
from tanbench.sweep import Cell, Sweep
from tanbench.terrain import navigation_map

# Memory of one run's vehicle data per IMU sample: the noise-free world a worker keeps
# (250 B retained, 620 B at the peak of its building) and one run's sensors and
# navigation solution (450 B more), by tracemalloc on the default scenario (119,000
# samples); rounded up for the methods' own arrays.
BYTES_PER_IMU_SAMPLE = 1000
SENSORS = ("dvl", "sbe")  # a built-in method's name ends in the sensor whose ranges it weighs by


def validate_sweep(sweep: Sweep) -> None:
    """Every check of the module docstring but the output's (see :func:`check_output`)."""
    check_methods(sweep)
    validate_worlds(sweep)


def _label(sweep: Sweep) -> str:
    return str(sweep.path or sweep.name)


def _cell_label(sweep: Sweep, cell: Cell) -> str:
    varied = ", ".join(f"{k}={v}" for k, v in cell.varied.items()) or "defaults"
    return f"{_label(sweep)}: cell {cell.cell_id} ({varied})"


def check_methods(sweep: Sweep) -> None:
    """Method names, each cell's method options, and no ``method_options`` entry left unused."""
    records = {}
    for name in sweep.spec.methods:
        try:
            records[name] = get(name)
        except TanbenchError as exc:
            raise TanbenchError(f"{_label(sweep)}: methods: {exc}") from None
    seen = set()
    for cell in sweep.cells:
        options = cell.scenario.method_options
        key = json.dumps(options, sort_keys=True, default=str)
        if key in seen:
            continue
        seen.add(key)
        for name in options:
            if name in records:
                continue
            try:
                get(name)
                what = f"options of method {name!r}, which this sweep does not run"
            except TanbenchError:
                what = f"unknown method {name!r}"
            raise TanbenchError(f"{_cell_label(sweep, cell)}: method_options.{name}: {what} (its methods: "
                                f"{', '.join(sweep.spec.methods)}); remove the entry or add the method")
        for record in records.values():
            try:
                record.parse_options(cell.scenario)
            except TanbenchError as exc:
                raise TanbenchError(f"{_cell_label(sweep, cell)}: {exc}") from None


def check_memory(cell: Cell, duration_s: float) -> None:
    """Refuse a run whose vehicle data would take more than half this machine's memory."""
    s = cell.scenario.sensors
    samples = duration_s * s.imu_rate_hz
    need = samples * BYTES_PER_IMU_SAMPLE
    have = physical_memory()
    if have is not None and need > have / 2:
        raise ValueError(
            f"a run lasts {duration_s:.0f} s at sensors.imu_rate_hz={s.imu_rate_hz:g} ({samples:.3g} IMU samples): "
            f"its vehicle data would take about {need / 1e9:.3g} GB, more than half of this machine's "
            f"{have / 1e9:.3g} GB; shorten the trajectory (trajectory.cruise_s, legs, leg_length_m) or duration_s")


def check_world(cell: Cell, world, sensors_used: set[str]) -> None:
    """The vehicle in the water, and pings with a bottom return for the sensors the methods use."""
    truth, ping_idx, dvl, sbe = world
    up = truth.pos[:, 2]
    if up.max() > 1e-6:
        k = int(np.argmax(up))
        raise ValueError(f"the vehicle is above the sea surface at t={truth.t[k]:.0f} s (up {up[k]:+.1f} m): the "
                         f"trajectory (trajectory.start_enu_m's third value, up; trajectory.depth_m) must keep it "
                         f"in the water")
    lock = {"dvl": np.isfinite(dvl).any(axis=1), "sbe": np.isfinite(sbe).any(axis=1)}
    blind = [s for s in SENSORS if not lock[s].any()]
    if blind and (len(blind) == len(SENSORS) or set(blind) & sensors_used):
        s = cell.scenario.sensors
        which = " nor ".join({"dvl": "the DVL beams", "sbe": "the altimeter"}[b] for b in blind)
        raise ValueError(f"no sonar ping of the run has a bottom return from {which} (sensors.max_range_m="
                         f"{s.max_range_m:g} m, sensors.beam_tilt_deg={s.beam_tilt_deg:g}): the methods would "
                         f"have no measurement; raise max_range_m or lower the track")


def check_sampling_time(scenario, length_s: float, run: str = "the run") -> None:
    """Refuse a ``sampling_time_s`` longer than the run (``length_s`` seconds; ``run`` says what was measured): the
    filter would not update after the start. A sweep's cells and ``tanbench replay`` (the log's DVL pings) use it."""
    if scenario.sampling_time_s > length_s + 1e-9:
        raise TanbenchError(f"sampling_time_s ({scenario.sampling_time_s:g} s) is longer than {run} "
                            f"({length_s:g} s): the filter would not update after the start")


def validate_worlds(sweep: Sweep) -> None:
    """Check every cell against its terrain: memory, maps, track, sonar and initial uncertainty."""
    suffixes = {name.rsplit("-", 1)[-1] for name in sweep.spec.methods if get(name).builtin}
    used = suffixes & set(SENSORS)
    seen = set()
    for cell in sweep.cells:
        sc = cell.scenario
        try:
            length = motion_plan(sc).duration
            check_sampling_time(sc, length)
            if "mbe" in suffixes and not sc.sensors.multibeam_beams:
                raise ValueError("the multibeam methods (*-mbe) need a multibeam: set sensors.multibeam_beams > 0")
            world = json.dumps(sc.world_spec(), sort_keys=True)
            if world not in seen:
                check_memory(cell, length)
                check_world(cell, noise_free_world(world), used)
                seen.add(world)
            check_start_on_map(sc, navigation_map(sc.terrain, sc.map_resolution_m))
        except (ValueError, TanbenchError) as exc:
            raise TanbenchError(f"{_cell_label(sweep, cell)}: {exc}") from None
        except Exception as exc:  # noqa: BLE001 - bad settings can reach arithmetic; name the cell
            raise TanbenchError(f"{_cell_label(sweep, cell)}: building its world failed ({describe_exception(exc)}); "
                                f"check its sensors.*, trajectory.* and duration_s settings") from None


# what a results directory holds from its first stored run on (or a run stopped before it: the work area, the lock)
RESULTS_MARKERS = frozenset({"sweep.yaml", "runs", "sessions.jsonl", ".work", ".tanbench.lock"})


def check_output(sweep: Sweep, out: Path) -> None:
    """``out`` names a directory that is not inside another results directory, and every file
    a sweep writes there has a name and a path the file system takes."""
    if str(out).strip() == "":
        raise TanbenchError("--out '': give the results directory a name")
    resolved = Path(os.path.abspath(out))
    if (resolved / "replay.yaml").is_file():  # tanbench replay's output (missions/replay.py), which refuses ours too
        raise TanbenchError(f"--out {out}: holds a replay's results (replay.yaml); use another directory")
    if resolved.is_dir():
        names = {p.name for p in resolved.iterdir()}
        foreign = sorted(n for n in names if not n.startswith("."))
        if foreign and not names & RESULTS_MARKERS:  # e.g. a mission log, or results/ itself: never written into
            raise TanbenchError(f"--out {out}: holds files that are not a tanbench results directory's (e.g. "
                                f"{foreign[0]!r}); give a new or empty directory")
    for parent in resolved.parents:
        if (parent / "sweep.yaml").is_file() and ((parent / "runs").is_dir() or (parent / "tables").is_dir()):
            raise TanbenchError(f"--out {out} is inside the results directory {parent}: give the sweep a directory "
                                f"of its own (e.g. beside it)")
    existing = next((p for p in (resolved, *resolved.parents) if p.exists()), Path("/"))
    try:
        name_max = os.pathconf(existing, "PC_NAME_MAX")
        path_max = os.pathconf(existing, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    pid = "9" * 7
    names = [f".{t}.parquet.{pid}.tmp" for t in sweep.table_designs] + [f".{t}.md.{pid}.tmp" for t in sweep.table_designs]
    cell = "cell_id=" + "0" * 16
    longest = max([resolved / "tables" / n for n in names] +
                  [resolved / ".work" / "series" / cell / f".run-00000.parquet.{pid}.tmp",
                   resolved / "series" / "runs" / cell / f".run-00000.parquet.{pid}.tmp"], key=lambda p: len(str(p)))
    for part in (*resolved.parts[1:], *names):
        if len(part.encode()) > name_max:
            raise TanbenchError(f"{part[:40]!r}... is {len(part.encode())} bytes long, but file names here may have "
                                f"at most {name_max}: shorten the --out directory's or the table's name")
    if len(str(longest).encode()) >= path_max:
        raise TanbenchError(f"--out {out}: the results' file paths would be {len(str(longest).encode())} bytes long, "
                            f"more than this file system's {path_max}: use a shorter --out path")
