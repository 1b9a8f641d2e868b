"""Numerical kernels of the particle filters: propagation, likelihood, resampling, estimates.

Jitted functions on plain arrays (each with a plain-numpy reference in the tests); the
methods that assemble them into TAN filters are in :mod:`tanbench.methods`.
"""

# fastmath without the no-NaN / no-Inf assumptions: the kernels test for NaN (beams without
# a range, footprints off the map), which full fastmath would silently compile away.
FASTMATH = {"contract", "arcp", "nsz", "reassoc", "afn"}

