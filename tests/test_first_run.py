"""The first run explains itself: the plan's time model, the numba cache check, help text, figures per cell."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from sweep_support import ROOT, cli, cli_env
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
    if processes > 1:  # tight's group and loose's side by side (loose without tight's kernels), staged
        # (runner/compile_stages.py): each compiles half of what the two share, and half the simulation's kernels
        half = planning.shared_compile_s("loose") / 2
        assert half == pytest.approx((planning.COMPILE_ALONE_S["loose"] - planning.COMPILE_FAMILY_S["loose"]) / 2)
        assert side == pytest.approx(planning.COMPILE_SHARED_S / 2 + planning.COMPILE_JOIN_S + max(
            planning.COMPILE_FAMILY_S["tight"] - half, planning.COMPILE_ALONE_S["loose"] - half))
    share_compile = min(1.0, cores / processes)
    speed = planning.machine_speed_factor()  # this machine's core against the constants' (measured once)
    assert idle["compile"] == pytest.approx(side * speed / share_compile + planning.worker_start_s() / share_all)
    assert idle["tasks"] == pytest.approx(tasks / (workers * share_all))
    assert idle["fixed"] == pytest.approx(planning.FIXED_S / share_one)
    warm = plan.estimate_parts(load=0.0, warm=True)
    assert warm["compile"] == pytest.approx(planning.worker_start_s() / share_all)
    busy = plan.estimate_parts(load=8.0, warm=False)
    assert busy["tasks"] == pytest.approx(tasks / (workers * min(1.0, cores / (8.0 + workers))))
    assert busy["compile"] > idle["compile"] and busy["fixed"] > idle["fixed"]
    assert plan.estimate_seconds() == pytest.approx(sum(plan.estimate_parts().values()), rel=0.5)


def test_a_spawned_worker_is_counted_with_its_imports(monkeypatch):
    """Workers are forked on Linux (their imports done) and spawned elsewhere (executors.local_context): the
    estimate's worker start follows."""
    sweep = load_sweep(ROOT / "configs" / "quick.yaml")
    plan = planning.make_plan(sweep, Path("/nonexistent/results"), workers=2)
    monkeypatch.setattr(planning.sys, "platform", "linux")
    forked = plan.estimate_parts(load=0.0, warm=True)["compile"]
    monkeypatch.setattr(planning.sys, "platform", "darwin")
    spawned = plan.estimate_parts(load=0.0, warm=True)["compile"]
    share_all = min(1.0, planning.default_workers() / min(2, len(plan.tasks)))
    assert forked == pytest.approx(planning.WARM_START_S / share_all)
    assert spawned == pytest.approx(planning.SPAWN_START_S / share_all) and spawned > forked


def test_the_compile_estimate_follows_the_machine_speed(monkeypatch):
    """The compile part of the estimate is the constants times the machine-speed factor (docs/speed.md,
    seventh session): a core twice as slow doubles it, nothing else moves; the factor is measured once per
    process and kept within [0.25, 4]."""
    factor = planning.machine_speed_factor()
    assert 0.25 <= factor <= 4.0 and planning.machine_speed_factor() == factor
    sweep = load_sweep(ROOT / "configs" / "quick.yaml")
    plan = planning.make_plan(sweep, Path("/nonexistent/results"), workers=2)
    monkeypatch.setattr(planning, "machine_speed_factor", lambda: 1.0)
    one = plan.estimate_parts(load=0.0, warm=False)
    monkeypatch.setattr(planning, "machine_speed_factor", lambda: 2.0)
    two = plan.estimate_parts(load=0.0, warm=False)
    start = planning.WARM_START_S / min(1.0, planning.default_workers() / min(2, len(plan.tasks)))
    assert two["compile"] - start == pytest.approx(2 * (one["compile"] - start))
    assert (two["tasks"], two["fixed"]) == (one["tasks"], one["fixed"])
    assert plan.estimate_parts(load=0.0, warm=True)["compile"] == pytest.approx(start)  # nothing to compile


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
    # loose-dvl alone (64.4 s: it compiles the likelihood, resampling and random-number passes it shares with tight) is
    # the longer group, the parent's
    assert planning.compile_groups(methods, 2) == [["loose-dvl"], ["tight-dvl", "tight-sbe"]]
    assert planning.compile_groups(methods, 8) == [["loose-dvl"], ["tight-dvl", "tight-sbe"]]
    five = ("tight-dvl", "loose-dvl", "pmf-dvl", "mpf-dvl", "ekf-dvl")  # 63.3, 29.6 (64.4 alone), 31.8, 24.3, 16.2 s
    # with today's constants: tight + loose (63.3 + 29.6 = 92.9 s: loose after tight reuses its kernels) and
    # pmf + mpf + ekf (31.8 + 24.3 + 16.2 = 72.3 s)
    groups = planning.compile_groups(five, 2)
    assert sorted(m for g in groups for m in g) == sorted(five) and len(groups) == 2
    assert all(len({planning.family_of(m) for m in g}) == len(g) for g in groups)  # whole families, one each here
    costs = [planning.group_compile_s({planning.family_of(m) for m in g}) for g in groups]
    assert costs[0] == max(costs)  # the parent's group is the longest
    assert groups == [["tight-dvl", "loose-dvl"], ["pmf-dvl", "mpf-dvl", "ekf-dvl"]]  # with today's constants
    assert planning.compile_groups(methods, 2, cold=[]) == []
    assert planning.compile_seconds(methods, cold=[], processes=2) == 0.0
    busy = planning.compile_seconds(five, five, processes=2)
    assert busy == pytest.approx(planning.COMPILE_SHARED_S + planning.COMPILE_JOIN_S + max(costs))
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
    # measured other load wins over the one the share implies: one busy process beside a whole-core probe
    assert planning.share_of_each(2, 1.0, others=1.0) == pytest.approx(2 / 3)
    assert planning.share_of_each(2, 0.5, others=0.0) == 1.0


