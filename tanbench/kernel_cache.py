"""Where numba caches tanbench's compiled kernels: a directory named by their sources.

numba invalidates a cached kernel only when the kernel's own file changes, but a kernel
holds its callees, and the module constants it reads, compiled inside it: an edit to a
callee in another module (or a ``git pull``) would leave its callers running yesterday's
code. So tanbench points numba's cache at a directory named by a hash of every source
that compiled code can hold: the modules that import numba at their top, and, followed
transitively, the tanbench modules those import at their top (constants and jitted
helpers come from there). Any edit to one of them gives a new directory, so every kernel
compiles afresh; an edit elsewhere (the CLI, the results tables) keeps the cache.

The directory is ``PARENT/tanbench-kernels-<hash>``, where PARENT is the user's
``NUMBA_CACHE_DIR`` if set, else ``tanbench/__pycache__`` beside the sources (or
``~/.cache/tanbench`` when the package is not writable). It is set when tanbench is
imported, before any kernel module is decorated: :mod:`tanbench` imports this module
first. Child processes (the sweep's workers) inherit ``NUMBA_CACHE_DIR``; a value that
is already such a directory is read as its parent, so they use the same one.
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
from functools import lru_cache
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
PREFIX = "tanbench-kernels-"
_OURS = re.compile(rf"^{PREFIX}[0-9a-f]{{16}}$")
_NUMBA_AT_TOP = re.compile(r"^(?:import numba|from numba)\b", re.M)
_TANBENCH_AT_TOP = re.compile(r"^(?:from|import)\s+(tanbench(?:\.\w+)*)", re.M)
# the module whose kernels a sweep always runs: its cache index says whether the cache is warm
MAIN_KERNEL_MODULE = "tight"


def _module_file(name: str) -> Path | None:
    parts = name.split(".")[1:]
    for path in (PACKAGE.joinpath(*parts).with_suffix(".py"), PACKAGE.joinpath(*parts, "__init__.py")):
        if parts and path.is_file():
            return path
    return None


def kernel_sources() -> list[Path]:
    """The sources compiled kernels can hold: modules importing numba at their top, and the
    tanbench modules those import at their top, transitively (sorted)."""
    texts = {p: p.read_text(errors="replace") for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts}
    todo = [p for p, text in texts.items() if _NUMBA_AT_TOP.search(text)]
    found = set(todo)
    while todo:
        for name in _TANBENCH_AT_TOP.findall(texts[todo.pop()]):
            path = _module_file(name)
            if path is not None and path not in found:
                found.add(path)
                todo.append(path)
    return sorted(found)


@lru_cache(maxsize=1)
def sources_hash() -> str:
    """A 16-hex-digit hash of :func:`kernel_sources` (their paths in the package and bytes)."""
    digest = hashlib.sha256()
    for path in kernel_sources():
        digest.update(path.relative_to(PACKAGE).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def _default_parent() -> Path:
    beside = PACKAGE / "__pycache__"
    try:
        beside.mkdir(exist_ok=True)
    except OSError:
        pass
    if os.access(beside, os.W_OK):
        return beside
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "tanbench"


def cache_parent() -> Path:
    """Where the per-version cache directories go: the user's ``NUMBA_CACHE_DIR`` or the default."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    if not given:
        return _default_parent()
    path = Path(given)
    return path.parent if _OURS.match(path.name) else path


def cache_dir() -> Path:
    """This tanbench's kernel cache directory (see the module docstring)."""
    return cache_parent() / f"{PREFIX}{sources_hash()}"


def use_kernel_cache() -> Path:
    """Point numba's cache at :func:`cache_dir` (for this process and the processes it starts);
    under the default parent if the user's ``NUMBA_CACHE_DIR`` cannot hold it (numba would then
    fall back to caching beside the sources, where a stale kernel could be loaded)."""
    path = cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        path = _default_parent() / path.name
    os.environ["NUMBA_CACHE_DIR"] = str(path)
    config = sys.modules.get("numba.core.config")
    if config is not None:  # numba was imported before tanbench: it has read the variable already
        config.CACHE_DIR = str(path)
    return path


WARM_MARK = "warmed-"  # + a kernel name (:func:`kernel_name`): a file in the cache directory once its kernels are in it
VARIANT_SEP = "+"  # between a built-in method's name and the variant of its kernels in a kernel name


def kernel_name(method: str, variant: str = "") -> str:
    """The name a warm mark carries for ``method``'s kernels compiled in ``variant`` (the options that
    change their argument types, ``tanbench.runner.plan.kernel_variant``): the method's name for its
    default variant (""), else ``method+variant``."""
    return f"{method}{VARIANT_SEP}{variant}" if variant else method


def method_of(kernel: str) -> str:
    """The method of a kernel name (:func:`kernel_name`)."""
    return kernel.split(VARIANT_SEP, 1)[0]


def variant_of(kernel: str) -> str:
    """The variant of a kernel name (:func:`kernel_name`; "" for the default)."""
    return kernel.partition(VARIANT_SEP)[2]


def is_warm(methods=None) -> bool:
    """Whether the cache holds the kernels of the main filter module (a sweep then loads them
    instead of compiling; the rule of ``plan``'s estimate and of ``run``'s compile message).

    With ``methods`` (kernel names, :func:`kernel_name`: built-in method names, each in its default
    variant or with ``+variant``): whether it holds the kernels of each, as marked by
    :func:`mark_warm` once a warm-up compiled them here.
    """
    if methods is None:
        path = cache_dir()
        return path.is_dir() and any(path.rglob(f"{MAIN_KERNEL_MODULE}.*.nbi"))
    return not cold_methods(methods)


def cold_methods(methods) -> list[str]:
    """The kernel names among ``methods`` (:func:`kernel_name`) whose kernels this cache does not hold yet."""
    path = cache_dir()
    return [name for name in methods if not (path / f"{WARM_MARK}{name}").is_file()]


def warm_kernels() -> list[str]:
    """Every kernel name (:func:`kernel_name`) marked warm in this cache, sorted."""
    path = cache_dir()
    try:
        return sorted(p.name[len(WARM_MARK):] for p in path.glob(f"{WARM_MARK}*"))
    except OSError:
        return []


def mark_warm(methods) -> None:
    """Record that the kernels of these kernel names (:func:`kernel_name`) are in the cache (after a
    warm-up ran each one here); a cache that cannot be written is simply not marked."""
    path = cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
        for name in methods:
            (path / f"{WARM_MARK}{name}").touch()
    except OSError:
        pass
