"""NumPy arrays: a bare 2-D ``.npy`` array, or an ``.npz`` with the grid and optional spacing keys."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.terrain.formats.registry import RawGrid, as_2d, register_format


def _unreadable(path: Path, kind: str, exc: Exception) -> TanbenchError:
    """np.load's failure as one line; its pickle refusal (a text file, or object arrays) without its
    advice to load the file unsafely."""
    if isinstance(exc, ValueError) and "allow_pickle" in str(exc):
        return TanbenchError(f"{path}: not a numeric NumPy array file (object/pickled data is refused)")
    return TanbenchError(f"{path}: not a readable {kind} file ({type(exc).__name__}: {exc})")


def read_npy(path: Path) -> RawGrid:
    """A bare 2-D array: georeferencing comes from the arguments."""
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise _unreadable(path, ".npy", exc) from None
    return RawGrid(as_2d(z, path))


def read_npz(path: Path) -> RawGrid:
    """Key ``z`` (or the only array) and optional scalar keys e0, n0, res_e, res_n."""
    meta_keys = ("e0", "n0", "res_e", "res_n")
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in npz.files}
    except Exception as exc:
        raise _unreadable(path, ".npz", exc) from None
    if "z" in arrays:
        zkey = "z"
    else:
        others = [key for key in arrays if key not in meta_keys]
        if len(others) != 1:
            raise TanbenchError(
                f"{path}: .npz needs a key 'z' or exactly one array (keys: {', '.join(arrays) or 'none'})"
            )
        zkey = others[0]
    raw = RawGrid(as_2d(arrays[zkey], path))
    found = {}
    for key in meta_keys:
        if key in arrays:
            try:
                found[key] = float(np.asarray(arrays[key]).reshape(()))
            except (TypeError, ValueError):
                raise TanbenchError(f"{path}: .npz key {key} must be a single number") from None
    for key, value in found.items():
        if not np.isfinite(value):
            raise TanbenchError(f"{path}: .npz key {key} must be finite, got {value}")
    for key in ("res_e", "res_n"):
        if key in found and not found[key] > 0:
            raise TanbenchError(f"{path}: .npz key {key} must be positive, got {found[key]}")
    raw.x0, raw.y0 = found.get("e0"), found.get("n0")
    raw.dx, raw.dy = found.get("res_e"), found.get("res_n")
    if found:
        raw.georef = "keys"
    return raw


register_format("npy", (".npy",), read_npy)
register_format("npz", (".npz",), read_npz)
