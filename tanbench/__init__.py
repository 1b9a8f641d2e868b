"""tanbench: a Monte Carlo benchmark for underwater terrain-aided navigation.

The pipeline, one subpackage per stage:
terrain -> vehicle and sensors -> navigation -> filters -> runner -> results.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from tanbench.kernel_cache import use_kernel_cache

use_kernel_cache()  # before any kernel module is decorated: numba's cache keyed on the kernel sources

try:
    __version__ = _version("tanbench")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
