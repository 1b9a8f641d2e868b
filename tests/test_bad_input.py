"""Bad input through the CLI: exactly one `error:` line naming the problem, exit code 2, no traceback,
and nothing already stored changed.

One table of cases (sweep YAML, map files, results and output directories, a Dask
address); ``{maps}``, ``{tmp}``, ``{sweep}`` and ``{out}`` in a case are filled in at run
time. A case's setup may store results first (a copy of the committed CI baseline);
every file under the test's directory is compared before and after the command. A few
cases are unusual input that must do the right thing instead (``code=0``, or ``code=1``
for `check` with missing cells), with their own assertions (``then=``).
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from sweep_support import ROOT, WALL_COLUMNS, cli, error_lines

BASE = {"name": "bad", "seed": 1, "runs": 2, "scenario": {"particles": 60, "duration_s": 60}}

MAP_RES = 5.0  # the test maps' node spacing, m; they span 0..1000 m east and north
FILE_SCENARIO = {
    "area": "custom", "particles": 60, "duration_s": 60,
    "terrain": {"kind": "file", "path": "{maps}/map.npy", "origin": [0, 0], "resolution": MAP_RES},
    "trajectory": {"kind": "survey", "centre_en_m": [500, 500], "heading_deg": 0, "leg_length_m": 300,
                   "leg_spacing_m": 100, "legs": 2, "depth_m": 20},
}


def sweep(*drop, **changes) -> dict:
    """The base sweep with top-level keys replaced and ``scenario.x.y=`` given as ``scenario__x__y=``."""
    data = copy.deepcopy(BASE)
    for key in drop:
        data.pop(key)
    for key, value in changes.items():
        *parents, last = key.split("__")
        node = data
        for p in parents:
            node = node.setdefault(p, {})
        node[last] = value
    return data


def file_sweep(path="{maps}/map.npy", **changes) -> dict:
    """A sweep over a map file around a survey track (changes as in :func:`sweep`)."""
    data = sweep(scenario=copy.deepcopy(FILE_SCENARIO), **changes)
    data["scenario"]["terrain"]["path"] = path
    return data


def incompatible_results(tmp, layout):
    """A results directory whose run file says results schema 999."""
    out = tmp / "out"
    path = out / "runs" / layout / "run-00000.parquet"
    path.parent.mkdir(parents=True)
    table = pa.table({"cell_id": ["x"], "run": [0]}).replace_schema_metadata(
        {b"tanbench": json.dumps({"schema_version": 999}).encode()})
    pq.write_table(table, path)
    (out / "sweep.yaml").write_text(yaml.safe_dump(BASE))
    return {"out": str(out)}


def unwritable_output(tmp):
    """A read-only directory, or (as root, who may write there anyway) a path under a regular file."""
    ro = tmp / "readonly"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        (ro / "probe").write_text("")
    except OSError:
        return {"out": str(ro / "sub")}
    ro.chmod(0o700)
    (tmp / "a-file").write_text("")
    return {"out": str(tmp / "a-file" / "sub")}


BASELINE = ROOT / "results" / "ci-baseline"
# a cell of the committed CI baseline (its default cell), as the messages name it
CI_CELL = min(p.name.split("=", 1)[1] for p in (BASELINE / "runs").glob("cell_id=*"))
# its runs per cell (the CI design's count, docs/results.md)
CI_RUNS = int(pd.read_parquet(BASELINE / "runs", columns=["run"])["run"].max()) + 1


def stored_results(tmp):
    """A copy of the committed CI baseline (its cells, methods and runs) as already stored results."""
    out = tmp / "out"
    shutil.copytree(BASELINE, out, ignore=shutil.ignore_patterns(".work", "figures", "REPORT.md"))
    return {"out": str(out)}


def baseline_missing_cells(tmp):
    """The CI baseline with 2 of its 3 cell directories deleted (as a run that lost cells)."""
    values = stored_results(tmp)
    for cell in sorted((tmp / "out" / "runs").glob("cell_id=*"))[:2]:
        shutil.rmtree(cell)
    return values


def baseline_missing_runs_and_method(tmp):
    """The CI baseline with its last two runs of every cell and every loose-dvl row deleted."""
    values = stored_results(tmp)
    for path in (tmp / "out" / "runs").glob("cell_id=*/runs.parquet"):
        table = pq.read_table(path)
        df = table.to_pandas()
        df = df[(df["run"] < CI_RUNS - 2) & (df["method"] != "loose-dvl")]
        pq.write_table(pa.Table.from_pandas(df, schema=table.schema, preserve_index=False), path)
    return values


def read_only_figures(tmp):
    """Stored results whose figures cannot be written: a read-only directory (or, as root, who
    may write there anyway, a regular file where DIR/figures/ should be)."""
    values = stored_results(tmp)
    out = tmp / "out"
    out.chmod(0o500)
    try:
        (out / "probe").write_text("")
    except OSError:
        return values
    (out / "probe").unlink()
    out.chmod(0o700)
    (out / "figures").write_text("")
    return values


def no_directory(path):
    """A refused run leaves no directory it created (snapshot() lists files only)."""
    assert not path.exists(), path


def regular_file(tmp):
    (tmp / "a-file").write_text("keep me")
    return {"out": str(tmp / "a-file")}


def foreign_directory(tmp):
    """A directory of the user's own files (a table of theirs, a mission log's files): `run` wrote its results beside
    them, overwriting tables/default.md (found by an audit)."""
    (tmp / "mine" / "tables").mkdir(parents=True)
    (tmp / "mine" / "tables" / "default.md").write_text("my notes")
    (tmp / "mine" / "mission.yaml").write_text("source: {vehicle: Sirius}")
    return {"out": str(tmp / "mine")}


def case(id, args, data, *fragments, setup=None, hang_s=240, code=2, then=None, absent=()):
    """One row: CLI ``args``, the sweep file's ``data``, text the output must hold (``fragments``)
    and must not (``absent``)."""
    return pytest.param(args, data, fragments, setup, hang_s, code, then, absent, id=id)


def csv_header(expected):
    """A ``then=`` check: stdout is CSV whose header is ``expected``."""
    def check(tmp, proc):
        assert proc.stdout.splitlines()[0] == expected, proc.stdout[:300]
        assert "|" not in proc.stdout
    return check


def simulated_csv(tmp, proc):
    text = (tmp / "run.csv").read_text()
    df = pd.read_csv(tmp / "run.csv")
    assert not text.startswith("PAR1") and {"t", "truth_e", "nav_e"} <= set(df.columns) and len(df) > 100


def other_runs_kept(tmp, proc):
    """After `--runs 1 --force` on the baseline: run 0 recomputed, the other runs kept as they were."""
    before = pd.read_parquet(BASELINE / "runs").drop(columns=WALL_COLUMNS)
    after = pd.read_parquet(tmp / "out" / "runs").drop(columns=WALL_COLUMNS)
    assert "1 run(s) per cell" not in proc.stdout
    key = ["cell_id", "method", "run"]
    assert sorted(map(tuple, after[key].to_numpy())) == sorted(map(tuple, before[key].to_numpy()))
    # (options added since the baseline was stored are extra columns of the new rows)
    keep = lambda df: df[df["run"] >= 1].sort_values(key).reset_index(drop=True)[list(before.columns)]  # noqa: E731
    pd.testing.assert_frame_equal(keep(after), keep(before))
    tables = pd.read_parquet(tmp / "out" / "tables" / "map_resolution.parquet")
    assert (tables["n_runs"] == CI_RUNS).all()


CASES = [
    # the sweep file itself
    case("no-such-sweep-file", ["validate", "{tmp}/missing.yaml"], None, "missing.yaml: no such sweep file"),
    case("sweep-file-is-a-directory", ["validate", "{tmp}"], None, "cannot read the sweep file"),
    case("malformed-yaml", ["validate", "{sweep}"], "name: bad\nseed: [1\n", "bad.yaml: malformed YAML at line"),
    case("not-a-mapping", ["validate", "{sweep}"], "- 1\n- 2\n", "a sweep file must be a mapping"),
    case("unknown-top-level-key", ["validate", "{sweep}"], sweep(colour="red"), "bad.yaml: colour: unknown key"),
    case("unknown-nested-key", ["validate", "{sweep}"], sweep(scenario__filter__foo=1),
         "scenario.filter.foo: unknown key"),
    case("unknown-method", ["validate", "{sweep}"], sweep(methods=["tight-dvl", "magic"]), "unknown method 'magic'"),
    case("wrong-type", ["validate", "{sweep}"], sweep(scenario__particles="lots"),
         "scenario.particles: Input should be a valid integer", "'lots'"),
    case("zero-particles", ["validate", "{sweep}"], sweep(scenario__particles=0),
         "scenario.particles: Input should be greater than 0"),
    case("negative-particles", ["run", "{sweep}", "--out", "{tmp}/out"], sweep(scenario__particles=-5),
         "scenario.particles: Input should be greater than 0", "(got -5)"),
    case("zero-runs", ["validate", "{sweep}"], sweep(runs=0), "runs: Input should be greater than 0"),
    case("negative-runs", ["run", "{sweep}", "--out", "{tmp}/out"], sweep(runs=-3),
         "runs: Input should be greater than 0"),
    case("missing-seed", ["validate", "{sweep}"], sweep("seed"), "seed: Field required"),
    # a seed beyond int64 was stored once, then made `run` again, `plan` and `replay` fail (found by an audit)
    case("seed-beyond-int64", ["run", "{sweep}", "--out", "{tmp}/out"], sweep(seed=2**64 + 1),
         "seed: Input should be less than or equal to 9223372036854775807"),
    case("terrain-seed-beyond-int64", ["run", "{sweep}", "--out", "{tmp}/out"], sweep(scenario__terrain={
         "kind": "synthetic", "seed": 2**64}), "scenario.terrain.seed: Input should be less than or equal to"),
    case("simulate-seed-beyond-int64", ["simulate", "--seed", str(2**63), "--out", "{tmp}/run.csv"], None,
         "Invalid value for '--seed'"),
    case("missing-seed-and-runs", ["validate", "{sweep}"], sweep("seed", "runs"),
         "seed: Field required; runs: Field required", absent=("more problem",)),
    case("seven-problems-name-five", ["validate", "{sweep}"],
         sweep(scenario__particles=0, scenario__duration_s=-1, scenario__noise_m=-1, scenario__map_resolution_m=0,
               scenario__sampling_time_s=0, scenario__colour="red", scenario__shade="blue"),
         "scenario.map_resolution_m: Input should be greater than 0 (got 0); scenario.noise_m: ",
         "scenario.duration_s: Input should be greater than 0 (got -1); and 2 more problems"),
    case("zero-map-resolution", ["validate", "{sweep}"], sweep(scenario__map_resolution_m=0),
         "scenario.map_resolution_m: Input should be greater than 0"),
    case("negative-map-resolution-in-a-table", ["validate", "{sweep}"],
         sweep(tables={"maps": {"map_resolution_m": [10, -20]}}),
         "tables.maps: map_resolution_m: Input should be greater than 0"),
    case("zero-sampling-time", ["validate", "{sweep}"], sweep(scenario__sampling_time_s=0),
         "scenario.sampling_time_s: Input should be greater than 0"),
    case("negative-sampling-time", ["validate", "{sweep}"], sweep(scenario__sampling_time_s=-1),
         "scenario.sampling_time_s: Input should be greater than 0"),
    case("sampling-time-not-whole-pings", ["validate", "{sweep}"], sweep(scenario__sampling_time_s=1.5),
         "sampling_time_s (1.5) must be a whole number of sonar pings"),
    case("unknown-profile", ["validate", "{sweep}"], sweep(profile="zhou2017-loose"),
         "profile: unknown profile 'zhou2017-loose'"),
    case("unknown-propagation", ["validate", "{sweep}"], sweep(scenario__filter__propagation="rk4"),
         "scenario.filter.propagation: Input should be 'exact', 'euler-last-second', 'euler-last-sample' or 'euler-interval-start'"),
    case("roughness-unknown-region", ["validate", "{sweep}"], sweep(scenario__terrain__region_hurst={"Z": 1.0}),
         "has no region 'Z'"),
    case("roughness-out-of-range", ["validate", "{sweep}"], sweep(scenario__terrain__region_hurst={"A": 9.0}),
         "region_hurst.A must be in [0.1, 3]"),
    case("report-literal-not-results", ["report", "{tmp}", "--literal", "{tmp}/nothing"], None,
         "--literal", "not a tanbench results directory"),
    case("empty-table-values", ["validate", "{sweep}"], sweep(tables={"maps": {"map_resolution_m": []}}),
         "maps.map_resolution_m: needs at least one value"),
    # map resolution against the terrain
    case("map-finer-than-synthetic-truth", ["validate", "{sweep}"], sweep(scenario__map_resolution_m=1),
         "scenario: map_resolution_m (1) is finer than the truth grid (2.5 m)"),
    case("map-finer-than-file-grid", ["validate", "{sweep}"], file_sweep(scenario__map_resolution_m=2),
         "bad.yaml: cell", "map resolution 2.0 m is finer than the truth grid (5 m)"),
    case("map-coarser-than-extent", ["validate", "{sweep}"], sweep(scenario__map_resolution_m=5000),
         "bad.yaml: cell", "map resolution 5000.0 m is coarser than the map extent"),
    # map files
    case("missing-map-file", ["validate", "{sweep}"], file_sweep("{maps}/nothere.npy"),
         "nothere.npy: file not found"),
    case("garbage-tif", ["validate", "{sweep}"], file_sweep("{maps}/garbage.tif"),
         "garbage.tif: not a readable TIFF file"),
    case("truncated-tif", ["terrain", "info", "{maps}/truncated.tif"], None, "truncated.tif: not a readable TIFF file"),
    case("text-file-named-npy", ["validate", "{sweep}"], file_sweep("{maps}/text.npy"),
         "text.npy: not a numeric NumPy array file (object/pickled data is refused)", absent=("allow_pickle",)),
    case("map-path-is-a-directory", ["validate", "{sweep}"], file_sweep("{maps}/a-directory.npy"),
         "a-directory.npy: not a regular file"),
    case("unknown-map-format", ["validate", "{sweep}"], file_sweep("{maps}/map.xyz"),
         "map.xyz: cannot tell the grid format from the extension '.xyz'"),
    case("glob-matches-nothing", ["validate", "{sweep}"], file_sweep("{maps}/tiles-*.npy"),
         "matches no file"),
    case("holes-under-the-track", ["run", "{sweep}", "--out", "{tmp}/out"],
         file_sweep("{maps}/holes.npy", scenario__duration_s=None),
         "the map has no data (a hole) under the track at t=", "(E, N) = (450, 4", "terrain.fill_holes: true"),
    case("trajectory-leaves-the-map", ["validate", "{sweep}"],
         file_sweep(scenario__duration_s=None, scenario__trajectory__centre_en_m=[500, 900]),
         "the trajectory leaves the map at t=", "N 0..1000 m"),
    case("initial-uncertainty-leaves-the-map", ["run", "{sweep}", "--out", "{tmp}/out"],
         file_sweep(scenario__filter__initial_area_m=2000),
         "the initial uncertainty", "leaves the navigation map", "filter.initial_area_m"),
    case("duration-longer-than-the-track", ["validate", "{sweep}"], file_sweep(scenario__duration_s=5000),
         "duration_s (5000 s) is longer than the trajectory"),
    # results and output directories, executors
    case("results-of-another-schema-run", ["run", "{sweep}", "--out", "{out}"], BASE,
         "cell_id=x/run-00000.parquet: written with results schema 999", "reads schema",
         setup=lambda tmp: incompatible_results(tmp, "cell_id=x")),
    case("results-of-another-schema-tables", ["tables", "{out}"], None,
         "run-00000.parquet: written with results schema 999",
         setup=lambda tmp: incompatible_results(tmp, "x")),
    case("tables-of-a-non-results-directory", ["tables", "{tmp}"], None, "no sweep.yaml"),
    case("tables-unknown-format", ["tables", "{tmp}", "--format", "xlsx"], None, "--format must be md or csv"),
    case("output-not-writable", ["run", "{sweep}", "--out", "{out}"], BASE, "output directory {tmp}/",
         setup=unwritable_output),
    case("output-is-a-regular-file", ["run", "{sweep}", "--out", "{out}"], BASE,
         "output directory {tmp}/a-file is a file, not a directory", setup=regular_file),
    case("output-holds-a-users-files", ["run", "{sweep}", "--out", "{out}"], BASE,
         "holds files that are not a tanbench results directory's (e.g. 'mission.yaml')", setup=foreign_directory),
    case("plan-output-is-a-regular-file", ["plan", "{sweep}", "--out", "{out}"], BASE,
         "output directory {tmp}/a-file is a file, not a directory", setup=regular_file),
    # names that become paths (results/<sweep>, DIR/tables/<table>.parquet)
    *[case(f"table-name-{label}", ["run", "{sweep}", "--out", "{out}"],
           sweep(tables={name: {"noise_m": [1.0]}}), "tables: table name", "cannot be used as a file name",
           setup=stored_results)
      for label, name in (("into-a-cell", f"../runs/cell_id={CI_CELL}/runs"), ("parent", "../../evil"),
                          ("slash", "a/b"), ("empty", ""), ("hidden", ".x"), ("dot", "."), ("dotdot", ".."))],
    case("table-named-grid-with-a-grid", ["validate", "{sweep}"],
         sweep(tables={"grid": {"noise_m": [1.0]}}, grid={"noise_m": [2.0]}), "table name 'grid' is taken"),
    *[case(f"sweep-name-{label}", ["run", "{sweep}"], sweep(name=name), "name: sweep name",
           "cannot be used as a file name")
      for label, name in (("dot", "."), ("dotdot", ".."), ("slash", "a/b"), ("empty", ""))],
    # YAML that would silently keep the last of two values
    case("table-listed-twice", ["run", "{sweep}", "--out", "{out}"],
         "name: bad\nseed: 1\nruns: 2\ntables:\n  t4: {noise_m: [1]}\n  t4: {noise_m: [2]}\n",
         "malformed YAML at line 6", "duplicate key 't4' (first given at line 5)", setup=stored_results),
    case("key-given-twice", ["validate", "{sweep}"], "name: bad\nseed: 1\nruns: 2\nscenario:\n  particles: 60\n"
         "  noise_m: 1\n  particles: 90\n", "line 7", "duplicate key 'particles' (first given at line 5)"),
    # booleans are not numbers; non-finite numbers are refused
    case("particles-true", ["run", "{sweep}", "--out", "{out}"], sweep(scenario__particles=True),
         "scenario.particles: expected a number, not the boolean true", setup=stored_results),
    case("runs-true", ["validate", "{sweep}"], sweep(runs=True), "runs: expected a number, not the boolean true"),
    case("boolean-in-a-table", ["validate", "{sweep}"], sweep(tables={"t": {"noise_m": [1.0, False]}}),
         "tables.t: noise_m: expected a number, not the boolean false"),
    case("boolean-in-a-tuple", ["validate", "{sweep}"], sweep(scenario__trajectory__start_enu_m=[1000, True, 0]),
         "scenario.trajectory.start_enu_m: expected a number, not the boolean true"),
    case("noise-inf", ["validate", "{sweep}"], "name: bad\nseed: 1\nruns: 2\nscenario: {noise_m: .inf}\n",
         "scenario.noise_m: must be a finite number, not inf"),
    case("nan-in-a-table", ["validate", "{sweep}"],
         "name: bad\nseed: 1\nruns: 2\ntables:\n  t: {map_resolution_m: [10, .nan]}\n",
         "tables.t: map_resolution_m: must be a finite number, not nan"),
    # run lengths
    case("duration-shorter-than-a-ping", ["validate", "{sweep}"], sweep(scenario__duration_s=0.001),
         "scenario: duration_s (0.001 s) is shorter than one sonar ping (1 s"),
    case("sampling-time-longer-than-the-run", ["validate", "{sweep}"],
         sweep(scenario__duration_s=None, scenario__sampling_time_s=100000, scenario__map_resolution_m=20),
         "bad.yaml: cell", "sampling_time_s (100000 s) is longer than the run (1190 s)"),
    case("sampling-time-longer-than-duration", ["run", "{sweep}", "--out", "{out}"],
         sweep(scenario__sampling_time_s=90), "sampling_time_s (90 s) is longer than the run (60 s)",
         setup=stored_results),
    # simulate
    *[case(f"simulate-duration-{label}", ["simulate", "--duration", value],
           None, f"--duration must be a positive number of seconds, not {label}")
      for label, value in (("-5", "-5"), ("0", "0"), ("nan", "nan"))],
    case("simulate-duration-too-short", ["simulate", "--duration", "0.001"], None,
         "--duration: duration_s (0.001 s) is shorter than one sonar ping"),
    case("simulate-duration-too-long", ["simulate", "--duration", "5000"], None,
         "--duration: duration_s (5000 s) is longer than the trajectory (1190 s)"),
    case("simulate-negative-seed", ["simulate", "--seed", "-1"], None, "'--seed'", "greater than or equal to 0"),
    case("simulate-unknown-suffix", ["simulate", "--out", "{tmp}/run.txt"], None,
         "--out {tmp}/run.txt: use a .parquet or .csv file name"),
    case("simulate-csv", ["simulate", "--duration", "20", "--out", "{tmp}/run.csv"], None, "wrote {tmp}/run.csv",
         code=0, then=simulated_csv),
    # results directories
    case("report-needs-the-papers-tables", ["report", "{out}"], None,
         "report needs the paper's tables", "this sweep (ci) has map_resolution, sampling_time",
         "tanbench tables", setup=stored_results),
    case("plot-cannot-write", ["plot", "{out}"], None, "cannot write the figures under {tmp}/out/figures",
         setup=read_only_figures),
    case("plot-unknown-cell", ["plot", "{out}", "--cell", "nosuchcell"], None,
         "--cell nosuchcell: no cell with stored series has this id", f"cell {CI_CELL}",
         setup=stored_results),
    case("tables-compare-paper-not-the-paper", ["tables", "{out}", "--compare-paper"], None,
         "note: --compare-paper: none of this sweep's tables (map_resolution, sampling_time) is one of the paper's",
         setup=stored_results, code=0),
    case("check-missing-cells", ["check", "{out}", str(BASELINE)], None,
         "missing: cell only in BASELINE: ", "2 missing", "check fails: 2 cell(s)",
         setup=baseline_missing_cells, code=1),
    case("check-missing-cells-allowed", ["check", "{out}", str(BASELINE), "--allow-missing", "--allow-underpowered"], None,
         "missing: cell only in BASELINE: ", "2 missing", setup=baseline_missing_cells, code=0),
    # a --report the comparison could not be written to is refused before the comparison (no table printed)
    case("check-report-unknown-suffix", ["check", "{out}", str(BASELINE), "--report", "{tmp}/r.xlsx"], None,
         "--report {tmp}/r.xlsx: use a .parquet, .md or .json file name", setup=stored_results, absent=("| ",)),
    case("check-report-no-such-directory", ["check", "{out}", str(BASELINE), "--report", "{tmp}/no/r.md"], None,
         "its directory {tmp}/no does not exist", setup=stored_results, absent=("| ",)),
    case("check-missing-runs-and-method", ["check", str(BASELINE), "{out}"], None,
         f"missing: method loose-dvl only in NEW: cell {CI_CELL}",
         f"missing: runs {CI_RUNS - 2}, {CI_RUNS - 1} of tight-dvl only in NEW (ok runs): cell {CI_CELL}", "9 missing",
         setup=baseline_missing_runs_and_method, code=1),
    case("force-with-fewer-runs-keeps-the-others",
         ["run", "{out}/sweep.yaml", "--out", "{out}", "--runs", "1", "--force", "--workers", "1", "-q"], None,
         "ci: 3 tasks (9 runs) run, 0 tasks (0 runs) already done", setup=stored_results, code=0,
         then=other_runs_kept),
    # terrain stats
    case("terrain-stats-track-off-the-map", ["terrain", "stats", "--sweep", "{sweep}"],
         file_sweep(scenario__trajectory__centre_en_m=[5000, 5000]),
         "lies entirely off the map file:map.npy; nothing to measure"),
    case("terrain-stats-csv", ["terrain", "stats", "--sweep", "{sweep}", "-f", "csv"], file_sweep(),
         "area,terrain,points,depth_mean_m", code=0,
         then=csv_header("area,terrain,points,depth_mean_m,depth_std_m,depth_min_m,depth_max_m,mean_slope_deg,"
                         "off_map_points,map_rms_10m,map_rms_20m,map_rms_30m")),
    case("dask-scheduler-not-answering", ["run", "{sweep}", "--out", "{tmp}/out", "--scheduler", "tcp://127.0.0.1:1"],
         BASE, "cannot reach the Dask scheduler at tcp://127.0.0.1:1", hang_s=120,
         then=lambda tmp, proc: no_directory(tmp / "out")),
    # terrain info
    case("terrain-info-needs-a-map-or-a-sweep", ["terrain", "info"], None,
         "give a map file (or a glob of tiles) or --sweep FILE, one of them"),
    case("terrain-info-missing-map", ["terrain", "info", "{tmp}/nothing.tif"], None, "nothing.tif: file not found"),
    case("terrain-info-of-a-sweep", ["terrain", "info", "--sweep", "configs/quick.yaml"], None,
         "synthetic:paper:seed1: 1201 x 481 nodes at 2.50 x 2.50 m; E 0.0 .. 3000.0 m, N 0.0 .. 1200.0 m; "
         "elevation (up positive) -120.9 .. 0.0 m", code=0),
    case("dask-scheduler-malformed", ["run", "{sweep}", "--out", "{tmp}/out", "--scheduler", "bogus"],
         BASE, "--scheduler 'bogus': not a Dask scheduler address", "give HOST:PORT", absent=("within",),
         then=lambda tmp, proc: no_directory(tmp / "out")),
    case("dask-scheduler-unknown-protocol", ["run", "{sweep}", "--out", "{tmp}/out", "--scheduler", "htp://h:8786"],
         BASE, "unknown protocol 'htp'"),
    case("dask-scheduler-with-a-space", ["run", "{sweep}", "--out", "{tmp}/out", "--scheduler", "tcp://h :8786"],
         BASE, "it holds a space"),
    case("dask-scheduler-without-a-host", ["run", "{sweep}", "--out", "{tmp}/out", "--scheduler", "tcp://:8786"],
         BASE, "no host"),
    case("terrain-info-bare-npy", ["terrain", "info", "{maps}/map.npy"], None, "no usable georeferencing",
         "give --sweep"),
]


# ---- issue 25: everything a sweep file says is used or refused; validate is run's first step --------


def fifo(tmp):
    """A FIFO where the sweep file should be (reading it would block forever)."""
    os.mkfifo(tmp / "fifo.yaml")
    return {}


def huge_sweep_file(tmp):
    (tmp / "huge.yaml").write_text("name: bad\nseed: 1\nruns: 1\n" + "# padding\n" * 150_000)
    return {}


def damaged_sweep_yaml(tmp):
    """The CI baseline whose sweep.yaml is binary junk (its run files still say whose they are)."""
    values = stored_results(tmp)
    (tmp / "out" / "sweep.yaml").write_bytes(bytes(range(256)) * 4)
    return values


ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join([f'*{chr(97 + i)}'] * 10)}]\n" for i in range(8)) + \
    "name: bad\nseed: 1\nruns: 1\n"
NESTED = "name: bad\nseed: 1\nruns: 1\nscenario: " + "[" * 5000 + "]" * 5000 + "\n"
LONG_NAME = "t" * 300


CASES += [
    # method options: checked before any task, one line each
    case("method-option-unknown", ["run", "{sweep}", "--out", "{tmp}/out"],
         sweep(methods=["pmf-dvl"], scenario__method_options={"pmf-dvl": {"grid_m": 5}}),
         "method_options.pmf-dvl.grid_m: unknown option of 'pmf-dvl' (known: cells, headings"),
    case("method-option-out-of-range", ["validate", "{sweep}"],
         sweep(methods=["pmf-dvl"], scenario__method_options={"pmf-dvl": {"cells": 2}}),
         "method_options.pmf-dvl.cells: Input should be greater than or equal to 4 (got 2)"),
    case("method-options-for-a-method-without-options", ["run", "{sweep}", "--out", "{tmp}/out"],
         sweep(scenario__method_options={"tight-dvl": {"cells": 2}}),
         "method_options.tight-dvl: method 'tight-dvl' takes no options"),
    case("method-options-of-a-misspelt-method", ["validate", "{sweep}"],
         sweep(methods=["pmf-dvl"], scenario__method_options={"pmf-dvk": {"cells": 16}}),
         "method_options.pmf-dvk: unknown method 'pmf-dvk' (its methods: pmf-dvl)"),
    case("method-options-of-an-absent-method", ["validate", "{sweep}"],
         sweep(scenario__method_options={"pmf-dvl": {"cells": 16}}),
         "method_options.pmf-dvl: options of method 'pmf-dvl', which this sweep does not run"),
    # names that become files: the length too (every task computed, then refused at the end, before)
    case("table-name-too-long", ["run", "{sweep}", "--out", "{out}"], sweep(tables={LONG_NAME: {"noise_m": [1.0]}}),
         "tables: table name 'tttttttttttttttttttt'... is 300 characters long", setup=stored_results),
    case("sweep-name-too-long", ["validate", "{sweep}"], sweep(name=LONG_NAME), "name: sweep name",
         "is 300 characters long"),
    # settings that would be ignored
    case("map-path-on-synthetic-terrain", ["validate", "{sweep}"], sweep(scenario__terrain__path="map.npy"),
         "scenario.terrain: path applies to file terrain only (kind: file); this terrain is synthetic"),
    case("table-mapping-drops-scenario-settings", ["run", "{sweep}", "--out", "{out}"],
         sweep(scenario__filter__ess_threshold=0.3, tables={"t": {"filter": [{"resampling": "residual"}]}}),
         "tables.t: filter: this mapping replaces the whole filter section of the scenario and drops "
         "filter.ess_threshold", setup=stored_results),
    case("profile-setting-overridden-is-shown", ["validate", "{sweep}"],
         sweep(profile="zhou2017-literal", scenario__filter__resampling="systematic"),
         "overridden by the sweep's scenario: filter.resampling = 'systematic' (the profile's 'multinomial' "
         "is not used)", "ok (1 cell(s)", code=0),
    # impossible worlds
    case("vehicle-above-the-surface", ["run", "{sweep}", "--out", "{tmp}/out"],
         sweep(scenario__trajectory__start_enu_m=[1111.2, 400.0, 50.0]),
         "the vehicle is above the sea surface at t=0 s (up +50.0 m)"),
    case("sonar-range-leaves-no-measurement", ["validate", "{sweep}"], sweep(scenario__sensors__max_range_m=1),
         "no sonar ping of the run has a bottom return from the DVL beams nor the altimeter",
         "sensors.max_range_m=1 m"),
    case("tide-bias-absurd", ["validate", "{sweep}"], sweep(scenario__faults__tide_bias_m=-1e6),
         "scenario.faults.tide_bias_m: Input should be greater than or equal to -100"),
    case("gyro-bias-absurd", ["validate", "{sweep}"], sweep(scenario__sensors__gyro_turn_on_bias_deg_h=1e9),
         "scenario.sensors.gyro_turn_on_bias_deg_h: Input should be less than or equal to 36000"),
    case("imu-slower-than-the-sonar", ["validate", "{sweep}"], sweep(scenario__sensors__imu_rate_hz=0.5),
         "scenario.sensors: imu_rate_hz (0.5) must be at least sonar_rate_hz (1)"),
    case("cruise-too-long-for-memory", ["validate", "{sweep}"],
         sweep(scenario__duration_s=None, scenario__trajectory__cruise_s=1e7),
         "a run lasts 10000350 s at sensors.imu_rate_hz=100 (1e+09 IMU samples): its vehicle data would take "
         "about", "shorten the trajectory", hang_s=240),
    # the sweep file itself
    case("sweep-file-is-a-fifo", ["validate", "{tmp}/fifo.yaml"], None, "fifo.yaml: not a regular file",
         setup=fifo, hang_s=120),
    case("sweep-file-too-large", ["validate", "{tmp}/huge.yaml"], None, "is too large for a sweep file",
         setup=huge_sweep_file),
    case("yaml-alias-bomb", ["validate", "{sweep}"], ALIAS_BOMB, "the YAML's aliases (*name) expand to",
         "an alias bomb?", hang_s=120),
    case("yaml-nested-too-deeply", ["validate", "{sweep}"], NESTED, "the YAML is nested too deeply"),
    # results directories
    case("out-empty", ["run", "{sweep}", "--out", ""], BASE, "--out '': give the results directory a name"),
    case("out-inside-a-results-directory", ["run", "{sweep}", "--out", "{out}/runs/new"], BASE,
         "is inside the results directory {tmp}/out", setup=stored_results),
    case("add-with-another-root-seed", ["run", "{sweep}", "--out", "{out}", "--add"], sweep(name="other"),
         "holds runs made with root seed 424242; sweep 'other' has root seed 1", "use another --out",
         setup=stored_results, absent=("--force",)),
    case("damaged-sweep-yaml-keeps-its-owner", ["run", "{sweep}", "--out", "{out}"], BASE,
         "holds the results of sweep 'ci' (its sweep.yaml is damaged", "not 'bad'", setup=damaged_sweep_yaml),
]


# ---- map readers (issue 16): depth-positive grids, NetCDF grids without coordinates ----------


def _seafloor_1km() -> np.ndarray:
    """A 1 km x 1 km seafloor at MAP_RES nodes, row 0 south, elevations -66..-54 m."""
    e = np.arange(0.0, 1000.0 + 1e-9, MAP_RES)
    ee, nn = np.meshgrid(e, e)
    return -60.0 + 5.0 * np.sin(ee / 50.0) * np.cos(nn / 70.0)


def depth_positive_geotiff(tmp):
    """An untagged GeoTIFF of depths (positive down), placed by the sweep's origin/resolution."""
    import tifffile

    tifffile.imwrite(tmp / "depths.tif", (-_seafloor_1km()).astype(np.float32))
    return {"depths": tmp / "depths.tif"}