def test_the_load_probe_reads_proc_stat(monkeypatch, tmp_path):
    """``busy_jiffies`` counts user, system, interrupts and steal as busy and niced time as free; the probe
    returns its share and the other busy cores, or None for them where /proc/stat cannot be read."""
    stat = tmp_path / "stat"
    stat.write_text("cpu  100 50 20 800 10 5 5 10 0 0\ncpu0 1 2 3\n")
    real_path = planning.Path
    monkeypatch.setattr(planning, "Path", lambda p: stat if p == "/proc/stat" else real_path(p))
    assert planning.busy_jiffies() == (100 + 20 + 5 + 5 + 10, 100 + 20 + 5 + 5 + 10 + 50 + 800 + 10)
    share, others = planning.cpu_load_now(0.02)
    assert 0.0 < share <= 1.0 and others is None  # the same ticks before and after: no interval to read
    monkeypatch.setattr(planning, "Path", lambda p: tmp_path / "missing" if p == "/proc/stat" else real_path(p))
    assert planning.busy_jiffies() is None


def test_the_load_is_the_least_any_probe_saw(monkeypatch):
    """A burst that one probe sees and the others do not is not load: the largest share and the fewest other
    busy cores of the probes; without /proc/stat, None for the cores."""
    readings = iter([(0.55, 1.2), (1.0, 0.04), (0.9, 0.0)])
    monkeypatch.setattr(planning, "cpu_load_probe", lambda probe_s: next(readings))
    monkeypatch.setattr(planning, "LOAD_PROBE_GAP_S", 0.0)
    assert planning.cpu_load_now() == (1.0, 0.0)
    readings = iter([(0.5, None), (0.4, None)])
    assert planning.cpu_load_now(probes=2) == (0.5, None)
    readings = iter([(0.5, 1.0), (0.5, 1.0), (0.5, 1.0)])  # load that lasts
    assert planning.cpu_load_now() == (0.5, 1.0)


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


def test_python_dash_m_tanbench_is_the_cli():
    """`python -m tanbench` runs the console script's app (it had no __main__ module)."""
    proc = subprocess.run([sys.executable, "-m", "tanbench", "--version"], capture_output=True, text=True,
                          env=cli_env(), cwd=ROOT, timeout=120)
    assert proc.returncode == 0 and proc.stdout.startswith("tanbench "), proc.stderr


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


EULER = {"propagation": "euler-last-second"}
SHARED = {"tight_regularisation": "shared"}


def _variant_task(filter_block, particles=100, methods=("tight-dvl",)):
    import json

    from tanbench.runner.tasks import Task

    return Task("c", json.dumps({"particles": particles, "filter": filter_block}), 0, methods, 1, False)


