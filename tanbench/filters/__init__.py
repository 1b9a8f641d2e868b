"""Numerical kernels of the particle filters: propagation, likelihood, resampling, estimates.

Jitted functions on plain arrays (each with a plain-numpy reference in the tests); the
methods that assemble them into TAN filters are in :mod:`tanbench.methods`.
"""

# fastmath without the no-NaN / no-Inf assumptions: the kernels test for NaN (beams without
# a range, footprints off the map), which full fastmath would silently compile away; and
# without "reassoc" and "contract": with them LLVM re-associates sums and fuses a*b + c*d
# into an FMA on one product or the other depending on where the operands sit in the
# compiled code, so the same formula gave other last bits once a kernel was restructured or
# inlined elsewhere. Without them a kernel's numbers follow from its source expressions:
# the particle passes run block by block equal the kernels run on the whole cloud, bit for
# bit (tests/test_particle_passes.py),
# and sums that should vectorise are written over four accumulators in a fixed order
# (resample.sum4), which gives the same bits whatever the SIMD width (docs/speed.md).
FASTMATH = {"arcp", "nsz", "afn"}
