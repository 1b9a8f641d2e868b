"""Resuming a sweep: what a results directory holds, whose it is, and what is stale.

:meth:`ResumeState.read` reads the store once per sweep (every run file's identity
columns and metadata, the list of series files) and hashes each map file once. From it:

* which tasks are done: every method of the sweep has a stored "ok" row made exactly as
  it would be made now (the same seeds, map content and user-method code), and the run's
  series file exists when series are kept;
* what is stale: stored "ok" runs of the sweep's cells that would come out differently
  now. Runs made with other seeds (a changed root seed) or from edited map files are
  refused unless ``--force``; runs of a user method whose code changed are recomputed.
  Either way every stale run is recomputed, also one outside the sweep's run range, so
  no table ever pools runs of two codes or seeds, and no run is deleted to get there;
* who owns the directory: the sweep named by ``sweep.yaml``, or, if that file is damaged,
  by its run files; another sweep needs ``--add``, and may not bring another root seed.

Failed rows ("error") are never stale: they are retried by every rerun.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import yaml

from tanbench import store
from tanbench.errors import TanbenchError
from tanbench.methods.registry import get
from tanbench.runner.seeds import keyed_filter_seed, keyed_vehicle_seed, seed_number
from tanbench.runner.tasks import Task
from tanbench.sweep import Sweep
from tanbench.terrain.files import terrain_content_hash


def terrain_hashes(sweep: Sweep) -> dict[str, str]:
    """Per cell with a file terrain: the content hash of its map files (each file hashed once)."""
    by_spec: dict[str, str | None] = {}
    out = {}
    for cell in sweep.cells:
        key = json.dumps(cell.scenario.terrain.model_dump(mode="json"), sort_keys=True)
        if key not in by_spec:
            by_spec[key] = terrain_content_hash(cell.scenario.terrain)
        if by_spec[key] is not None:
            out[cell.cell_id] = by_spec[key]
    return out


def method_codes(sweep: Sweep) -> dict[str, str]:
    """Per user method of the sweep: its code identity (:meth:`MethodRecord.code_id`)."""
    return {m: get(m).code_id() for m in sweep.spec.methods if get(m).code_id() is not None}


def expected_seeds(sweep: Sweep, keys) -> dict[tuple[str, int, str], tuple[int, int]]:
    """(seed, filter seed) a row of (cell, run, method) would carry now, for ``keys`` of (cell, run)."""
    cells = {c.cell_id: c.scenario for c in sweep.cells}
    cell_keys = {cell: (sc.pairing_key(), sc.cell_key()) for cell, sc in cells.items()}
    seed_ids = {m: get(m).seed_id for m in sweep.spec.methods}
    root = sweep.spec.seed
    out = {}
    for cell, run in keys:
        if cell not in cell_keys:
            continue
        pairing, cell_key = cell_keys[cell]
        vseed = seed_number(keyed_vehicle_seed(root, pairing, run))
        for method, seed_id in seed_ids.items():
            out[(cell, run, method)] = (vseed, seed_number(keyed_filter_seed(root, cell_key, seed_id, run)))
    return out


@dataclass
class ResumeState:
    """What ``out`` holds for ``sweep`` (see the module docstring)."""

    sweep: Sweep
    out: Path
    rows: pd.DataFrame  # the sweep's cells' stored rows, with a ``stale`` column ("", "seeds", "map", "code")
    damaged: list[tuple[Path, str]]
    series: set[tuple[str, int]]
    terrain: dict[str, str]
    codes: dict[str, str]
    owner: str | None = None  # the sweep the directory belongs to (None: an empty directory)
    owner_from: str = "sweep.yaml"
    stored_seeds: set = field(default_factory=set)  # root seeds of every stored run file
    damaged_cells: set = field(default_factory=set)  # cells with an unreadable run file (every run to redo)
    summary_damaged: bool = False  # the series summary cannot be read: every run needs its own series file

    @classmethod
    def read(cls, sweep: Sweep, out: Path, series_mode: str = "summary") -> "ResumeState":
        """``series_mode``: the run's ``--series``; with ``none`` an unreadable series summary is left as it is (nothing
        rebuilds it; ``tables`` keeps naming it)."""
        terrain, codes = terrain_hashes(sweep), method_codes(sweep)
        if not (out / "runs").is_dir():
            return cls(sweep, out, _with_stale(pd.DataFrame(columns=store.RUN_INDEX_COLUMNS), ""), [], set(),
                       terrain, codes)
        store.check_layout(out)
        everything, damaged = store.read_run_index(out)
        owner, owner_from = _owner(out, everything) if len(everything) or damaged else (None, "")
        stored_seeds = set(everything["root_seed"].dropna().astype(int))
        ids = {c.cell_id for c in sweep.cells}
        rows = everything[everything["cell_id"].isin(ids)].reset_index(drop=True)
        series, damaged_series = store.series_runs(out, check=True)
        summary = store.unreadable_summary(out) if series_mode != "none" else None
        damaged_summary = [(store.summary_file(out), summary)] if summary is not None else []
        state = cls(sweep, out, rows, damaged + damaged_series + damaged_summary, series, terrain, codes, owner,
                    owner_from, stored_seeds, {store.cell_of(p) for p, _ in damaged}, summary is not None)
        state.rows = state._mark_stale(rows)
        return state

    def _mark_stale(self, rows: pd.DataFrame) -> pd.DataFrame:
        if rows.empty:
            return _with_stale(rows, "")
        expected = expected_seeds(self.sweep, set(zip(rows["cell_id"], rows["run"].astype(int))))
        why = []
        for r in rows.itertuples(index=False):
            want = expected.get((r.cell_id, int(r.run), r.method))
            if r.status != "ok" or want is None:  # failures are retried; other methods are not ours
                why.append("")
            elif (int(r.seed), int(r.filter_seed)) != want:
                why.append("seeds")
            elif r.cell_id in self.terrain and r.terrain is not None and r.terrain != self.terrain[r.cell_id]:
                why.append("map")
            elif r.method in self.codes and r.code != self.codes[r.method]:
                why.append("code")
            else:
                why.append("")
        return _with_stale(rows, why)

    # ---- what is done, what is stale ----------------------------------------------
    def done(self, tasks: list[Task], need_series: bool) -> set[tuple[str, int]]:
        """(cell, run) of ``tasks`` stored exactly as they would be computed now.

        With ``need_series``, a run also needs its series file if its cell keeps series
        here: it has some (a missing one was deleted), or this session computes some of its
        runs (the rebuilt summary must cover them all). A cell with none, and nothing to
        compute, keeps the summary it has (a clone of committed results has no per-run series).
        """
        good = self.rows[(self.rows["status"] == "ok") & (self.rows["stale"] == "")]
        have = set(zip(good["cell_id"], good["run"].astype(int), good["method"]))
        stored = {t.key for t in tasks
                  if t.cell_id not in self.damaged_cells and all((*t.key, m) in have for m in t.methods)}
        if not need_series:
            return stored
        if self.summary_damaged:  # no summary to keep a cell's rows from: each run's own series file rebuilds it
            return {key for key in stored if key in self.series}
        keeps = {cell for cell, _ in self.series} | {t.cell_id for t in tasks if t.key not in stored}
        return {key for key in stored if key in self.series or key[0] not in keeps}

    def stale(self, kinds=("seeds", "map", "code")) -> pd.DataFrame:
        return self.rows[self.rows["stale"].isin(kinds)]

    def missing_series(self, tasks: list[Task]) -> int:
        """How many of ``tasks`` have every row stored but are to run again for their series file."""
        return len(self.done(tasks, need_series=False) - self.done(tasks, need_series=True))

    def check(self, force: bool, add: bool) -> list[str]:
        """Refuse what cannot be resumed (one line); the notices of what will be recomputed."""
        name = self.sweep.name
        if self.owner is not None and self.owner != name and not add:
            how = "" if self.owner_from == "sweep.yaml" else " (its sweep.yaml is damaged: the name is its run files')"
            raise TanbenchError(f"{self.out} holds the results of sweep {self.owner!r}{how}, not {name!r}: use "
                                f"another --out, or --add to add this sweep's cells to it")
        if add and self.stored_seeds and self.sweep.spec.seed not in self.stored_seeds:
            seeds = ", ".join(str(s) for s in sorted(self.stored_seeds))
            raise TanbenchError(f"{self.out} holds runs made with root seed {seeds}; sweep {name!r} has root seed "
                                f"{self.sweep.spec.seed}, and one directory holds one root seed (its cells would "
                                f"mix two): use another --out")
        refused = self.stale(("seeds", "map"))
        if len(refused):
            others = sorted(set(refused["sweep"].dropna()) - {name})
            if others:
                whose = f"sweep {others[0]!r}'s" if others else "the directory's"
                raise TanbenchError(
                    f"{self.out} holds {len(refused)} run(s) of this sweep's cells made with other seeds or from "
                    f"other map files ({whose}); a sweep does not replace another's runs: use another --out")
            if not force:
                raise TanbenchError(self._refusal(refused))
        notices = []
        recomputed = self.stale(("code",) if not force else ("seeds", "map", "code"))
        for method, group in recomputed.groupby("method", sort=True):
            why = sorted(set(group["stale"]))
            what = {"code": "its code has changed since", "seeds": "they were made with other seeds",
                    "map": "they were made from other map files"}
            notices.append(f"note: recomputing {len(group)} stored run(s) of {method} in {group['cell_id'].nunique()} "
                           f"cell(s): {'; '.join(what[w] for w in why)}" +
                           (f" (now: {self.codes[method]})" if "code" in why else "") +
                           ("; a run's task is run whole, so the other methods of those runs are computed again "
                            "too (to the same results)" if len(self.sweep.spec.methods) > 1 else ""))
        for path, reason in self.damaged:
            what = ("it is rebuilt from the runs' series files, and runs without one are recomputed"
                    if path == store.summary_file(self.out) else "its runs are recomputed")
            notices.append(f"note: {path} cannot be read ({reason}): set aside as .{path.name}.damaged; {what}")
        return notices

    def _refusal(self, refused: pd.DataFrame) -> str:
        cells = refused["cell_id"].nunique()
        if (refused["stale"] == "map").all():
            edited = ", ".join(sorted(set(refused["cell_id"])))
            return (f"{self.out} holds runs of {cells} of this sweep's cells made from map files whose content has "
                    f"changed since ({edited}); they would come out differently now: rerun with --force to "
                    f"recompute them, or use another --out")
        return (f"{self.out} holds {len(refused)} run(s) of {cells} of this sweep's cells made with other seeds "
                f"(was the sweep's root seed {self.sweep.spec.seed} changed?); they would come out differently "
                f"now: rerun with --force to recompute them, or use another --out")

    def stale_runs_outside(self, runs: int, force: bool) -> set[tuple[str, int]]:
        """(cell, run) of stale stored runs at run indices the sweep's range does not reach (recomputed too)."""
        kinds = ("seeds", "map", "code") if force else ("code",)
        stale = self.stale(kinds)
        return {(c, int(r)) for c, r in zip(stale["cell_id"], stale["run"]) if int(r) >= runs}

    def set_aside_damaged(self) -> None:
        for path, _ in self.damaged:
            if path.exists():
                store.set_aside(path)


