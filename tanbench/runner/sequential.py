"""``tanbench check --until-decisive``: add runs in seeded batches until every row is decided.

Both directories are extended with their own stored sweep (``DIR/sweep.yaml``) to the same
number of runs per cell (a sweep's runs 0..n-1 have fixed seeds, so the runs added are the
same whoever adds them and whenever: the stopping point is deterministic). The looks are
planned before the first one: n0 (the runs both directories already hold, at least
``batch``), n0 + batch, ..., ``cap``; K looks in all. Each look runs the whole check at
level alpha / K (alpha spent evenly over the planned looks: the chance of a false verdict
at any look is at most the sum of the looks' levels, whatever the data make the procedure
stop at, so the error rate holds under this optional stopping). It stops at the first look
where every decisive row is regressed, improved, or shown equivalent (its change is below
its margin at the look's level; lost runs: the upper bound of the rate of newly lost runs
below ``lost_detect``), else at the cap.
"""

from __future__ import annotations

from pathlib import Path

from tanbench import store
from tanbench.check import CheckOptions, CheckResult, compare, looks, spend
from tanbench.errors import TanbenchError
from tanbench.results import load
from tanbench.runner.engine import run_sweep
from tanbench.runner.resume import ResumeState
from tanbench.sweep import load_sweep


def _stored_runs(directory: Path) -> int:
    runs = load(directory)
    return int(runs.groupby(["cell_id", "method"])["run"].nunique().min())


def _check_extendable(sweep, directory: Path) -> None:
    """Refuse to extend a directory whose stored runs another code made: the runs added would be this code's,
    and a baseline would silently become the new code's (found by a user's audit: the check then compared a bug
    with itself). A user method's stored runs of other code are stale (they would be recomputed); the built-ins
    carry no code identity of their own, so their runs are judged by the revision of the checkout that made them
    (``git_revision`` in the run files, read with the run index; unknown outside a git checkout, and a dirty
    tree's changes are not told apart)."""
    state = ResumeState.read(sweep, directory, "none")
    here = store.git_revision()
    made = set(state.rows["git_revision"].dropna()) - {""}
    if here and made - {here}:
        raise TanbenchError(f"{directory}: its runs were made by code revision {', '.join(sorted(made))}, and this "
                            f"is {here}: the runs --until-decisive adds would be this code's, not that code's; make "
                            f"both directories with one code (e.g. rerun it here), or check without --until-decisive")
    stale = state.stale()
    if len(stale):
        why = ", ".join(f"{method} ({', '.join(sorted(set(group['stale'])))})"
                        for method, group in stale.groupby("method"))
        raise TanbenchError(f"{directory}: {len(stale)} stored run(s) would be recomputed by the code here, "
                            f"not extended: {why}; --until-decisive only adds runs made as the stored ones were "
                            f"(rerun that directory with its own code first, or check without --until-decisive)")


def until_decisive(new_dir, base_dir, options: CheckOptions, batch: int, cap: int, echo=print) -> CheckResult:
    """The check at the first decisive look (or the cap); see the module docstring."""
    dirs = [Path(new_dir), Path(base_dir)]
    sweeps = []
    for d in dirs:
        if not (d / "sweep.yaml").is_file():
            raise TanbenchError(f"{d}: no sweep.yaml; --until-decisive extends a directory with its own sweep")
        sweeps.append(load_sweep(d / "sweep.yaml"))
    for sweep, d in zip(sweeps, dirs):
        _check_extendable(sweep, d)
    start = max(min(_stored_runs(d) for d in dirs), min(batch, cap))
    plan = looks(start, batch, cap)
    level = spend(options.alpha, len(plan))
    result = None
    for k, n in enumerate(plan, 1):
        for sweep, d in zip(sweeps, dirs):
            report = run_sweep(sweep.with_runs(n), d, series="none", progress=False, echo=lambda *_: None,
                               note=lambda *_: None)
            if report.failed_rows or report.lost or report.interrupted:
                raise TanbenchError(f"{d}: the sweep did not finish {n} runs per cell; fix it and rerun")
        result = compare(dirs[0], dirs[1], options, alpha=level)
        d = result.decisive
        decided = int((d["verdict"].isin(["regressed", "improved"]) | d["equivalent"]).sum())
        echo(f"look {k}/{len(plan)}: {n} runs per cell, level {level:.2g}: {decided} of {len(d)} rows decided")
        if result.decided:
            break
    return result
