"""The three TAN methods: tightly coupled PF with DVL or SBE beams, loosely coupled PF."""

METHODS = ("tight-dvl", "tight-sbe", "loose-dvl")

# fastmath without the no-NaN / no-Inf assumptions: the kernels test for NaN (beams without
# a range, footprints off the map), which full fastmath would silently compile away.
FASTMATH = {"contract", "arcp", "nsz", "reassoc", "afn"}

