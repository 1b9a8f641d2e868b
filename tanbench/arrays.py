"""Array helpers every layer shares (base layer: numpy only)."""

from __future__ import annotations

import os

import numpy as np


def read_only(arr: np.ndarray) -> np.ndarray:
    """A read-only view of ``arr``: the same memory (no copy, the same alignment), over a
    read-only buffer, so that neither it nor a view of it can be made writeable again.

    Also what the jitted kernels' Python wrappers hand them: numba compiles a kernel once per
    argument type, and an array's type includes whether it is read-only, so inputs that are
    sometimes views of read-only data (a method's inputs) and sometimes fresh arrays would
    compile every kernel twice (docs/speed.md, "Compiling one signature per kernel")."""
    return np.asarray(memoryview(arr).toreadonly())


def physical_memory() -> int | None:
    """This machine's memory in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None