def _compile_plan(methods=("tight-dvl",), workers=1):
    class Spec:
        pass

    Spec.methods = methods

    class FakePlan:
        pass

    FakePlan.workers = workers
    FakePlan.sweep = type("Sweep", (), {"spec": Spec})()
    return FakePlan()


def _record_warm_ups(monkeypatch, engine):
    calls = []
    monkeypatch.setattr(engine, "cpu_load_now", lambda: (1.0, 0.0))
    monkeypatch.setattr(engine, "warm_up_side_by_side", lambda s, groups, maps: calls.append(("side", s, groups)))
    monkeypatch.setattr(engine, "warm_up", lambda s, methods: calls.append(("here", s, tuple(methods))))
    return calls


def test_cold_warm_up_covers_every_filter_variant_of_the_sweep(tmp_path, monkeypatch):
    """A sweep whose cells set different filter options (e.g. the Euler step, which compiles the tight
    loop once more) warms one cell per distinct filter block before the workers start, in order, the
    first side by side; cells that differ elsewhere (here the particles) add nothing."""
    from tanbench.runner import engine

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))  # an empty cache: every kernel cold
    todo = [_variant_task({}, 100), _variant_task({}, 200), _variant_task(EULER, 100), _variant_task(EULER, 300)]
    assert engine.filter_variants(todo) == [todo[0].scenario_json, todo[2].scenario_json]
    calls = _record_warm_ups(monkeypatch, engine)
    engine.compile_kernels(_compile_plan(), todo, False, print)
    assert calls == [("side", todo[0].scenario_json, [["tight-dvl"]]), ("here", todo[2].scenario_json, ("tight-dvl",))]


def test_kernel_variant_is_what_the_tight_loop_compiles(monkeypatch):
    """A cell's kernel variant names the options that give the jitted tight loop other argument types:
    the Euler inputs and the shared resampling bundle that ``tight_filter_loop`` passes instead of None
    (captured here from the function itself), and numpy's random numbers (tight and loose)."""
    from types import SimpleNamespace

    from tanbench.config import Scenario
    from tanbench.filters import tight

    seen = []
    monkeypatch.setattr(tight, "_tight_loop", lambda *args: seen.append((args[-3] is not None, args[-2] is not None)))
    nmap = SimpleNamespace(e0=0.0, e_max=1.0, n0=0.0, n_max=1.0)
    cases = [("", {}), ("euler", EULER), ("shared-resampling", SHARED), ("euler+shared-resampling", {**EULER, **SHARED}),
             ("shared-resampling", {"regularisation": "none"}),  # no jitter: the shared kernel's switch
             ("numpy-rng", {"random_numbers": "numpy"}), ("numpy-rng+euler", {**EULER, "random_numbers": "numpy"})]
    for variant, block in cases:
        scenario = Scenario(filter=block)
        settings = tight.tight_settings(scenario, nmap)
        tight.tight_filter_loop(None, None, tight.TightTrack(*[None] * 5, "euler inputs"), None, None, None, settings,
                                None)
        assert planning.kernel_variant("tight-dvl", scenario) == variant
        assert planning.kernel_variant("tight-sbe", scenario) == variant
        assert seen[-1] == ("euler" in variant, "shared" in variant)
        assert planning.kernel_variant("loose-dvl", scenario) == ("numpy-rng" if "numpy" in variant else "")
        assert planning.kernel_variant("pmf-dvl", scenario) == ""
        assert planning.cell_kernels(scenario, ("tight-dvl", "pmf-dvl", "my.module:run")) == [
            kernel_cache.kernel_name("tight-dvl", variant), "pmf-dvl"]
    assert len(seen) == len(cases)


LOOSE_KALMAN = {"loose_heading_offsets": False, "loose_bias_gate_sigma": None, "loose_fix_shape": None,
                "loose_fix_prior_gate": None, "loose_fix_fit_one_wild_beam": False,
                "loose_reopen_heading": "navigation", "loose_reopen_position": "prior",
                "loose_fix_correlation_s": 0.0}