def netcdf_without_coordinates(tmp):
    """A NetCDF grid with only its z variable: no x/y or lon/lat coordinate vectors."""
    from scipy.io import netcdf_file

    z = _seafloor_1km()
    with netcdf_file(tmp / "bare.nc", "w") as nc:
        nc.createDimension("rows", z.shape[0])
        nc.createDimension("cols", z.shape[1])
        nc.createVariable("z", "f8", ("rows", "cols"))[:] = z
    return {"bare_nc": tmp / "bare.nc"}


def no_georeferencing_arguments(data: dict) -> dict:
    for key in ("origin", "resolution"):
        data["scenario"]["terrain"].pop(key)
    return data


READER_CASES = [
    case("depth-positive-geotiff", ["validate", "{sweep}"], file_sweep("{depths}"),
         "bad.yaml: cell", "the map looks depth-positive",
         "(median elevation +58.1 m, range +57.9..+59.4 m)", "set terrain.positive: down",
         setup=depth_positive_geotiff),
    case("netcdf-without-coordinates-or-override", ["validate", "{sweep}"],
         no_georeferencing_arguments(file_sweep("{bare_nc}")),
         "bare.nc: the file has no usable georeferencing (no coordinate variables",
         "origin=(e0, n0) with resolution=", setup=netcdf_without_coordinates),
]
CASES += READER_CASES


