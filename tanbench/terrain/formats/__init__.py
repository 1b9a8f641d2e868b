"""Grid file formats: the registry (:mod:`tanbench.terrain.formats.registry`) and the built-in readers.

A new format is one module that defines its reader and registers it::

    from tanbench.terrain.formats import RawGrid, register_format

    def read_xyz(path):
        ...
        return RawGrid(z, georef="header", x0=..., y0=..., dx=..., dy=..., crs="metric")

    register_format("xyz", (".xyz",), read_xyz)

Once the module is imported, files with the suffix (or any file with ``format: xyz`` in
a sweep's terrain) are read through it; a package adds formats for every tanbench command
by naming its modules under the ``tanbench.formats`` entry-point group (see the registry).
"""

from tanbench.terrain.formats.registry import (ENTRY_POINT_GROUP, FORMATS, GridFormat, RawGrid,  # noqa: F401
                                               as_2d, as_float, format_named, known_formats, mask_value,
                                               read_raw, register_format, resolve_format)
from tanbench.terrain.formats.registry import load_plugin_formats

# The built-in formats register themselves on import (this order is the order of messages),
# then those of installed plug-ins.
from tanbench.terrain.formats import geotiff, netcdf, esri_ascii, npy  # noqa: E402,F401,I001

load_plugin_formats()
