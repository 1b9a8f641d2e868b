"""The regression check's own regression test: a mutation suite (issue 22).

Each degradation of tests/mutation_support.py (an option or a world fault: map offset,
sonar latency, unmodelled range noise, a fraction of runs started far off, fewer particles,
regularisation switched off) is run through a small design with the CI check's statistics
(paired runs, two-part outcome, permutation and exact tests, Holm) and must be flagged
(some row regressed); reseeds of the unmodified code (the filters' random numbers, the
sweep's seed) must not be. The design is smaller than configs/ci.yaml to keep the cost
down (tight-dvl, one cell, 40 runs of 400 s); docs/results.md ("Mutation suite") gives
the effects measured.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from mutation_support import MUTATIONS, NULLS, sweep_text
from tanbench.check import CheckOptions, compare
from tanbench.runner.engine import run_sweep
from tanbench.sweep import parse_sweep

OPTIONS = dict(margin_rel=0.10, margin_abs=0.0)


def _run(text: str, out: Path) -> Path:
    report = run_sweep(parse_sweep(text, "mutation.yaml"), out, workers=1, series="none", progress=False,
                       echo=lambda *_: None, note=lambda *_: None)
    assert not report.failed_rows
    return out


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    return _run(sweep_text(), tmp_path_factory.mktemp("mutation-base") / "base")


@pytest.mark.parametrize("name", list(MUTATIONS))
def test_every_mutation_is_flagged(name, base, tmp_path):
    extra, ignore = MUTATIONS[name]
    result = compare(_run(sweep_text(extra), tmp_path / "new"), base, CheckOptions(ignore=ignore, **OPTIONS))
    t = result.table
    assert result.regressed, f"{name} not flagged:\n{t[['metric', 'change', 'margin', 'p_worse_holm', 'verdict']]}"
    flagged = t[t["verdict"] == "regressed"]
    assert (flagged["change"] > flagged["margin"]).all()


@pytest.mark.parametrize("name", [*NULLS, "sweep reseeded"])
def test_reseeds_are_not_flagged(name, base, tmp_path):
    extra, ignore = NULLS.get(name, ("", ()))
    text = sweep_text(extra, seed=3333 if name == "sweep reseeded" else None)
    result = compare(_run(text, tmp_path / "new"), base, CheckOptions(ignore=ignore, **OPTIONS))
    assert not result.regressed, result.table[["metric", "change", "p_worse_holm", "verdict"]]
    assert not (result.table["verdict"] == "improved").any()