# ---- map files the readers must refuse (or read quietly): headers, non-finite georeferencing, NetCDF --------


def broken_maps(tmp):
    """Map files, 1 km x 1 km at MAP_RES nodes unless said, each broken in one way (or extreme but readable)."""
    from scipy.io import netcdf_file

    z = _seafloor_1km()
    n = z.shape[0]
    header = {"ncols": n, "nrows": n, "xllcorner": -2.5, "yllcorner": -2.5, "cellsize": MAP_RES}
    for name, change in (("ncols-nan", {"ncols": "nan"}), ("ncols-fraction", {"ncols": "100.7"}),
                         ("nrows-negative", {"nrows": -100}), ("xllcorner-nan", {"xllcorner": "nan"}),
                         ("cellsize-inf", {"cellsize": "inf"})):
        lines = [f"{k} {v}" for k, v in {**header, **change}.items()]
        (tmp / f"{name}.asc").write_text("\n".join(lines + [" ".join(f"{v:.3f}" for v in row) for row in z[::-1]]))
    np.savez(tmp / "e0-nan.npz", z=z, e0=np.nan, n0=0.0, res_e=MAP_RES, res_n=MAP_RES)
    np.savez(tmp / "e0-inf.npz", z=z, e0=np.inf, n0=0.0, res_e=MAP_RES, res_n=MAP_RES)
    huge = np.full(z.shape, -1e307)  # elevations whose sum overflows
    huge[0, 0] = -1.5e307
    np.savez(tmp / "huge.npz", z=huge, e0=0.0, n0=0.0, res_e=MAP_RES, res_n=MAP_RES)
    np.savez(tmp / "two-by-two.npz", z=z[:2, :2], e0=0.0, n0=0.0, res_e=MAP_RES, res_n=MAP_RES)
    coords = np.arange(n) * MAP_RES
    for name in ("char-x", "scale-inf"):
        with netcdf_file(tmp / f"{name}.nc", "w") as nc:
            nc.createDimension("x", n)
            nc.createDimension("y", n)
            if name == "char-x":
                nc.createVariable("x", "S1", ("x",))[:] = np.array([b"a"] * n)
            else:
                nc.createVariable("x", "f8", ("x",))[:] = coords
            nc.createVariable("y", "f8", ("y",))[:] = coords
            v = nc.createVariable("z", "i2", ("y", "x"))
            v[:] = np.round(z * 100).astype(np.int16)
            if name == "scale-inf":
                v.scale_factor = np.float64(np.inf)
    return {"bm": tmp}


