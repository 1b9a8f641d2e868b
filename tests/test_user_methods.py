"""User methods from a sweep file: the worked example in examples/, run from outside the tree.

The example plug-ins are copied to a temporary directory (so nothing of the repository
is importable but the installed tanbench), put on PYTHONPATH, and run in one sweep
beside two built-ins with 2 local workers and on a local Dask cluster: the runs must be
identical. They appear in the tables, the figures and `tanbench check`, and pass the
public conformance check. Bad plug-ins get one clear line and nothing stored is lost.
"""

from __future__ import annotations

import shutil
import subprocess
import sys

import pandas as pd
import pytest
import yaml

from sweep_support import ROOT, assert_same_runs, cli, cli_env, error_lines
from tanbench import results

DR = "tan_plugins.dead_reckoning:run"
PF = "tan_plugins.numpy_pf:METHOD"


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory):
    """The example plug-ins and their sweep, copied outside the repository (2 runs, 120 s)."""
    base = tmp_path_factory.mktemp("userland")
    shutil.copytree(ROOT / "examples" / "tan_plugins", base / "tan_plugins")
    sweep = yaml.safe_load((ROOT / "examples" / "run_sweep.yaml").read_text())
    sweep["runs"] = 2
    sweep["scenario"]["duration_s"] = 120
    sweep["scenario"]["particles"] = 300
    (base / "sweep.yaml").write_text(yaml.safe_dump(sweep, sort_keys=False))
    return base


@pytest.fixture(scope="module")
def two_ways(plugin_dir):
    """The example sweep with --workers 2 and with --scheduler local-dask."""
    outs = {}
    for label, args in (("local", ["--workers", 2]), ("dask", ["--scheduler", "local-dask", "--workers", 2])):
        out = plugin_dir / f"out-{label}"
        proc = cli("run", plugin_dir / "sweep.yaml", "--out", out, "-q", *args, extra_path=plugin_dir,
                   cwd=plugin_dir, timeout=600)
        assert proc.returncode == 0, proc.stderr
        outs[label] = out
    return outs


@pytest.mark.slow
def test_user_methods_run_beside_builtins_identically_on_both_executors(two_ways):
    local, dask = (results.load(two_ways[k]) for k in ("local", "dask"))
    assert set(local["method"]) == {"tight-dvl", "loose-dvl", DR, PF}
    assert (local["status"] == "ok").all(), local.loc[local["status"] != "ok", "error"].tolist()
    assert_same_runs(local, dask)


@pytest.mark.slow
def test_user_methods_in_tables_figures_and_check(two_ways, plugin_dir):
    out = two_ways["local"]
    proc = cli("tables", out, extra_path=plugin_dir, cwd=plugin_dir)
    assert proc.returncode == 0, proc.stderr
    assert DR in proc.stdout and PF in proc.stdout
    plot = cli("plot", out, extra_path=plugin_dir, cwd=plugin_dir)
    assert plot.returncode == 0, plot.stderr
    assert list((out / "figures").glob("*.png"))
    check = cli("check", two_ways["dask"], out, "--allow-underpowered", extra_path=plugin_dir, cwd=plugin_dir)
    assert check.returncode == 0, check.stdout + check.stderr
    assert PF in check.stdout


@pytest.mark.slow
def test_dead_reckoning_plugin_is_the_navigation_solution(two_ways):
    runs = results.load(two_ways["local"])
    dr = runs[runs["method"] == DR].set_index(["cell_id", "run"])
    tight = runs[runs["method"] == "tight-dvl"].set_index(["cell_id", "run"])
    # terrain aiding beats the navigation system alone on area A
    assert (tight["final_horizontal_error_m"] < dr["final_horizontal_error_m"]).all()


@pytest.mark.parametrize("method", [DR, PF])
def test_example_plugins_pass_the_public_conformance_check(plugin_dir, method):
    code = f"from tanbench.testing import check_method; print(check_method({method!r}).checks)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=plugin_dir,
                          env=cli_env(plugin_dir), timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "identical in a worker process" in proc.stdout


