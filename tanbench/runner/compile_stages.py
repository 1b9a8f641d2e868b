"""The kernels two compile processes would both compile, split between them (issue 27, docs/speed.md).

When a sweep's families compile side by side (:func:`tanbench.runner.plan.compile_groups`), each process
compiles every kernel its methods reach, and the tight and loose families reach many of the same: the
simulation's kernels, the likelihood pass, the random numbers, resampling and the estimate. A kernel
compiled on its own goes into numba's on-disk cache, and a caller compiled later, in any process, loads it
from there instead of compiling it again. So each process first compiles its *share* of the shared kernels,
by their recorded argument types, and only then warms up its own methods, loading what the other process
compiled meanwhile.

The shares are data, recorded from cold compiles by ``make compile-stages`` (:func:`record`) into
``compile_stages.json`` beside this module: for each family of the table, the shared kernels it compiles
first (those both families reach that no other shared kernel calls, each with its argument types and the
seconds it took), split so that each process's share plus its own kernels take about equally long.
A signature the code no longer passes would be compiled for nothing: a test warms up every share and then
every method on an empty cache and requires one signature per kernel, so a stale table fails it; an entry
that does not resolve (a renamed kernel, a type this numba cannot build) is skipped at run time.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tanbench.runner.plan import STAGES_TABLE as TABLE
from tanbench.runner.plan import family_of, kernel_variant, load_stages_table, staged_groups

# the methods whose cold warm-ups are recorded, per family: configs/quick.yaml's and the default sweep's
RECORDED = {"tight": ("tight-dvl", "tight-sbe"), "loose": ("loose-dvl",)}


# --- numba argument types as JSON --------------------------------------------------------------------

def encode_type(ty) -> list:
    """A JSON form of the numba argument type ``ty`` (the kinds tanbench's kernels take)."""
    from numba.core import types

    if isinstance(ty, types.Array):
        return ["array", str(ty.dtype), ty.ndim, ty.layout, not ty.mutable]
    if isinstance(ty, types.Omitted):
        return ["omitted", ty.value]
    if isinstance(ty, types.Literal):
        return ["literal", ty.literal_value]
    if isinstance(ty, types.BaseTuple):
        cls = getattr(ty, "instance_class", None)
        where = f"{cls.__module__}:{cls.__qualname__}" if isinstance(ty, types.BaseNamedTuple) else None
        return ["tuple", [encode_type(t) for t in ty.types], where]
    if isinstance(ty, (types.Integer, types.Float, types.Boolean)):
        return ["scalar", str(ty)]
    raise TypeError(f"no JSON form for the numba type {ty}")


def decode_type(data: list):
    """The numba type :func:`encode_type` gave ``data`` for."""
    from numba.core import types

    kind, *rest = data
    if kind == "array":
        dtype, ndim, layout, readonly = rest
        return types.Array(getattr(types, dtype), ndim, layout, readonly=readonly)
    if kind == "omitted":
        return types.Omitted(rest[0])
    if kind == "literal":
        return types.literal(rest[0])
    if kind == "tuple":
        members, where = rest
        decoded = [decode_type(m) for m in members]
        if where is None:
            return types.BaseTuple.from_types(decoded)
        module, qualname = where.split(":")
        return types.BaseTuple.from_types(decoded, _resolve(module, qualname))
    if kind == "scalar":
        return getattr(types, rest[0])
    raise ValueError(f"unknown numba type kind {kind!r}")


def _resolve(module: str, qualname: str):
    obj = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


# --- using the table ---------------------------------------------------------------------------------

load_table = load_stages_table  # the recorded table (empty if there is none), read once per process


def shares_for(groups, scenario=None) -> list[list]:
    """Each of ``groups`` (lists of method names, compiled side by side, :func:`warm_up_side_by_side
    <tanbench.runner.executors.warm_up_side_by_side>`) with the share of the table it compiles first:
    the entries of the table's families in it. Nothing for any group unless every family of the table is
    in a group of its own and every built-in method of the groups runs its default kernel variant in a
    cell of ``scenario`` (:func:`tanbench.runner.plan.kernel_variant`): the table holds the default
    variant's argument types."""
    table = load_table().get("shares", {})
    shares = [[] for _ in groups]
    if not staged_groups(groups):
        return shares
    group_of = {family_of(m): i for i, g in enumerate(groups) for m in g}  # compile_groups keeps a family whole
    if scenario is not None and any(kernel_variant(m, scenario) for g in groups for m in g
                                    if family_of(m) in RECORDED):
        return shares
    for family, entries in table.items():
        shares[group_of[family]] = list(entries)
    return shares


def compile_share(entries) -> tuple[int, list[str]]:
    """Compile (or load from numba's cache) each kernel of ``entries`` (a share of the table) with its
    recorded argument types, in order; returns how many were compiled and the names of those skipped: a
    kernel or type that does not resolve here, or types the kernel no longer compiles for (with jitting
    disabled, every entry)."""
    done, skipped = 0, []
    for entry in entries:
        try:
            module, qualname = entry["kernel"].rsplit(".", 1)
            signature = tuple(decode_type(t) for t in entry["signature"])
            _resolve(module, qualname).compile(signature)
        except Exception:  # noqa: BLE001 - a stale entry costs nothing but this: its kernel compiles with its caller
            skipped.append(entry.get("kernel", "?"))
            continue
        done += 1
    return done, skipped


# --- recording the table (make compile-stages) -------------------------------------------------------

def record_compiles(warm_up) -> dict:
    """In this process, on an empty numba cache: call ``warm_up()`` (a group's warm-up) and return every
    tanbench kernel compile of it, in order: the kernel, its argument types (:func:`encode_type`), the seconds
    it took with its callees, and its caller (None for one called from Python); and the seconds of the whole
    warm-up."""
    from numba.core import event

    started = time.perf_counter()
    with event.install_recorder("numba:compile") as recorder:
        warm_up()
    total = time.perf_counter() - started
    compiles, stack = [], []
    for stamp, ev in recorder.buffer:
        dispatcher = ev.data["dispatcher"]
        name = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
        if ev.is_start:
            stack.append((name, stamp, ev.data["args"]))
            continue
        name, begun, args = stack.pop()
        if not name.startswith("tanbench."):
            continue
        caller = next((s[0] for s in reversed(stack) if s[0].startswith("tanbench.")), None)
        try:
            signature = [encode_type(t) for t in args]
        except TypeError:
            signature = None
        compiles.append({"kernel": name, "signature": signature, "seconds": stamp - begun, "caller": caller})
    return {"seconds": total, "compiles": compiles}


def split_shares(records: dict) -> dict:
    """The table from each family's :func:`record_compiles`: the kernels every family compiles with the same
    argument types are shared; the roots among them (no shared kernel calls them) are split, the longest
    first, each to the family whose share plus its own seconds (its warm-up less its shared roots) is then
    shortest."""
    def key(c):
        return c["kernel"], json.dumps(c["signature"])

    per_family = {f: {key(c): c for c in r["compiles"] if c["signature"] is not None} for f, r in records.items()}
    shared = set.intersection(*(set(k) for k in per_family.values()))
    shared_names = {k[0] for k in shared}
    callers = {k: {fam[k]["caller"] for fam in per_family.values()} for k in shared}
    roots = [k for k in shared if not callers[k] & shared_names]
    seconds = {k: max(fam[k]["seconds"] for fam in per_family.values()) for k in roots}
    own = {f: records[f]["seconds"] - sum(per_family[f][k]["seconds"] for k in roots) for f in records}
    shares = {f: [] for f in records}
    load = dict(own)
    for k in sorted(roots, key=lambda k: (-seconds[k], k)):
        family = min(load, key=lambda f: (load[f], f))
        load[family] += seconds[k]
        shares[family].append({"kernel": k[0], "signature": json.loads(k[1]), "seconds": round(seconds[k], 2)})
    return {"own_seconds": {f: round(s, 1) for f, s in own.items()},
            "expected_seconds": {f: round(s, 1) for f, s in load.items()}, "shares": shares}


def record(path: Path = TABLE) -> dict:
    """Record each family of :data:`RECORDED` warming up alone in a fresh process on an empty numba cache,
    one after the other, and write the table to ``path``."""
    import numba

    records = {}
    for family, methods in RECORDED.items():
        with tempfile.TemporaryDirectory(prefix="tanbench-stages-") as cache:
            code = ("import json\nfrom tanbench.runner.compile_stages import record_compiles\n"
                    "from tanbench.runner.executors import warm_up\n"
                    f"print(json.dumps(record_compiles(lambda: warm_up(None, {tuple(methods)!r}))))\n")
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                                 env={**os.environ, "NUMBA_CACHE_DIR": cache})
            records[family] = json.loads(out.stdout.strip().splitlines()[-1])
    table = {"numba": numba.__version__, "recorded": RECORDED, **split_shares(records)}
    write_table(table, path)
    return table


def write_table(table: dict, path: Path = TABLE) -> None:
    """Write ``table`` to ``path`` as JSON with one line per kernel of a share (readable in a diff)."""
    head = {k: v for k, v in table.items() if k != "shares"}
    lines = ["{"] + [f" {json.dumps(k)}: {json.dumps(v)}," for k, v in head.items()] + [' "shares": {']
    for i, (family, entries) in enumerate(table["shares"].items()):
        lines.append(f"  {json.dumps(family)}: [")
        lines += [f"   {json.dumps(e)}" + ("," if j < len(entries) - 1 else "") for j, e in enumerate(entries)]
        lines.append("  ]" + ("," if i < len(table["shares"]) - 1 else ""))
    path.write_text("\n".join(lines + [" }", "}"]) + "\n")
    load_stages_table.cache_clear()


if __name__ == "__main__":
    written = record()
    print(f"wrote {TABLE.name}: " + ", ".join(f"{f} {len(s)} kernels ({written['expected_seconds'][f]} s expected)"
                                              for f, s in written["shares"].items()))
