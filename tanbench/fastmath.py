"""The fastmath flags of every numba kernel (the filters' and the map look-ups in ``terrain/grid.py``).

A base-layer module so that the terrain layer can use them without importing the filters.
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