def quiet(*files):
    """A ``then=`` check of a command that succeeds: nothing on stderr (no numpy warning), ``files`` written."""
    def check(tmp, proc):
        assert proc.stderr == "", proc.stderr
        for name in files:
            assert (tmp / name).is_file(), name
    return check


BROKEN_MAP_CASES = [
    case("asc-ncols-nan", ["terrain", "info", "{bm}/ncols-nan.asc"], None,
         "ncols-nan.asc: ncols must be a positive whole number (got nan)", setup=broken_maps),
    case("asc-ncols-not-whole", ["terrain", "info", "{bm}/ncols-fraction.asc"], None,
         "ncols-fraction.asc: ncols must be a positive whole number (got 100.7)", setup=broken_maps),
    case("asc-nrows-negative-in-a-sweep", ["validate", "{sweep}"],
         no_georeferencing_arguments(file_sweep("{bm}/nrows-negative.asc")), "bad.yaml: cell",
         "nrows-negative.asc: nrows must be a positive whole number (got -100)", setup=broken_maps),
    case("asc-xllcorner-nan-in-a-sweep", ["validate", "{sweep}"],
         no_georeferencing_arguments(file_sweep("{bm}/xllcorner-nan.asc")), "bad.yaml: cell",
         "xllcorner-nan.asc: xllcorner must be finite (got nan)", setup=broken_maps, absent=("trajectory",)),
    case("asc-cellsize-inf", ["terrain", "info", "{bm}/cellsize-inf.asc"], None,
         "cellsize-inf.asc: cellsize must be a positive finite number (got inf)", setup=broken_maps),
    case("npz-e0-nan", ["terrain", "info", "{bm}/e0-nan.npz"], None,
         "e0-nan.npz: .npz key e0 must be finite, got nan", setup=broken_maps),
    case("npz-e0-inf-in-a-run", ["run", "{sweep}", "--out", "{tmp}/out"],
         no_georeferencing_arguments(file_sweep("{bm}/e0-inf.npz")), "bad.yaml: cell",
         "e0-inf.npz: .npz key e0 must be finite, got inf", setup=broken_maps, absent=("trajectory",)),
    case("netcdf-character-coordinate", ["terrain", "info", "{bm}/char-x.nc"], None,
         "char-x.nc: coordinate x is not numeric (it holds S1 values)", setup=broken_maps),
    case("netcdf-scale-factor-inf", ["terrain", "info", "{bm}/scale-inf.nc"], None,
         "scale-inf.nc: the grid holds no valid elevation once unpacked: z:scale_factor inf and add_offset 0 "
         "make every value non-finite", setup=broken_maps),
    case("resample-too-fine", ["validate", "{sweep}"], file_sweep(scenario__terrain__resample_m=0.01),
         "bad.yaml: cell", "terrain.resample_m (0.01 m) resamples the 1000 x 1000 m grid onto 100001 x 100001 "
         "nodes (1e+10), more than the ", "use a coarser resample_m (at least ", absent=("sensors.",)),
    # extreme but readable: the numbers as they are, no numpy warning
    case("terrain-info-elevations-near-the-float-limit", ["terrain", "info", "{bm}/huge.npz"], None,
         "huge.npz: 201 x 201 nodes at 5.00 x 5.00 m;",
         "elevation (up positive) -1.5e+307 .. -1e+307 m, mean -1.00001e+307;",
         setup=broken_maps, code=0, then=quiet()),
    case("suitability-of-a-two-by-two-map",
         ["terrain", "suitability", "{bm}/two-by-two.npz", "--out", "{tmp}/suit"], None,
         "two-by-two: 2 x 2 nodes, dvl at 30.0 m altitude", setup=broken_maps, code=0,
         then=quiet("suit/two-by-two-dvl.png", "suit/two-by-two-dvl-slope_std_deg.tif")),
]
CASES += BROKEN_MAP_CASES

