"""The first run explains itself: the plan's time model, the numba cache check, help text, figures per cell."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from sweep_support import ROOT, cli
from tanbench import kernel_cache
from tanbench.runner import plan as planning
from tanbench.sweep import load_sweep

COMMANDS = ["run", "plan", "validate", "tables", "simulate", "check", "plot", "report", "bench", "terrain stats"]


def test_plan_estimate_includes_compilation_and_the_load():
    """Cold cache: compilation + worker start + tasks + fixed; a loaded machine scales every part by its core share."""
    sweep = load_sweep(ROOT / "configs" / "quick.yaml")
    plan = planning.make_plan(sweep, Path("/nonexistent/results"), workers=2)
    tasks = sum(plan.task_cost(t) for t in plan.tasks)
    cores = planning.default_workers()
    workers = min(2, len(plan.tasks))
    idle = plan.estimate_parts(load=0.0, warm=False)
    share_one, share_all = min(1.0, cores / 1.0), min(1.0, cores / workers)
    processes = planning.compile_processes(2)
    compile_s = planning.compile_seconds(sweep.spec.methods, sweep.spec.methods)
    assert compile_s == pytest.approx(planning.COMPILE_SHARED_S + planning.COMPILE_FAMILY_S["tight"]
                                      + planning.COMPILE_FAMILY_S["loose"])  # tight-sbe shares tight-dvl's kernels
    side = planning.compile_seconds(sweep.spec.methods, sweep.spec.methods, processes=processes)
    if processes > 1:  # tight's group and loose's side by side (loose without tight's kernels): the longer one
        assert side == pytest.approx(planning.COMPILE_SHARED_S + planning.COMPILE_JOIN_S + max(
            planning.COMPILE_FAMILY_S["tight"], planning.COMPILE_ALONE_S["loose"]))
    share_compile = min(1.0, cores / processes)
    assert idle["compile"] == pytest.approx(side / share_compile + planning.WARM_START_S / share_all)
    assert idle["tasks"] == pytest.approx(tasks / (workers * share_all))
    assert idle["fixed"] == pytest.approx(planning.FIXED_S / share_one)
    warm = plan.estimate_parts(load=0.0, warm=True)
    assert warm["compile"] == pytest.approx(planning.WARM_START_S / share_all)
    busy = plan.estimate_parts(load=8.0, warm=False)
    assert busy["tasks"] == pytest.approx(tasks / (workers * min(1.0, cores / (8.0 + workers))))
    assert busy["compile"] > idle["compile"] and busy["fixed"] > idle["fixed"]
    assert plan.estimate_seconds() == pytest.approx(sum(plan.estimate_parts().values()), rel=0.5)


def test_warm_up_compiles_and_marks_only_the_sweeps_methods(tmp_path, monkeypatch):
    """A sweep's warm-up runs its own built-in methods only and marks them warm; the plan's compile
    estimate then drops to nothing for them, and still counts the methods never warmed."""
    from tanbench.runner import executors

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    ran = []
    monkeypatch.setattr("tanbench.methods.run_method", lambda scenario, method, vehicle, seed: ran.append(method))
    monkeypatch.setattr("tanbench.simulation.simulate_vehicle", lambda scenario, seed: None)
    sweep_methods = ("tight-dvl", "loose-dvl", "my.module:run")
    assert planning.builtin_methods(sweep_methods) == ["tight-dvl", "loose-dvl"]
    assert kernel_cache.cold_methods(planning.builtin_methods(sweep_methods)) == ["tight-dvl", "loose-dvl"]
    executors.warm_up(None, sweep_methods)
    assert ran == ["tight-dvl", "loose-dvl"]
    assert kernel_cache.is_warm(["tight-dvl", "loose-dvl"]) and not kernel_cache.is_warm(["tight-dvl", "pmf-dvl"])
    assert planning.compile_seconds(sweep_methods) == 0.0
    assert planning.compile_seconds(("tight-dvl", "pmf-dvl")) == pytest.approx(
        planning.COMPILE_SHARED_S + planning.COMPILE_FAMILY_S["pmf"])


def test_compile_groups_split_whole_families_longest_first(tmp_path, monkeypatch):
    """Cold methods go to side-by-side compile groups by family (a family's methods share kernels),
    the longest family first, each to the least loaded group; the parent's group is the longest."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    methods = ("tight-dvl", "tight-sbe", "loose-dvl", "my.module:run")
    assert planning.compile_groups(methods, 1) == [["tight-dvl", "tight-sbe", "loose-dvl"]]
    # loose-dvl alone (45.0 s: it compiles the likelihood, resampling and random-number passes it shares with tight) is
    # the longer group, the parent's
    assert planning.compile_groups(methods, 2) == [["loose-dvl"], ["tight-dvl", "tight-sbe"]]
    assert planning.compile_groups(methods, 8) == [["loose-dvl"], ["tight-dvl", "tight-sbe"]]
    five = ("tight-dvl", "loose-dvl", "pmf-dvl", "mpf-dvl", "ekf-dvl")  # 41.6, 23.5 (45.0 alone), 13.5, 7.5, 8.4 s
    groups = planning.compile_groups(five, 2)  # loose alone 45.0 + 8.4 + 7.5 = 60.9 s against 41.6 + 13.5 = 55.1 s
    assert groups == [["loose-dvl", "ekf-dvl", "mpf-dvl"], ["tight-dvl", "pmf-dvl"]]
    assert planning.compile_groups(methods, 2, cold=[]) == []
    assert planning.compile_seconds(methods, cold=[], processes=2) == 0.0
    busy = planning.compile_seconds(five, five, processes=2)
    assert busy == pytest.approx(planning.COMPILE_SHARED_S + planning.COMPILE_JOIN_S + planning.COMPILE_ALONE_S["loose"]
                                 + sum(planning.COMPILE_FAMILY_S[f] for f in ("ekf", "mpf")))
    assert planning.group_compile_s({"tight", "loose"}) == pytest.approx(  # loose after tight reuses its kernels
        planning.COMPILE_FAMILY_S["tight"] + planning.COMPILE_FAMILY_S["loose"])


def test_share_of_each_compiling_process(monkeypatch):
    """From the share one process gets now, the share each of k busy processes will get: the other
    load the first implies, shared with k of ours."""
    monkeypatch.setattr(planning, "default_workers", lambda: 2)
    assert planning.share_of_each(2, 1.0) == 1.0
    assert planning.share_of_each(2, 0.9999) == 1.0  # an idle core's probe reads a hair below 1
    assert planning.share_of_each(1, 0.5) == pytest.approx(0.5)
    assert planning.share_of_each(2, 0.5) == pytest.approx(2 / 5)  # 3 others + 2 of ours on 2 cores
    assert planning.share_of_each(3, 1.0) == pytest.approx(2 / 3)


def test_side_by_side_warm_up_of_one_group_stays_in_this_process(monkeypatch):
    """One group (or one process): the warm-up runs here, once, on every method; no helper starts."""
    from tanbench.runner import executors

    calls = []
    monkeypatch.setattr(executors, "warm_up", lambda scenario_json, methods: calls.append((scenario_json, methods)))
    monkeypatch.setattr(executors.multiprocessing, "get_context",
                        lambda *a: pytest.fail("no helper process for one group"))
    executors.warm_up_side_by_side("{}", [["tight-dvl", "tight-sbe"]])
    executors.warm_up_side_by_side("{}", [])
    assert calls == [("{}", ("tight-dvl", "tight-sbe")), ("{}", ())]


def test_kernel_cache_warm_only_with_the_main_kernels_of_these_sources(tmp_path, monkeypatch):
    """The cache is warm when the directory named by today's kernel sources holds the main filter
    module's index; another version's directory, or the old cache beside the sources, does not count.
    (``plan``'s estimate and ``run``'s compile message both ask :func:`kernel_cache.is_warm`.)"""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert kernel_cache.cache_dir().parent == tmp_path
    assert not kernel_cache.is_warm()
    other = tmp_path / f"{kernel_cache.PREFIX}{'0' * 16}" / "x" / "filters"
    other.mkdir(parents=True)
    (other / "tight.tight_filter_loop-1.py311.nbi").write_bytes(b"")
    assert not kernel_cache.is_warm()
    mine = kernel_cache.cache_dir() / "x" / "filters"
    mine.mkdir(parents=True)
    (mine / "resample.exp_weights-1.py311.nbi").write_bytes(b"")
    assert not kernel_cache.is_warm()
    (mine / "tight.tight_filter_loop-1.py311.nbi").write_bytes(b"")
    assert kernel_cache.is_warm()
    # a child process handed this directory as NUMBA_CACHE_DIR takes its parent as the user's
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(kernel_cache.cache_dir()))
    assert kernel_cache.cache_parent() == tmp_path


