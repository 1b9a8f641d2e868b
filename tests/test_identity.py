"""Cell identities: a stored run is reused exactly when it would come out the same.

* an option added with its neutral default changes no cell key, world key or seed, so
  the committed results still match (checked here on every committed results directory
  with a Scenario model extended by such an option);
* the option at another value, or a default changed on purpose, changes the keys;
* on resume, runs with other seeds (a changed root seed) are not reused, a method added
  to a sweep runs for every stored run, and another sweep's directory is refused.
"""

from __future__ import annotations

import copy
import shutil
from pathlib import Path

import pytest
import yaml
from pydantic import create_model

from sweep_support import ROOT, cli, error_lines, sweep_dict, write_sweep
from tanbench import results
from tanbench.config import FilterSpec, Scenario, new_option
from tanbench.sweep import load_sweep

def _committed_result_dirs() -> list[Path]:
    """results/*/ with a sweep.yaml, less the directories .gitignore keeps out of the repository (results/ci,
    results/quick, ...: a local `make ci-check` or `make run` leaves them, written by whatever code ran then)."""
    import fnmatch

    ignored = [line.strip().rstrip("/") for line in (ROOT / ".gitignore").read_text().splitlines()
               if line.strip().startswith("results/")]
    return sorted(p.parent for p in (ROOT / "results").glob("*/sweep.yaml")
                  if not any(fnmatch.fnmatch(f"results/{p.parent.name}", pattern) for pattern in ignored))


COMMITTED = _committed_result_dirs()


def extended_scenario(default=5.0, neutral=5.0):
    """The Scenario model with a new filter option ``pmf_grid_m`` (as a new method would add)."""
    filter_spec = create_model("FilterSpecPlus", __base__=FilterSpec,
                               pmf_grid_m=(float, new_option(default, neutral=neutral, gt=0)))
    return create_model("ScenarioPlus", __base__=Scenario, filter=(filter_spec, filter_spec()))


@pytest.mark.parametrize("directory", COMMITTED, ids=[p.name for p in COMMITTED])
def test_a_defaulted_new_option_keeps_every_committed_cell_key(directory):
    plus = extended_scenario()
    stored = {p.name.split("=", 1)[1] for p in (directory / "runs").glob("cell_id=*")}
    sweep = load_sweep(directory / "sweep.yaml")
    assert {c.cell_id for c in sweep.cells} == stored
    for cell in sweep.cells:
        again = plus(**cell.scenario.normalized())
        assert again.filter.pmf_grid_m == 5.0
        assert again.cell_key() == cell.cell_id
        assert again.world_key() == cell.scenario.world_key()


def test_the_new_option_at_another_value_or_a_changed_default_changes_the_key():
    base = Scenario()
    assert extended_scenario()(filter={"pmf_grid_m": 2.0}).cell_key() != base.cell_key()
    # a default changed on purpose keeps the old behaviour as neutral: keys change
    assert extended_scenario(default=2.0, neutral=5.0)().cell_key() != base.cell_key()
    # world keys only cover the world: a filter option never changes the vehicle data
    assert extended_scenario()(filter={"pmf_grid_m": 2.0}).world_key() == base.world_key()


def test_method_options_at_their_default_are_neutral():
    assert Scenario(method_options={}).cell_key() == Scenario().cell_key()
    assert Scenario(method_options={"x.y:run": {"a": 1}}).cell_key() != Scenario().cell_key()


@pytest.mark.parametrize("directory", COMMITTED, ids=[p.name for p in COMMITTED])
def test_committed_runs_tabulate_to_the_committed_tables(directory):
    """Today's code, tabulating the committed runs, writes exactly the committed tables/*.md."""
    from tanbench.results import sweep_tables, to_markdown

    tables = sweep_tables(results.load(directory), load_sweep(directory / "sweep.yaml"))
    committed = sorted((directory / "tables").glob("*.md"))
    assert sorted(p.stem for p in committed) == sorted(tables)
    for md in committed:
        assert to_markdown(tables[md.stem], title=md.stem).strip() == md.read_text().strip(), md.name


def ci_check_options():
    """The options `make ci-check` passes to `tanbench check`, read from the Makefile (one place)."""
    line = next(l for l in (ROOT / "Makefile").read_text().splitlines() if l.startswith("CI_CHECK_OPTIONS ="))
    return line.split("=", 1)[1].split()


def test_ci_baseline_checks_against_itself():
    baseline = ROOT / "results" / "ci-baseline"
    proc = cli("check", baseline, baseline, *ci_check_options())
    assert proc.returncode == 0, proc.stdout + proc.stderr


STORED = sweep_dict(runs=2, methods=["tight-dvl"], tables={})