MBE = {"multibeam_beams": 16}
CASES += [
    # the multibeam (issue 28): a row per new setting, checked before anything runs
    case("multibeam-beams-negative", ["validate", "{sweep}"], sweep(scenario__sensors={"multibeam_beams": -1}),
         "scenario.sensors.multibeam_beams: Input should be greater than or equal to 0 (got -1)"),
    case("multibeam-beams-too-many", ["validate", "{sweep}"], sweep(scenario__sensors={"multibeam_beams": 5000}),
         "scenario.sensors.multibeam_beams: Input should be less than or equal to 1024 (got 5000)"),
    case("multibeam-swath-too-wide", ["validate", "{sweep}"],
         sweep(scenario__sensors={**MBE, "multibeam_swath_deg": 180}),
         "scenario.sensors.multibeam_swath_deg: Input should be less than 170 (got 180)"),
    case("multibeam-pattern-unknown", ["validate", "{sweep}"],
         sweep(scenario__sensors={**MBE, "multibeam_pattern": "fan"}),
         "scenario.sensors.multibeam_pattern: Input should be 'equiangular' or 'equidistant' (got 'fan')"),
    case("multibeam-range-noise-negative", ["validate", "{sweep}"],
         sweep(scenario__sensors={**MBE, "multibeam_range_noise_m": -0.1}),
         "scenario.sensors.multibeam_range_noise_m: Input should be greater than or equal to 0 (got -0.1)"),
    case("multibeam-angle-noise-absurd", ["validate", "{sweep}"],
         sweep(scenario__sensors={**MBE, "multibeam_angle_noise_deg": 10}),
         "scenario.sensors.multibeam_angle_noise_deg: Input should be less than or equal to 5 (got 10)"),
    case("multibeam-rate-off-the-sonar-clock", ["validate", "{sweep}"],
         sweep(scenario__sensors={**MBE, "multibeam_rate_hz": 0.3}),
         "scenario.sensors: multibeam_rate_hz (0.3) must divide sonar_rate_hz (1)"),
    case("multibeam-method-without-a-multibeam", ["validate", "{sweep}"], sweep(methods=["tight-mbe"]),
         "the multibeam methods (*-mbe) need a multibeam: set sensors.multibeam_beams > 0"),
    case("multibeam-beams-used-negative", ["validate", "{sweep}"],
         sweep(methods=["tight-mbe"], scenario__sensors=MBE, scenario__method_options={"tight-mbe": {"beams_used": -1}}),
         "method_options.tight-mbe.beams_used: Input should be greater than or equal to 0 (got -1)"),
    case("multibeam-selection-unknown", ["validate", "{sweep}"],
         sweep(methods=["pmf-mbe"], scenario__sensors=MBE, scenario__method_options={"pmf-mbe": {"selection": "best"}}),
         "method_options.pmf-mbe.selection: Input should be 'every-kth' or 'information' (got 'best')"),
    case("suitability-multibeam-swath-too-wide", ["terrain", "suitability", "{maps}/map.npy", "--sensor", "mbe",
                                                  "--swath", "200", "--out", "{tmp}/suit"], None,
         "--beams/--swath: multibeam_swath_deg: Input should be less than 170 (got 200.0)"),
]