BAD_PLUGINS = {
    "no_such_module_xyz:run": "module 'no_such_module_xyz' not found",
    "tan_plugins.dead_reckoning:nothing": "has no attribute 'nothing'",
    "tan_plugins.broken:run": "importing tan_plugins.broken failed: ZeroDivisionError",
    # a module that ends the process, or raises a BaseException, while importing (found by an audit: exit 4 with
    # nothing printed, or a traceback)
    "tan_plugins.exits:run": "importing tan_plugins.exits failed: SystemExit: 4",
    "tan_plugins.generator_exit:run": "importing tan_plugins.generator_exit failed: GeneratorExit: at import",
    # a plot style the figures cannot draw: refused when the record loads, not later by `plot` (found by an audit)
    "tan_plugins.styled:BAD_COLOR": "method 'tan_plugins.styled:BAD_COLOR': color 'notacolor' is not a matplotlib",
    "tan_plugins.styled:BAD_LINE": "method 'tan_plugins.styled:BAD_LINE': linestyle 'zz' is not one of -, --, -., :",
}
STYLED = """from tanbench.methods import MethodRecord
from tan_plugins.dead_reckoning import run
BAD_COLOR = MethodRecord(name="x", seed_id=0, run=run, summary="s", color="notacolor")
BAD_LINE = MethodRecord(name="x", seed_id=0, run=run, summary="s", linestyle="zz")
"""


@pytest.mark.parametrize("name, message", sorted(BAD_PLUGINS.items()))
def test_a_plugin_that_does_not_load_is_one_line(plugin_dir, tmp_path, name, message):
    (plugin_dir / "tan_plugins" / "broken.py").write_text("x = 1 / 0\n")
    (plugin_dir / "tan_plugins" / "exits.py").write_text("import sys\nsys.exit(4)\n")
    (plugin_dir / "tan_plugins" / "generator_exit.py").write_text("raise GeneratorExit('at import')\n")
    (plugin_dir / "tan_plugins" / "styled.py").write_text(STYLED)
    sweep = yaml.safe_load((plugin_dir / "sweep.yaml").read_text())
    sweep["methods"] = ["tight-dvl", name]
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(sweep))
    proc = cli("validate", path, extra_path=plugin_dir, cwd=plugin_dir)
    assert proc.returncode == 2
    lines = error_lines(proc.stderr)
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in proc.stderr, proc.stderr


WRONG_OUTPUTS = {
    "shape": ("return {'east': ctx.nav.pos[:3, 0], 'north': ctx.nav.pos[:3, 1]}", "has shape (3,)"),
    "nan": ("import numpy as np\n    k = ctx.updates.size\n    return {'east': np.full(k, np.nan), "
            "'north': np.zeros(k)}", "east is not finite"),
    "key": ("k = ctx.updates.size\n    return {'east': [0.0] * k, 'north': [0.0] * k, 'speed': [0.0] * k}",
            "unknown key(s) 'speed'"),
    # values converted silently before (found by an audit): complex, text, a reinit flag of 2.5
    "complex": ("k = ctx.updates.size\n    return {'east': [0j] * k, 'north': [0.0] * k}",
                "east is not real numbers (dtype complex128)"),
    "text": ("k = ctx.updates.size\n    return {'east': ['1.0'] * k, 'north': [0.0] * k}",
             "east is not real numbers (dtype <U3)"),
    "reinit": ("k = ctx.updates.size\n    return {'east': [0.0] * k, 'north': [0.0] * k, 'reinit': [2.5] * k}",
               "reinit holds flags, 0 or 1 (or booleans), not 2.5 (update 0)"),
    "raises": ("raise RuntimeError('inside the run')", "RuntimeError: inside the run"),
    # ways of ending the worker process: the run's failure, with what the method did and where
    "sys_exit": ("import sys\n    sys.exit(3)", "called sys.exit(3) (at wrong_sys_exit.py:3)"),
    "os_exit": ("import os\n    os._exit(3)", "called os._exit(3) (at wrong_os_exit.py:3)"),
    "os_exit_imported": ("from os import _exit\n    _exit(3)", "called os._exit(3)"),
    "keyboard_interrupt": ("raise KeyboardInterrupt", "raised KeyboardInterrupt (at wrong_keyboard_interrupt.py:2)"),
    "writes_its_inputs": ("ctx.obs.dvl_ranges[:] += 50\n    return {}", "tried to write into its inputs"),
    # any other BaseException fails its own run, not the task's other methods (it used to lose the whole task)
    "generator_exit": ("raise GeneratorExit('ge')", "raised GeneratorExit: ge (at wrong_generator_exit.py:2)"),
}