@pytest.fixture(scope="module")
def stored_once(tmp_path_factory):
    """The 1-cell sweep STORED run once (the tests below change a copy of its results)."""
    root = tmp_path_factory.mktemp("stored")
    out = root / "out"
    proc = cli("run", write_sweep(root / "s.yaml", STORED), "--out", out, "--workers", 1, "-q")
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture
def stored(stored_once, tmp_path):
    """A private copy of STORED's sweep file and results: (sweep dict, results directory, directory)."""
    data = copy.deepcopy(STORED)
    write_sweep(tmp_path / "s.yaml", data)
    out = tmp_path / "out"
    shutil.copytree(stored_once, out)
    return data, out, tmp_path


def test_a_method_added_to_a_sweep_runs_for_every_stored_run(stored):
    data, out, tmp = stored
    before = results.load(out)
    data["methods"] = ["tight-dvl", "tight-sbe"]
    proc = cli("run", write_sweep(tmp / "s.yaml", data), "--out", out, "--workers", 1, "-q")
    assert proc.returncode == 0, proc.stderr
    runs = results.load(out)
    assert (runs.groupby("method")["run"].nunique() == 2).all()
    old = runs[runs["method"] == "tight-dvl"].sort_values("run")
    assert list(old["final_horizontal_error_m"]) == list(before.sort_values("run")["final_horizontal_error_m"])


def test_a_changed_root_seed_does_not_reuse_runs(stored):
    data, out, tmp = stored
    before = sorted((out / "runs").rglob("*.parquet"))
    stamps = [p.stat().st_mtime_ns for p in before]
    data["seed"] += 1
    path = write_sweep(tmp / "s.yaml", data)
    proc = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert proc.returncode == 2
    lines = error_lines(proc.stderr)
    assert len(lines) == 1 and "made with other seeds" in lines[0] and "--force" in lines[0]
    assert [p.stat().st_mtime_ns for p in before] == stamps  # nothing stored changed
    forced = cli("run", path, "--out", out, "--workers", 1, "-q", "--force")
    assert forced.returncode == 0, forced.stderr
    runs = results.load(out)
    from tanbench.runner.seeds import seed_number, vehicle_seed

    sc = load_sweep(path).cells[0].scenario
    assert set(runs["seed"]) == {seed_number(vehicle_seed(data["seed"], sc, r)) for r in (0, 1)}


def test_another_sweep_into_the_same_directory_is_refused_unless_added(stored):
    data, out, tmp = stored
    other = dict(data, name="other")
    path = write_sweep(tmp / "o.yaml", other)
    proc = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert proc.returncode == 2
    line = error_lines(proc.stderr)[0]
    assert "holds the results of sweep 'tiny'" in line and "--add" in line
    assert yaml.safe_load((Path(out) / "sweep.yaml").read_text())["name"] == "tiny"
    added = cli("run", path, "--out", out, "--workers", 1, "-q", "--add")
    assert added.returncode == 0, added.stderr


def test_an_edited_map_file_is_noticed_on_resume(tmp_path):
    """The runs of a file terrain carry its content hash: after editing the file they are not reused."""
    import numpy as np

    ee, nn = np.meshgrid(np.arange(0, 1001, 10.0), np.arange(0, 1001, 10.0))
    relief = -80.0 + 8 * np.sin(ee / 60.0) * np.cos(nn / 45.0)
    np.save(tmp_path / "map.npy", relief)
    data = sweep_dict(runs=1, methods=["tight-dvl"], tables={}, scenario={
        "area": "custom", "particles": 60, "duration_s": 60,
        "terrain": {"kind": "file", "path": str(tmp_path / "map.npy"), "origin": [0, 0], "resolution": 10.0},
        "trajectory": {"kind": "survey", "centre_en_m": [500, 500], "heading_deg": 0, "leg_length_m": 300,
                       "leg_spacing_m": 100, "legs": 2, "depth_m": 20}})
    path = write_sweep(tmp_path / "s.yaml", data)
    out = tmp_path / "out"
    assert cli("run", path, "--out", out, "--workers", 1, "-q").returncode == 0
    np.save(tmp_path / "map.npy", relief + 0.5)  # the same grid, re-surveyed
    proc = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert proc.returncode == 2
    lines = error_lines(proc.stderr)
    assert len(lines) == 1 and "map files whose content has changed" in lines[0], proc.stderr
    forced = cli("run", path, "--out", out, "--workers", 1, "-q", "--force")
    assert forced.returncode == 0, forced.stderr
    again = cli("run", path, "--out", out, "--workers", 1, "-q")
    assert again.returncode == 0 and "0 tasks (0 runs) run" in again.stdout, again.stdout


# ---- user methods: identity covers their code (issue 25) -------------------------------------------

OFFSET_PLUGIN = '''"""A dead-reckoning plug-in whose estimate is offset east (the offset stands for an edit)."""

OFFSET_M = {offset}


def run(ctx):
    pos = ctx.nav.pos[ctx.updates.imu]
    return {{"east": pos[:, 0] + OFFSET_M, "north": pos[:, 1]}}
'''
VERSIONED_PLUGIN = OFFSET_PLUGIN + '''
from tanbench.methods import MethodRecord  # noqa: E402

METHOD = MethodRecord(name="versioned", seed_id=0, summary="offset dead reckoning", run=run, version={version!r})
'''


