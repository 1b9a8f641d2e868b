"""Synthetic seafloors kept on disk, so a process builds each one once per machine, not once per process.

Synthesising the default seafloor (three fractal fields on 481 x 1201 nodes, a calibration
and a median search) takes about a second of CPU, and every ``tanbench run`` paid it again
in its parent process before any run started (docs/speed.md, fixed costs). A synthesised
map is a pure function of its resolved terrain spec and of the code and numpy that made
it, so it is stored once under the directory of tanbench's kernel cache
(:func:`tanbench.kernel_cache.cache_parent`) and read back, bit for bit, after that.

Identity: the directory is named by a hash of the sources synthesis runs (every module of
``tanbench/terrain``, and :mod:`tanbench.config`, which resolves the spec) and of numpy's
version (its FFT); a file is named by a hash of the resolved spec and holds the spec
itself, compared on reading. An edit to any of those sources, or another numpy, gives a
new directory (the old ones are removed), so a stored map is never one that today's code
would not make. Only synthetic seafloors are stored: file terrains are read from their
files. A file that cannot be read is recomputed and replaced; a cache that cannot be
written is skipped: the map is then synthesised as before.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from functools import lru_cache
from pathlib import Path

import numpy as np

from tanbench import kernel_cache
from tanbench.terrain.grid import Map

PREFIX = "tanbench-seafloors-"
KEPT = 8  # maps kept per directory (the most recently stored); about 4.6 MB each at the defaults
LARGEST_BYTES = 64 * 2**20  # larger maps are not stored


def _sources() -> list[Path]:
    package = kernel_cache.PACKAGE
    return sorted((package / "terrain").rglob("*.py")) + [package / "config.py"]


@lru_cache(maxsize=1)
def sources_hash() -> str:
    """A 16-hex-digit hash of the sources synthesis runs and of numpy's version."""
    digest = hashlib.sha256(np.__version__.encode() + b"\0")
    for path in _sources():
        if "__pycache__" in path.parts:
            continue
        digest.update(path.relative_to(kernel_cache.PACKAGE).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def cache_dir() -> Path:
    """The directory this code's seafloors are stored in."""
    return kernel_cache.cache_parent() / f"{PREFIX}{sources_hash()}"


def _file(key: str) -> Path:
    return cache_dir() / f"{hashlib.sha256(key.encode()).hexdigest()[:32]}.npz"


def load(key: str) -> Map | None:
    """The stored map of the resolved terrain spec ``key``, or None when there is none (or it cannot be read)."""
    path = _file(key)
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            if header.get("key") != key:
                return None
            z = data["z"]
        return Map(z=z, e0=header["e0"], n0=header["n0"], res_e=header["res_e"], res_n=header["res_n"],
                   name=header["name"], meta=header["meta"])
    except Exception:  # noqa: BLE001 - a damaged file is only a missed cache: synthesise again
        _remove(path)
        return None


def store(key: str, grid: Map) -> None:
    """Store ``grid`` as the map of ``key`` (whole or not at all); keep the :data:`KEPT` newest."""
    if grid.z.nbytes > LARGEST_BYTES:
        return
    path = _file(key)
    header = {"key": key, "e0": grid.e0, "n0": grid.n0, "res_e": grid.res_e, "res_n": grid.res_n,
              "name": grid.name, "meta": grid.meta}
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(tmp, z=grid.z, header=np.array(json.dumps(header)))
        os.replace(tmp, path)
        _prune(path.parent)
    except (OSError, TypeError, ValueError):  # read-only, full, or metadata JSON cannot hold: not stored
        _remove(tmp)


def _prune(directory: Path) -> None:
    """Keep the newest :data:`KEPT` maps here and drop the directories of other code versions."""
    try:
        maps = sorted((p for p in directory.glob("*.npz") if not p.name.startswith(".")),
                      key=lambda p: p.stat().st_mtime, reverse=True)
        for old in maps[KEPT:]:
            _remove(old)
        for other in directory.parent.glob(f"{PREFIX}*"):
            if other != directory and other.is_dir():
                shutil.rmtree(other, ignore_errors=True)
    except OSError:  # another process pruned at the same time
        pass


def _remove(path: Path) -> None:
    try:
        path.unlink()
    except OSError:
        pass