@pytest.mark.parametrize("case", sorted(WRONG_OUTPUTS))
def test_a_plugin_that_misbehaves_in_a_run_is_recorded_per_run(plugin_dir, tmp_path, case):
    body, message = WRONG_OUTPUTS[case]
    (plugin_dir / "tan_plugins" / f"wrong_{case}.py").write_text(f"def run(ctx):\n    {body}\n")
    sweep = yaml.safe_load((plugin_dir / "sweep.yaml").read_text())
    sweep.update(runs=1, methods=["tight-dvl", f"tan_plugins.wrong_{case}:run"], tables={})
    sweep["scenario"].update(duration_s=60, particles=100)
    sweep["scenario"].pop("method_options")
    path = tmp_path / "wrong.yaml"
    path.write_text(yaml.safe_dump(sweep))
    out = tmp_path / "out"
    proc = cli("run", path, "--out", out, "--workers", 1, "-q", extra_path=plugin_dir, cwd=plugin_dir)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    runs = pd.read_parquet(out / "runs")
    bad = runs[runs["method"] != "tight-dvl"]
    assert (bad["status"] == "error").all() and bad["error"].str.contains(message, regex=False).all(), \
        bad["error"].tolist()
    assert (runs.loc[runs["method"] == "tight-dvl", "status"] == "ok").all()


def test_unknown_method_lists_the_known_ones(tmp_path):
    sweep = yaml.safe_load((ROOT / "examples" / "run_sweep.yaml").read_text())
    sweep["methods"] = ["tight-dvl", "magic"]
    sweep["scenario"].pop("method_options")
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(sweep))
    proc = cli("validate", path)
    assert proc.returncode == 2
    line = error_lines(proc.stderr)[0]
    assert "unknown method 'magic'" in line and "tight-dvl, tight-sbe, loose-dvl" in line


def test_methods_command_lists_every_builtin_with_its_options():
    proc = cli("methods", "--options")
    assert proc.returncode == 0, proc.stderr
    for name in ("tight-dvl", "tight-sbe", "loose-dvl"):
        assert name in proc.stdout
    assert "filter.*" in proc.stdout


def test_plugins_never_get_a_plotted_builtins_colour(plugin_dir, monkeypatch):
    """The docs' example record and the spare colours both drew a plug-in in pmf-dvl's solid green (found by a
    user's audit): a spare colour is one no plotted method's record takes, while any is left."""
    from tanbench.methods.registry import get
    from tanbench.plot import method_styles

    monkeypatch.syspath_prepend(str(plugin_dir))
    builtins = ["tight-dvl", "tight-sbe", "loose-dvl", "pmf-dvl", "pmf-sbe", "mpf-dvl", "ekf-dvl", "tercom-dvl"]
    styles = method_styles([*builtins, PF, DR, "no_such_module_xyz:run"])
    assert len({styles[m] for m in builtins} | {styles[PF], styles[DR], styles["no_such_module_xyz:run"]}) == 11
    assert styles[PF] == (get(PF).linestyle, get(PF).color)
    assert len({styles[m][1] for m in styles}) == 11  # every colour its own


def test_plot_says_which_plugins_it_cannot_style(two_ways, plugin_dir, tmp_path):
    """Plotted where the plug-ins cannot be imported, their lines fall back to spare colours: `plot` says so,
    one note per method (it said nothing, and a user's dashed purple method was drawn solid green; found by a
    user's audit); with the plug-ins importable, no note."""
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(two_ways["local"], out)
    lost = cli("plot", out, cwd=tmp_path)
    assert lost.returncode == 0, lost.stderr
    notes = [line for line in lost.stderr.splitlines() if line.startswith("note: method")]
    assert sorted(notes) == sorted(f"note: method {m} cannot be imported here: drawn in a spare colour, not its "
                                   f"record's style (put its package on PYTHONPATH)" for m in (DR, PF))
    found = cli("plot", out, extra_path=plugin_dir, cwd=tmp_path)
    assert found.returncode == 0 and "note: method" not in found.stderr, found.stderr
    (out / "sweep.yaml").unlink()  # --frontier draws from the runs alone, and still does (found by the review)
    frontier = cli("plot", out, "--frontier", cwd=tmp_path)
    assert frontier.returncode == 0 and frontier.stderr.count("note: method") == 2, frontier.stderr
