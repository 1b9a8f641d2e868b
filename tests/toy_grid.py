"""A toy grid format that tanbench does not know: a line 'e0 n0 res', then rows south to north.

Only its reader lives here; the tests register it, from a test module or as an installed
plug-in (entry point), to show that a new format needs nothing in the package.
"""

from __future__ import annotations

import numpy as np

from tanbench.terrain.formats import RawGrid

SUFFIX = ".toygrid"


def write_toy(path, z, e0=0.0, n0=0.0, res=5.0) -> None:
    lines = [f"{e0!r} {n0!r} {res!r}"] + [" ".join(repr(float(v)) for v in row) for row in z]
    path.write_text("\n".join(lines) + "\n")


def read_toy(path) -> RawGrid:
    lines = path.read_text().split("\n")
    e0, n0, res = (float(v) for v in lines[0].split())
    z = np.array([[float(v) for v in line.split()] for line in lines[1:] if line.strip()])
    return RawGrid(z, georef="header", x0=e0, y0=n0, dx=res, dy=res, crs="metric")