def test_kernel_variant_is_the_loop_loose_dvl_runs(monkeypatch):
    """loose-dvl's kernel variant names the jitted loop it runs (each compiles on its first use): none for
    the default's (the Kalman feedback with heading offsets), ``loose-kalman`` without the offsets,
    ``loose-fix-only`` for the paper's architecture; the loop that runs is caught here."""
    import numpy as np

    from tanbench.config import Scenario
    from tanbench.methods import loose, method_context
    from tanbench.simulation import simulate_vehicle

    class Ran(Exception):
        pass

    for name in ("loose_filter_loop", "loose_kalman_loop", "loose_turned_loop"):
        monkeypatch.setattr(loose, name, lambda *args, name=name: (_ for _ in ()).throw(Ran(name)))
    vehicle = simulate_vehicle(Scenario(duration_s=30.0), np.random.SeedSequence(3))
    cases = [("", {}, "loose_turned_loop"), ("loose-kalman", LOOSE_KALMAN, "loose_kalman_loop"),
             ("loose-fix-only", {"loose_architecture": "fix-only"}, "loose_filter_loop"),
             ("numpy-rng+loose-fix-only", {"loose_architecture": "fix-only", "random_numbers": "numpy"},
              "loose_filter_loop")]
    for variant, block, loop in cases:
        scenario = Scenario(duration_s=30.0, filter=block)
        with pytest.raises(Ran) as ran:
            loose.run_loose_dvl(method_context(scenario, "loose-dvl", vehicle, np.random.SeedSequence(1)))
        assert str(ran.value) == loop
        assert planning.kernel_variant("loose-dvl", scenario) == variant
        assert planning.kernel_variant("tight-dvl", scenario) == ("numpy-rng" if "numpy" in variant else "")