@pytest.mark.parametrize("command", COMMANDS)
def test_help_text_is_plain(command):
    """--help: no '<bool>' metavars on flags, no stray space before a full stop, defaults shown."""
    proc = cli(*command.split(), "--help")
    assert proc.returncode == 0, proc.stderr
    assert "<bool>" not in proc.stdout
    assert not re.search(r"\w \.(\s|$)", proc.stdout), proc.stdout
    if command in ("run", "plan"):
        assert "Results directory [default: results/<name>]" in proc.stdout
        flat = " ".join(proc.stdout.split())
        assert re.search(r"--workers <int range> [^-]*\[default: the cores available\]", flat), proc.stdout
        assert re.search(r"--runs <int range> Override the sweep's runs per cell", flat), proc.stdout


def test_plot_reaches_every_cell_and_titles_name_it(tmp_path, monkeypatch):
    """`plot --cell all` draws a figure set per cell; every figure's title names its cell id."""
    pytest.importorskip("matplotlib")
    from tanbench import plot

    out = tmp_path / "ci"
    shutil.copytree(ROOT / "results" / "ci-baseline", out, ignore=shutil.ignore_patterns(".work"))
    sweep = load_sweep(out / "sweep.yaml")
    titles = {}
    real_save = plot._save

    def recording_save(fig, path, plt):
        texts = [ax.get_title() for ax in fig.axes] + ([fig._suptitle.get_text()] if fig._suptitle else [])
        titles[Path(path).name] = " ".join(texts)
        return real_save(fig, path, plt)

    monkeypatch.setattr(plot, "_save", recording_save)
    written = plot.plot_results(out, ["all"])
    assert {p.name for p in written} == set(titles)
    for cell in sweep.cells:
        own = [name for name in titles if cell.cell_id in name]
        default = cell.cell_id == plot.representative_cells(sweep)[0].cell_id
        kinds = ("east", "north", "horizontal", "heading", "bound_nees")  # bound_nees: runs carry the PCRB
        figures = [f"A_{k}.png" for k in kinds] if default else own
        assert len([f for f in figures if f.startswith("A_")]) == len(kinds), titles
        for name in figures:
            assert f"cell {cell.cell_id}" in titles[name], (name, titles[name])
    tracks = [name for name in titles if name.startswith("tracks")]
    assert tracks and all("cell" in titles[name] for name in tracks)
    only = plot.plot_results(out, [sweep.cells[2].cell_id[:6]])
    assert {p.name for p in only} >= {f"A_{sweep.cells[2].cell_id}_east.png"}


