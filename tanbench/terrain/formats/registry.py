"""The grid format registry (keyed by file suffix) and what a format's reader returns.

:mod:`tanbench.terrain.formats` re-exports all of it and imports the built-in formats.

A format is a function ``read(path) -> RawGrid``: the array as stored plus whatever
georeferencing the file carries (tags, coordinate vectors, a header, keys). Everything
after that (explicit georeferencing options, row order, nodata, the crs, projection,
mosaics) is common to all formats and lives in :mod:`tanbench.terrain.georef` and
:mod:`tanbench.terrain.mosaic`; :func:`tanbench.terrain.files.read_grid` ties them
together.

A new format is one module that defines its reader and registers it::

    from tanbench.terrain.formats import RawGrid, register_format

    def read_xyz(path):
        ...
        return RawGrid(z, georef="header", x0=..., y0=..., dx=..., dy=..., crs="metric")

    register_format("xyz", (".xyz",), read_xyz)

Once the module is imported, files with the suffix (or any file with ``format: xyz`` in
a sweep's terrain) are read through it. The built-in formats register themselves in :mod:`tanbench.terrain.formats`;
a package adds formats for every tanbench command by naming its modules under the
``tanbench.formats`` entry-point group (``pyproject.toml``)::

    [project.entry-points."tanbench.formats"]
    xyz = "mypackage.xyz_format"
Readers raise :class:`~tanbench.errors.TanbenchError` with one line naming the file and
the problem.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from tanbench.errors import TanbenchError


@dataclass
class RawGrid:
    """An array as stored, with the file's georeferencing where it has some.

    Stored node ``[i, j]`` sits at ``(x0 + j * dx, y0 + i * dy)``; a negative ``dy``
    means row 0 is the northern edge. ``crs`` (``"metric"``, ``"epsg4326"``,
    ``"epsg3857"``) is None when the file does not say. ``georef`` names where the
    georeferencing came from (``"tags"``, ``"coordinates"``, ``"header"``, ``"keys"``;
    ``"none"``), ``problem`` why the file's own is unusable, if it is.
    """

    z: np.ndarray
    georef: str = "none"
    x0: float | None = None
    y0: float | None = None
    dx: float | None = None
    dy: float | None = None
    crs: str | None = None
    problem: str = ""

    @property
    def complete(self) -> bool:
        return None not in (self.x0, self.y0, self.dx, self.dy)


@dataclass(frozen=True)
class GridFormat:
    """A registered format: its name, the file suffixes that select it, other names for it."""

    name: str
    suffixes: tuple[str, ...]
    read: Callable[[Path], RawGrid]
    aliases: tuple[str, ...] = ()


FORMATS: dict[str, GridFormat] = {}
"""Registered formats by name, in registration order."""


def _format_key(name) -> str:
    return str(name).strip().lower().replace("_", "-")


def register_format(name: str, suffixes, read: Callable[[Path], RawGrid], *, aliases=()) -> GridFormat:
    """Register (or replace) the format ``name`` for files ending in ``suffixes``.

    ``read(path)`` returns a :class:`RawGrid`. A suffix or alias already taken by
    another format is an error.
    """
    key = _format_key(name)
    suffixes = tuple(s.lower() if s.startswith(".") else f".{s.lower()}" for s in suffixes)
    aliases = tuple(_format_key(a) for a in aliases)
    for other in FORMATS.values():
        if other.name == key:
            continue
        taken = set(suffixes) & set(other.suffixes)
        if taken:
            raise TanbenchError(f"format {key!r}: suffix {sorted(taken)[0]!r} is already read as {other.name!r}")
        clash = ({key, *aliases} & {other.name, *other.aliases})
        if clash:
            raise TanbenchError(f"format {key!r}: the name {sorted(clash)[0]!r} is already {other.name!r}")
    fmt = GridFormat(key, suffixes, read, aliases)
    FORMATS[key] = fmt
    return fmt


def known_formats() -> str:
    """The registered formats and their suffixes, for messages."""
    return "; ".join(f"{f.name} ({', '.join(f.suffixes)})" for f in FORMATS.values())


def format_named(name) -> GridFormat | None:
    """The format called ``name`` or one of its aliases, else None."""
    key = _format_key(name)
    for fmt in FORMATS.values():
        if key == fmt.name or key in fmt.aliases:
            return fmt
    return None


def resolve_format(path: Path, name: str | None) -> GridFormat:
    """The format ``name`` selects, or (``name`` None) the one the file's suffix selects."""
    if name is not None:
        fmt = format_named(name)
        if fmt is None:
            raise TanbenchError(f"{path}: unknown grid format {name!r}; known formats: {known_formats()}")
        return fmt
    suffix = path.suffix.lower()
    for fmt in FORMATS.values():
        if suffix in fmt.suffixes:
            return fmt
    raise TanbenchError(
        f"{path}: cannot tell the grid format from the extension {suffix or '(none)'!r}; "
        f"known formats: {known_formats()}; or pass format="
    )


def read_raw(path: Path, name: str | None = None) -> tuple[str, RawGrid]:
    """The name of the file's format and what its reader returns."""
    fmt = resolve_format(path, name)
    return fmt.name, fmt.read(path)


# ---- values: what every reader does to what it read ---------------------------------------


def as_float(z: np.ndarray, path: Path) -> np.ndarray:
    """Numeric grid values as float64, non-finite values as NaN."""
    if z.dtype.kind not in "iuf":
        raise TanbenchError(f"{path}: grid values have type {z.dtype}; expected numbers")
    out = z.astype(np.float64)
    out[~np.isfinite(out)] = np.nan
    return out


def as_2d(z, path: Path) -> np.ndarray:
    """A 2-D array's values as :func:`as_float` gives them; another shape is an error."""
    z = np.asarray(z)
    if z.ndim != 2:
        raise TanbenchError(f"{path}: array has shape {z.shape}; expected a 2-D grid")
    return as_float(z, path)


def mask_value(z: np.ndarray, value: float) -> np.ndarray:
    """NaN where z equals a nodata value (compared in float32 too, as grids often store it)."""
    if np.isnan(value):
        return z
    hit = (z == value) | (z == float(np.float32(value)))
    if hit.any():
        z = z.copy()
        z[hit] = np.nan
    return z


ENTRY_POINT_GROUP = "tanbench.formats"


def load_plugin_formats() -> None:
    """Import every module installed under the ``tanbench.formats`` entry-point group."""
    from importlib.metadata import entry_points

    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            entry.load()
        except Exception as exc:  # noqa: BLE001 - a broken plug-in is one line, not a traceback
            raise TanbenchError(
                f"grid format plug-in {entry.name!r} ({entry.value}) does not load: {type(exc).__name__}: {exc}"
            ) from None