def test_the_estimate_counts_each_variant_a_sweep_compiles(tmp_path, monkeypatch):
    """The compile estimate counts the families compiled from nothing (the first variant of each) plus
    each other (family, variant) pair once (tight-dvl and tight-sbe share theirs), in the parent."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    tight = planning.COMPILE_SHARED_S + planning.COMPILE_FAMILY_S["tight"]
    euler = planning.COMPILE_LOOP_S + planning.COMPILE_OPTION_S["euler"]
    mixed = ["tight-dvl", "tight-dvl+euler"]
    assert planning.compile_groups(mixed, 2, cold=mixed) == [["tight-dvl"]]
    assert planning.compile_seconds(mixed, cold=mixed) == pytest.approx(tight + euler)
    both = ["tight-dvl", "tight-sbe", "tight-dvl+euler", "tight-sbe+euler"]
    assert planning.compile_seconds(both, cold=both, processes=2) == pytest.approx(tight + euler)
    # the first cell in the Euler step: the family compiles in it, the default loop after
    assert planning.compile_seconds(mixed[::-1], cold=mixed) == pytest.approx(tight + planning.COMPILE_LOOP_S)
    combined = ["tight-dvl", "tight-dvl+euler+shared-resampling", "loose-dvl+numpy-rng"]
    assert planning.compile_seconds(combined, cold=combined, processes=1) == pytest.approx(
        tight + planning.COMPILE_FAMILY_S["loose"] + euler + planning.COMPILE_OPTION_S["shared-resampling"])
    assert planning.variant_seconds("euler+made-up") == pytest.approx(euler + planning.COMPILE_OTHER_OPTION_S)
    # a plan of a sweep whose two cells differ in filter.propagation: its kernels and its estimate
    sweep_file = tmp_path / "mixed.yaml"
    sweep_file.write_text("name: mixed\nseed: 5\nruns: 2\nmethods: [tight-dvl]\nscenario: {particles: 200}\n"
                          "tables:\n  prop: {filter.propagation: [exact, euler-last-second]}\n")
    plan = planning.make_plan(load_sweep(sweep_file), tmp_path / "out", workers=1)
    assert plan.kernels() == mixed
    assert plan.kernels(plan.tasks[:1]) == ["tight-dvl"]
    monkeypatch.setattr(planning, "default_workers", lambda: 2)
    idle = plan.estimate_parts(load=0.0, warm=False)
    assert idle["compile"] == pytest.approx((tight + euler) * planning.machine_speed_factor() + planning.WARM_START_S)
    assert plan.estimate_parts(load=0.0)["compile"] == pytest.approx(idle["compile"])  # the empty cache: all cold


def test_a_warm_cache_with_a_new_variant_warms_only_that_variant(tmp_path, monkeypatch):
    """A cache marked warm for the defaults (e.g. after configs/quick.yaml) is cold for a cell's new
    variant and warm for the rest: the estimate counts that variant only, and the run warms it up in
    the parent (no side-by-side helpers) before the workers start; marked warm, nothing more."""
    from tanbench.runner import engine, executors

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    kernel_cache.mark_warm(["tight-dvl", "tight-sbe", "loose-dvl"])
    kernels = ["tight-dvl", "loose-dvl", "tight-dvl+euler", "loose-dvl"]
    assert kernel_cache.cold_methods(kernels) == ["tight-dvl+euler"]
    assert kernel_cache.warm_kernels() == ["loose-dvl", "tight-dvl", "tight-sbe"]
    assert planning.compile_groups(kernels, 2) == []
    assert planning.compile_seconds(kernels, processes=2) == pytest.approx(  # after loading the cached family
        planning.COMPILE_LOAD_S + planning.COMPILE_LOOP_S + planning.COMPILE_OPTION_S["euler"])
    methods = ("tight-dvl", "loose-dvl")
    todo = [_variant_task({}, methods=methods), _variant_task(EULER, methods=methods)]
    calls = _record_warm_ups(monkeypatch, engine)
    engine.compile_kernels(_compile_plan(methods, workers=2), todo, False, print)
    assert calls == [("here", todo[1].scenario_json, ("tight-dvl",))]
    # the warm-up marks each method in the cell's variant
    monkeypatch.setattr("tanbench.methods.run_method", lambda scenario, method, vehicle, seed: None)
    monkeypatch.setattr("tanbench.simulation.simulate_vehicle", lambda scenario, seed: None)
    executors.warm_up(todo[1].scenario_json, methods)
    assert kernel_cache.warm_kernels() == ["loose-dvl", "tight-dvl", "tight-dvl+euler", "tight-sbe"]
    assert planning.compile_seconds(kernels, processes=2) == 0.0
    calls.clear()
    engine.compile_kernels(_compile_plan(methods, workers=2), todo, False, print)
    assert calls == []




ONE_SIGNATURE_KERNELS = {  # kernels the simulation and every method's inputs call from Python wrappers
    "tanbench.terrain.grid": "bilinear_many", "tanbench.sensors.raycast": "cast_rays",
    "tanbench.navigation.increments": "interval_increments",
    "tanbench.terrain.representation": "representation_variance",
}


def test_the_warm_up_compiles_one_signature_per_wrapped_kernel():
    """numba compiles a kernel once per argument type, and read-only is part of an array's type: the
    wrappers hand these kernels read-only inputs (tanbench.arrays.read_only) whether the caller's arrays
    were a method's read-only views or fresh ones, so warming up the CI sweep's three methods (which also
    simulates the run and builds the maps) asks each for one signature, in a process of its own. (Kernels
    only jitted code calls, such as the likelihood pass, are not counted: a caller loaded from the cache
    leaves their dispatchers empty.)"""
    import json
    import subprocess
    import sys

    code = ("import importlib, json\n"
            "from tanbench.runner.executors import warm_up\n"
            "warm_up(None, ('tight-dvl', 'tight-sbe', 'loose-dvl'))\n"
            f"kernels = {ONE_SIGNATURE_KERNELS!r}\n"
            "print(json.dumps({m + '.' + k: len(getattr(importlib.import_module(m), k).signatures)"
            " for m, k in kernels.items()}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    counts = json.loads(out.stdout.strip().splitlines()[-1])
    assert counts == {f"{m}.{k}": 1 for m, k in ONE_SIGNATURE_KERNELS.items()}


THIN_FILL_WRAPPERS = {"tanbench.filters.rng.fill_normals", "tanbench.filters.rng.fill_uniforms"}
# kernels the tight and the loose loop call with types of their own (not shared, so not in the table): the
# estimate's angle row is a literal (5 or -1, which prunes the circular mean from the loose loop), and the
# loose loop hands keep_on_map a strided row of its cloud (0.2 s)
PER_FAMILY_SIGNATURES = {"tanbench.filters.estimate.weighted_estimate", "tanbench.filters.tight.keep_on_map"}


def test_a_cold_staged_warm_up_compiles_each_jitted_kernel_once(tmp_path):
    """On an empty cache, both shares of the compile-stages table (each process's part of the kernels the
    tight and loose families share, tanbench.runner.compile_stages), then tight-dvl, tight-sbe and
    loose-dvl warmed up in one process: every kernel they reach, jitted callees included, compiles one
    signature. So the table's argument types are the ones the methods pass (a stale entry would compile a
    second signature), and no caller passes a literal 0 or 1 where the others pass a run-time integer (that
    compiled the whole likelihood pass a second time, about 5 s of the first run, found 4 December). The
    random-number fills' two-line wrappers are allowed one signature per array rank; what they call
    compiles once."""
    import json
    import os
    import subprocess
    import sys

    code = ("import gc, json\n"
            "from numba.core.registry import CPUDispatcher\n"
            "from tanbench.runner import compile_stages\n"
            "from tanbench.runner.executors import warm_up\n"
            "table = compile_stages.load_table()['shares']\n"
            "skipped = [compile_stages.compile_share(share)[1] for share in table.values()]\n"
            "warm_up(None, ('tight-dvl', 'tight-sbe', 'loose-dvl'))\n"
            "print(json.dumps({'skipped': skipped, 'counts': {f'{d.py_func.__module__}.{d.py_func.__qualname__}':"
            " len(d.signatures) for d in gc.get_objects() if isinstance(d, CPUDispatcher)"
            " and d.py_func.__module__.startswith('tanbench')}}))\n")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT, env=env)
    found = json.loads(out.stdout.strip().splitlines()[-1])
    counts = found["counts"]
    assert found["skipped"] == [[], []]
    assert counts["tanbench.filters.likelihood.loglik_tight_pass"] == 1  # compiled here, not loaded
    assert {k: n for k, n in counts.items() if n > 1 and k not in THIN_FILL_WRAPPERS | PER_FAMILY_SIGNATURES} == {}
    assert all(counts[k] == 2 for k in PER_FAMILY_SIGNATURES)


def test_a_sweep_of_other_kernel_variants_is_not_charged_a_staged_compile():
    """runner/compile_stages.py stages only the default kernel variants (the table's argument types):
    configs/ci-numpy.yaml (numpy's random numbers) compiles side by side unstaged, and the plan charges it so:
    loose alone, the whole simulation; configs/quick.yaml's default variants are staged and cost less."""
    numpy_kernels = planning.make_plan(load_sweep(ROOT / "configs" / "ci-numpy.yaml"), Path("/nonexistent"),
                                       workers=2).kernels()
    default_kernels = planning.make_plan(load_sweep(ROOT / "configs" / "quick.yaml"), Path("/nonexistent"),
                                         workers=2).kernels()
    groups = planning.compile_groups(numpy_kernels, 2, numpy_kernels)
    assert len(groups) == 2 and not planning.staged_groups(groups, numpy_kernels)
    assert planning.staged_groups(planning.compile_groups(default_kernels, 2, default_kernels), default_kernels)
    unstaged = planning.compile_seconds(numpy_kernels, numpy_kernels, processes=2)
    assert unstaged == pytest.approx(planning.COMPILE_SHARED_S + planning.COMPILE_JOIN_S + max(
        planning.COMPILE_FAMILY_S["tight"], planning.COMPILE_ALONE_S["loose"]))
    assert planning.compile_seconds(default_kernels, default_kernels, processes=2) < unstaged


@pytest.mark.parametrize("sweep_file", sorted(p.name for p in (ROOT / "configs").glob("*.yaml")))
def test_the_plan_charges_a_staged_compile_exactly_where_run_stages_one(sweep_file):
    """The plan's estimate counts a staged side-by-side compile (plan.staged_groups) where run stages one: the shares
    compile_stages.shares_for gives the groups for the first cell run warms up on (engine.filter_variants)."""
    import json

    from tanbench.config import Scenario
    from tanbench.errors import TanbenchError
    from tanbench.runner.compile_stages import shares_for
    from tanbench.runner.engine import filter_variants

    try:
        sweep = load_sweep(ROOT / "configs" / sweep_file)
    except TanbenchError as exc:  # a sweep over ../shared's maps, where they are not beside the clone
        pytest.skip(str(exc))
    plan = planning.make_plan(sweep, Path("/nonexistent/results"), workers=2)
    kernels = plan.kernels()
    groups = planning.compile_groups(kernels, 2, kernels)
    first = Scenario(**json.loads(filter_variants(plan.todo)[0]))
    assert planning.staged_groups(groups, kernels) == (len(groups) > 1 and any(shares_for(groups, first)))