def _with_stale(rows: pd.DataFrame, why) -> pd.DataFrame:
    rows = rows.copy()
    rows["stale"] = why
    return rows


def _owner(out: Path, rows: pd.DataFrame) -> tuple[str | None, str]:
    """The sweep ``out`` belongs to: ``sweep.yaml``'s name, else (a damaged or missing file)
    the sweep that wrote its newest run file."""
    try:
        name = (yaml.safe_load((out / "sweep.yaml").read_text()) or {}).get("name")
        if isinstance(name, str):
            return name, "sweep.yaml"
    except (OSError, ValueError, AttributeError, yaml.YAMLError):
        pass
    if rows.empty:
        return None, "runs"
    newest = rows.sort_values("mtime", kind="stable").iloc[-1]
    try:
        return store.read_meta(Path(newest["path"])).get("sweep"), "runs"
    except TanbenchError:
        return None, "runs"


def last_session_runs(out: Path, sweep_name: str) -> int | None:
    """The runs per cell the last session of sweep ``sweep_name`` in ``out`` was asked for (its ``--runs``, or its
    sweep file's), from ``sessions.jsonl`` (``engine.log_session``; a sweep added with ``--add`` logs its own); None
    where no session of it recorded them (results of older versions)."""
    try:
        lines = (out / "sessions.jsonl").read_text().splitlines()
    except OSError:
        return None
    for line in reversed(lines):
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        runs = entry.get("runs") if isinstance(entry, dict) and entry.get("sweep") == sweep_name else None
        if isinstance(runs, int) and runs > 0:
            return runs
    return None