def test_cold_warm_up_covers_every_filter_variant_of_the_sweep(monkeypatch):
    """A sweep whose cells set different filter options (e.g. the Euler step, which compiles the tight
    loop once more) warms one cell per distinct filter block before the workers start, in order, the
    first side by side; cells that differ elsewhere (here the particles) add nothing."""
    import json

    from tanbench.runner import engine
    from tanbench.runner.tasks import Task

    def task(filter_block, particles):
        spec = {"particles": particles, "filter": filter_block}
        return Task("c", json.dumps(spec), 0, ("tight-dvl",), 1, False)

    euler = {"propagation": "euler-last-second"}
    todo = [task({}, 100), task({}, 200), task(euler, 100), task(euler, 300)]
    assert engine.filter_variants(todo) == [todo[0].scenario_json, todo[2].scenario_json]

    calls = []
    monkeypatch.setattr(engine.kernel_cache, "is_warm", lambda methods: False)
    monkeypatch.setattr(engine, "compile_groups", lambda methods, processes: [list(methods)])
    monkeypatch.setattr(engine, "compile_seconds", lambda methods, processes: 1.0)
    monkeypatch.setattr(engine, "warm_up_side_by_side", lambda s, groups, maps: calls.append(("side", s)))
    monkeypatch.setattr(engine, "warm_up", lambda s, methods: calls.append(("here", s, tuple(methods))))

    class Spec:
        methods = ("tight-dvl",)

    class FakePlan:
        workers = 1
        sweep = type("Sweep", (), {"spec": Spec})()

    engine.compile_kernels(FakePlan(), todo, False, print)
    assert calls == [("side", todo[0].scenario_json), ("here", todo[2].scenario_json, ("tight-dvl",))]