def plugin_sweep(tmp_path, method: str, offset: float, version: str | None = None, runs: int = 2):
    """A package ``mine`` with the plug-in (written with ``offset``) and a 1-cell sweep naming it."""
    package = tmp_path / "userland" / "mine"
    package.mkdir(parents=True, exist_ok=True)
    (package / "__init__.py").write_text("")
    text = VERSIONED_PLUGIN.format(offset=offset, version=version) if version else OFFSET_PLUGIN.format(offset=offset)
    (package / "plug.py").write_text(text)
    return write_sweep(tmp_path / "s.yaml", sweep_dict(runs=runs, methods=[method], tables={}))


def plugin_run(tmp_path, path, *args):
    return cli("run", path, "--out", tmp_path / "out", "--workers", 1, "-q", *args, extra_path=tmp_path / "userland")


def final_errors(out) -> list[float]:
    return list(results.load(out).sort_values("run")["final_horizontal_error_m"])


def test_a_plugin_whose_code_changed_is_recomputed_never_reused_or_pooled(tmp_path):
    """A stored run made by other code of a user method is recomputed (with one line saying so):
    on resume, and when --runs adds runs beside it; no table pools the two codes."""
    method = "mine.plug:run"
    path = plugin_sweep(tmp_path, method, offset=0.0)
    first = plugin_run(tmp_path, path)
    assert first.returncode == 0, first.stderr
    before = final_errors(tmp_path / "out")
    assert max(before) < 400

    plugin_sweep(tmp_path, method, offset=1000.0)  # the plug-in edited
    again = plugin_run(tmp_path, path)
    assert again.returncode == 0, again.stderr
    assert "2 tasks (2 runs) run, 0 tasks (0 runs) already done" in again.stdout
    notes = [line for line in again.stderr.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and f"recomputing 2 stored run(s) of {method} in 1 cell(s): its code has changed" \
        in notes[0], again.stderr
    assert min(final_errors(tmp_path / "out")) > 400

    plugin_sweep(tmp_path, method, offset=0.0)  # edited back; then two more runs
    more = plugin_run(tmp_path, path, "--runs", 4)
    assert more.returncode == 0, more.stderr
    assert "4 tasks (4 runs) run" in more.stdout  # runs 0-1 recomputed, not pooled with runs 2-3
    assert max(final_errors(tmp_path / "out")) < 400 and len(final_errors(tmp_path / "out")) == 4


@pytest.mark.parametrize("package", ["initpkg", "nsroot.sub"])
def test_a_plugin_defined_in_its_package_init_is_its_whole_package(tmp_path, package):
    """A method whose ``run`` lives in its package's ``__init__.py`` and reads another module of the package:
    an edit of that module is noticed. The hash covered only ``__init__.py``, and a stale run was reused (found
    by a user's audit); under a namespace package (``nsroot``, no __init__.py of its own), only the module's file
    (found by the review)."""
    folder = tmp_path / "userland" / package.replace(".", "/")
    folder.mkdir(parents=True)
    (folder / "__init__.py").write_text(f"from {package} import core\n\n\ndef run(ctx):\n"
                                        "    pos = ctx.nav.pos[ctx.updates.imu]\n"
                                        "    return {'east': pos[:, 0] + core.OFFSET_M, 'north': pos[:, 1]}\n")
    (folder / "core.py").write_text("OFFSET_M = 0.0\n")
    path = write_sweep(tmp_path / "s.yaml", sweep_dict(runs=2, methods=[f"{package}:run"], tables={}))
    assert plugin_run(tmp_path, path).returncode == 0
    assert max(final_errors(tmp_path / "out")) < 400
    (folder / "core.py").write_text("OFFSET_M = 1000.0\n")
    again = plugin_run(tmp_path, path)
    assert again.returncode == 0, again.stderr
    assert f"recomputing 2 stored run(s) of {package}:run" in again.stderr
    assert min(final_errors(tmp_path / "out")) > 400


def test_a_plugin_with_a_declared_version_is_reused_until_the_version_changes(tmp_path):
    method = "mine.plug:METHOD"
    path = plugin_sweep(tmp_path, method, offset=0.0, version="1")
    assert plugin_run(tmp_path, path).returncode == 0
    before = final_errors(tmp_path / "out")
    plugin_sweep(tmp_path, method, offset=1000.0, version="1")  # the author says: same results
    same = plugin_run(tmp_path, path)
    assert same.returncode == 0 and "0 tasks (0 runs) run" in same.stdout, same.stdout + same.stderr
    assert final_errors(tmp_path / "out") == before
    plugin_sweep(tmp_path, method, offset=1000.0, version="2")
    bumped = plugin_run(tmp_path, path)
    assert bumped.returncode == 0 and "2 tasks (2 runs) run" in bumped.stdout, bumped.stderr
    assert "(now: version 2)" in bumped.stderr
    assert min(final_errors(tmp_path / "out")) > 400
