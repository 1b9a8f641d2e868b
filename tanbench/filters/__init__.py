"""Numerical kernels of the particle filters: propagation, likelihood, resampling, estimates.

Jitted functions on plain arrays (each with a plain-numpy reference in the tests); the
methods that assemble them into TAN filters are in :mod:`tanbench.methods`.
"""

# fastmath without the no-NaN / no-Inf assumptions: the kernels test for NaN (beams without
# a range, footprints off the map), which full fastmath would silently compile away; and
# without "reassoc" and "contract": with them LLVM re-associates sums and fuses a*b + c*d
# into an FMA on one product or the other depending on where the operands sit in the
# compiled code, so the same formula gave other last bits once a kernel was restructured or
# inlined elsewhere (the filter loops' fused passes, docs/speed.md). Without them a kernel's
# numbers follow from its source expressions, and the fused passes equal the array kernels
# bit for bit (tests/test_fused_passes.py). Dropping FMA contraction cost the tight loop about
# 5-8 % (docs/speed.md); re-associated sums cost nothing measurable.
FASTMATH = {"arcp", "nsz", "afn"}
