"""The first run explains itself: the plan's time model, the numba cache check, help text, figures per cell."""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest

from sweep_support import ROOT, cli
from tanbench.runner import engine
from tanbench.runner.sweep import load_sweep

COMMANDS = ["run", "plan", "validate", "tables", "simulate", "check", "plot", "report", "bench", "terrain stats"]


def test_plan_estimate_includes_compilation_and_the_load():
    """Cold cache: compilation + worker start + tasks + fixed; a loaded machine scales every part by its core share."""
    sweep = load_sweep(ROOT / "configs" / "quick.yaml")
    plan = engine.make_plan(sweep, Path("/nonexistent/results"), workers=2)
    tasks = sum(engine.task_cost(t) for t in plan.tasks)
    cores = engine.default_workers()
    workers = min(2, len(plan.tasks))
    idle = plan.estimate_parts(load=0.0, warm=False)
    share_one, share_all = min(1.0, cores / 1.0), min(1.0, cores / workers)
    assert idle["compile"] == pytest.approx(engine.COMPILE_S / share_one + engine.WARM_START_S / share_all)
    assert idle["tasks"] == pytest.approx(tasks / (workers * share_all))
    assert idle["fixed"] == pytest.approx(engine.FIXED_S / share_one)
    warm = plan.estimate_parts(load=0.0, warm=True)
    assert warm["compile"] == pytest.approx(engine.WARM_START_S / share_all)
    busy = plan.estimate_parts(load=8.0, warm=False)
    assert busy["tasks"] == pytest.approx(tasks / (workers * min(1.0, cores / (8.0 + workers))))
    assert busy["compile"] > idle["compile"] and busy["fixed"] > idle["fixed"]
    assert plan.estimate_seconds() == pytest.approx(sum(plan.estimate_parts().values()), rel=0.5)


def test_numba_cache_warm_only_when_every_index_is_newer_than_its_source(tmp_path, monkeypatch):
    """No index: cold; indexes newer than the sources: warm; a source edited after its index: cold."""
    sources = [tmp_path / "filters" / "tight.py", tmp_path / "navigation" / "ins.py", tmp_path / "filters" / "trig.py"]
    for src in sources:
        src.parent.mkdir(exist_ok=True)
        src.write_text("@njit(cache=True)\ndef f(): pass\n")
        os.utime(src, (1000, 1000))
    monkeypatch.setattr(engine, "jit_modules", lambda: tuple(sources))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    assert not engine.numba_cache_is_warm()
    for src in sources[:2]:  # trig.py's kernels are only called from other kernels: no index of its own
        index = src.parent / "__pycache__" / f"{src.stem}.f-1.py311.nbi"
        index.parent.mkdir(exist_ok=True)
        index.write_bytes(b"")
        os.utime(index, (2000, 2000))
    assert engine.numba_cache_is_warm()
    os.utime(sources[1], (3000, 3000))  # ins.py edited after it was compiled
    assert not engine.numba_cache_is_warm()


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
