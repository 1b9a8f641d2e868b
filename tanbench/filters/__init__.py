"""Numerical kernels of the particle filters: propagation, likelihood, resampling, estimates.

Jitted functions on plain arrays (each with a plain-numpy reference in the tests); the
methods that assemble them into TAN filters are in :mod:`tanbench.methods`.
"""

# fastmath without the no-NaN / no-Inf assumptions: the kernels test for NaN (beams without
# a range, footprints off the map), which full fastmath would silently compile away; and
# without "reassoc": with it, LLVM re-associates sums by the position of their operands in
# the compiled code, so the same formula gave other last bits when a kernel was restructured
# or inlined elsewhere (e.g. the filter loops' fused passes, docs/speed.md). Without it a
# kernel's numbers follow from its source expressions (plus FMA contraction); it cost no
# measurable speed.
FASTMATH = {"contract", "arcp", "nsz", "afn"}
