"""Numerical kernels of the particle filters: propagation, likelihood, resampling, estimates.

Jitted functions on plain arrays (each with a plain-numpy reference in the tests); the
methods that assemble them into TAN filters are in :mod:`tanbench.methods`.
"""

# the kernels' fastmath flags, defined (and explained) in tanbench/fastmath.py
from tanbench.fastmath import FASTMATH  # noqa: F401 - re-exported for the kernel modules