def incomplete_cells(sweep: Sweep, out: Path) -> tuple[dict[str, str], int]:
    """Per cell of ``sweep`` whose stored runs in ``out`` are not whole: what is missing; and the directory's run
    count: the larger of the runs the sweep's last session there was asked for (:func:`last_session_runs`; none in
    results of older versions) and the most runs any of its cells holds (a session killed outright logs nothing).

    A cell is whole when every method of the sweep has a row for every run index below that count, and, in a
    directory that keeps series, every such run has a readable series file; an unreadable series summary makes
    every cell not whole. (What ``tables`` and ``plot`` show of a cell that is not whole is not what was run; a
    rerun of the sweep into the directory, with ``--runs`` that count, recomputes what is missing.)
    """
    rows, damaged = store.read_run_index(out) if (out / "runs").is_dir() else (
        pd.DataFrame(columns=store.RUN_INDEX_COLUMNS), [])
    series, damaged_series = store.series_runs(out, check=True)
    keeps_series = {cell for cell, _ in series} | {store.cell_of(p) for p, _ in damaged_series}
    unreadable = {store.cell_of(p) for p, _ in damaged}
    summary = store.unreadable_summary(out)
    mine = rows[rows["cell_id"].isin({c.cell_id for c in sweep.cells}) & rows["method"].isin(sweep.spec.methods)]
    count = max(last_session_runs(out, sweep.name) or 0, int(mine["run"].max()) + 1 if len(mine) else 0)
    out_cells = {}
    for cell in sweep.cells:
        if cell.cell_id in unreadable:
            out_cells[cell.cell_id] = "a run file cannot be read"
            continue
        if summary is not None:
            out_cells[cell.cell_id] = f"the series summary cannot be read: {summary}"
            continue
        held = mine[mine["cell_id"] == cell.cell_id]
        if held.empty:
            out_cells[cell.cell_id] = "no stored runs"
            continue
        have = set(zip(held["run"].astype(int), held["method"]))
        lacking = [f"run {r} of {m}" for r in range(count) for m in sweep.spec.methods if (r, m) not in have]
        if cell.cell_id in keeps_series:  # some series here: each run's (none: a clone keeps only the summary)
            lacking += [f"run {r}'s series file" for r in range(count) if (cell.cell_id, r) not in series]
        if lacking:
            more = f" and {len(lacking) - 3} more" if len(lacking) > 3 else ""
            out_cells[cell.cell_id] = f"missing {', '.join(lacking[:3])}{more}"
    return out_cells, count