@pytest.mark.parametrize("setup, changes", [
    (depth_positive_geotiff, {"scenario__terrain__positive": "down"}),
    (netcdf_without_coordinates, {}),
], ids=["depth-positive-negated", "netcdf-origin-resolution"])
def test_reader_inputs_accepted_as_documented(tmp_path, setup, changes):
    """The same maps with the documented option validate, and read as the seafloor they hold."""
    from tanbench.sweep import load_sweep
    from tanbench.terrain import truth_map

    path = next(iter(setup(tmp_path).values()))
    data = file_sweep(str(path), **changes)
    (tmp_path / "ok.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    proc = cli("validate", tmp_path / "ok.yaml")
    assert proc.returncode == 0 and "ok (1 cell(s)" in proc.stdout, proc.stderr
    grid = truth_map(load_sweep(tmp_path / "ok.yaml").cells[0].scenario.terrain)
    np.testing.assert_allclose(grid.z, _seafloor_1km(), atol=1e-5)  # float32 in the GeoTIFF
    assert (grid.e0, grid.n0, grid.res_e, grid.res_n) == (0.0, 0.0, MAP_RES, MAP_RES)


# ---- end of the map-reader block ---------------------------------------------------------------


@pytest.fixture(scope="module")
def maps(tmp_path_factory):
    """A 1 km x 1 km .npy map (5 m nodes), the same with a hole under the survey, and broken files."""
    d = tmp_path_factory.mktemp("maps")
    e = np.arange(0.0, 1000.0 + 1e-9, MAP_RES)
    ee, nn = np.meshgrid(e, e)
    z = -60.0 + 5.0 * np.sin(ee / 50.0) * np.cos(nn / 70.0) + 3.0 * np.cos(ee / 23.0 + nn / 41.0)
    np.save(d / "map.npy", z)
    holes = z.copy()
    holes[(nn >= 480) & (nn <= 520) & (ee >= 430) & (ee <= 470)] = np.nan  # on the first leg (E = 450 m)
    np.save(d / "holes.npy", holes)
    (d / "garbage.tif").write_bytes(b"\x00 this is not a TIFF \xff" * 40)
    import tifffile
    tifffile.imwrite(d / "whole.tif", z.astype(np.float32))
    (d / "truncated.tif").write_bytes((d / "whole.tif").read_bytes()[:200])  # tifffile logged 9 lines of its own
    (d / "map.xyz").write_text("0 0 -60\n5 0 -61\n")
    (d / "text.npy").write_text("hello")
    (d / "a-directory.npy").mkdir()
    return d


def fill(text: str, values: dict) -> str:
    for key, value in values.items():
        text = text.replace("{" + key + "}", str(value))
    return text


def prepare(tmp_path, maps, args, data, setup):
    """Write the case's sweep file and run its setup; the CLI arguments with placeholders filled."""
    values = {"maps": maps, "tmp": tmp_path, "sweep": tmp_path / "bad.yaml"}
    if setup is not None:
        values.update(setup(tmp_path))
    if data is not None:
        text = data if isinstance(data, str) else yaml.safe_dump(data, sort_keys=False)
        (tmp_path / "bad.yaml").write_text(fill(text, values))
    return [fill(a, values) for a in args]


def snapshot(root: Path) -> dict[str, str]:
    """Every file under ``root`` (hidden ones too) and a hash of its bytes."""
    out = {}
    for path in sorted(root.rglob("*")):
        if path.is_file():
            out[str(path.relative_to(root))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


def stat_snapshot(root: Path) -> dict[str, tuple]:
    """Every file and directory under ``root`` (hidden ones too) with its size, modification time
    (ns) and inode: a file written, replaced, added or removed changes it. For the project's
    results/ (tens of MB, read before and after every case), where hashing every byte twice per
    case cost more than the command under test."""
    out = {}
    for path in sorted(root.rglob("*")):
        info = path.lstat()
        out[str(path.relative_to(root))] = (info.st_size, info.st_mtime_ns, info.st_ino)
    return out


@pytest.mark.parametrize("args, data, fragments, setup, hang_s, code, then, absent", CASES)
def test_bad_input_gives_one_error_line(tmp_path, maps, args, data, fragments, setup, hang_s, code, then, absent):
    """Bad input: one `error:` line naming the problem, exit 2, no traceback, nothing stored changed.
    (The cases with another ``code`` say what they print instead, on stdout or stderr.)"""
    argv = prepare(tmp_path, maps, args, data, setup)
    root_results = stat_snapshot(ROOT / "results")
    before = snapshot(tmp_path)
    try:  # a hang detector, not a speed assertion: the command is given far more than it needs
        proc = cli(*argv, timeout=hang_s)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the command hung (no answer in {hang_s} s): {argv}")
    assert proc.returncode == code, (proc.returncode, proc.stdout[-2000:], proc.stderr)
    assert "Traceback" not in proc.stderr + proc.stdout
    assert "Warning" not in proc.stderr, proc.stderr
    if code == 2:
        lines = error_lines(proc.stderr)
        assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
        text = lines[0]
    else:
        text = proc.stdout + proc.stderr
    for fragment in fragments:
        assert fill(fragment, {"tmp": tmp_path}) in text, text[-3000:]
    for fragment in absent:
        assert fill(fragment, {"tmp": tmp_path}) not in text, text[-3000:]
    if then is None:  # nothing stored changed (the project's results/ included)
        assert snapshot(tmp_path) == before
    else:
        then(tmp_path, proc)
    assert stat_snapshot(ROOT / "results") == root_results


def test_holes_are_accepted_when_filled(tmp_path, maps):
    """The map with a hole under the track validates and runs with terrain.fill_holes: true."""
    data = file_sweep("{maps}/holes.npy", runs=1, scenario__duration_s=None, scenario__terrain__fill_holes=True)
    argv = prepare(tmp_path, maps, ["validate", "{sweep}"], data, None)
    proc = cli(*argv)
    assert proc.returncode == 0 and "ok (1 cell(s)" in proc.stdout, proc.stderr
    proc = cli("run", argv[1], "--out", tmp_path / "out", "--workers", 1, "-q")
    assert proc.returncode == 0, proc.stderr
    runs = pd.read_parquet(tmp_path / "out" / "runs")
    assert (runs["status"] == "ok").all() and runs["terrain.fill_holes"].all()


def test_debug_shows_the_traceback(tmp_path, maps):
    """With --debug the same bad input raises with its traceback (exit 1 from Python)."""
    argv = prepare(tmp_path, maps, ["validate", "{sweep}"], sweep(runs=0), None)
    proc = cli("--debug", *argv)
    assert proc.returncode != 0
    assert "Traceback (most recent call last)" in proc.stderr
    assert "TanbenchError: " in proc.stderr and "runs: Input should be greater than 0" in proc.stderr


def test_usage_errors_are_one_line_too(tmp_path, maps):
    """A bad command-line option (`--workers 0`) is one `error:` line with exit 2, like bad input."""
    argv = prepare(tmp_path, maps, ["run", "{sweep}"], BASE, None)
    proc = cli(*argv, "--workers", 0)
    lines = error_lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "--workers" in lines[0]
    assert not os.path.exists(tmp_path / "results")


@pytest.mark.parametrize("data", [
    sweep(scenario__noise_m=float("inf")),
    sweep(scenario__duration_s=0.001),
    sweep(scenario__duration_s=None, scenario__sampling_time_s=100000, scenario__map_resolution_m=20),
    file_sweep(scenario__filter__initial_area_m=2000),
    file_sweep(scenario__terrain__resample_m=0.01),
], ids=["noise-inf", "duration-0.001", "sampling-longer-than-the-run", "initial-uncertainty-off-the-map",
        "resample-too-fine"])
def test_validate_refuses_what_run_refuses(tmp_path, maps, data):
    """`validate` and `run` give the same one error line (run before any task, storing nothing)."""
    argv = prepare(tmp_path, maps, ["validate", "{sweep}"], data, None)
    checked = cli(*argv)
    ran = cli("run", argv[1], "--out", tmp_path / "out", "--workers", 1, "-q")
    assert checked.returncode == ran.returncode == 2, (checked.stderr, ran.stderr)
    assert error_lines(checked.stderr) == error_lines(ran.stderr) and len(error_lines(ran.stderr)) == 1
    assert not list((tmp_path / "out").rglob("*.parquet"))


# a full disk, as every write sees it: sitecustomize is imported by the CLI and its workers
FULL_DISK = '''
import errno
import os


def _full(fd):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


os.fsync = _full
'''


def test_a_full_disk_is_one_line_naming_the_path(tmp_path, maps):
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(FULL_DISK)
    argv = prepare(tmp_path, maps, ["run", "{sweep}", "--out", "{tmp}/out", "--workers", "1", "-q"], BASE, None)
    proc = cli(*argv, extra_path=hook)
    lines = error_lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"error: cannot write {tmp_path}/out/") and "No space left on device" in lines[0]
    assert not [p for p in (tmp_path / "out").rglob("*") if p.is_file()]  # no half-written or temporary file


def test_plan_is_linear_in_cells_and_warns_past_a_size(tmp_path, monkeypatch):
    """`plan` costs each cell once (a task's cost depends only on its cell: it was computed per task, and
    per cell by scanning every task, quadratic in cells); past LARGE_SWEEP_CELLS it warns."""
    from tanbench.methods.registry import MethodRecord
    from tanbench.runner import plan as planning
    from tanbench.sweep import parse_sweep

    cells = planning.LARGE_SWEEP_CELLS + 25
    data = sweep(runs=3, grid={"particles": list(range(100, 100 + cells))})
    swept = parse_sweep(yaml.safe_dump(data))
    calls = []
    real = MethodRecord.estimate_seconds
    monkeypatch.setattr(MethodRecord, "estimate_seconds", lambda self, sc: calls.append(1) or real(self, sc))
    made = planning.make_plan(swept, tmp_path / "out", workers=2)
    assert len(made.tasks) == 3 * cells and len(calls) == cells * len(swept.spec.methods)
    assert f"expands to {cells} cells" in planning.size_warning(swept)
