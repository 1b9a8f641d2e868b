"""Option codes: the one table of every enumerated setting's allowed values and kernel codes.

``tanbench.config`` builds its ``Literal`` types from these tables and the jitted kernels
take the integer codes, so an allowed value and its code are written down once. Plain
Python, no numerical imports (``config`` imports it).
"""

from __future__ import annotations

from typing import Literal

# the largest root or run seed: results store seeds as 64-bit signed integers (Parquet int64)
MAX_SEED = 2**63 - 1

RESAMPLING = {"systematic": 0, "multinomial": 1, "stratified": 2, "residual": 3}
REGULARISATION = {"none": 0, "liu-west": 1, "gordon": 2}
# the tight filters' regularisation: the shared ``regularisation`` / ``min_spread_m``, or the posterior-sized kernel
# (filters/posterior.py; kernel code REG_POSTERIOR there, after REGULARISATION's)
TIGHT_REGULARISATION = ("shared", "posterior")
GYRO_BIAS_NOISE = ("none", "data-sheet")
# the likelihood's range noise: Table 2's altitude sigma, or the sonar's data sheet (noise_m's uniform std)
RANGE_NOISE = ("table-2", "data-sheet")
# the map-aware likelihood's representation term: nearest-node slope term, or bilinear interpolation's own error
MAP_REPRESENTATION = ("slope", "bilinear")
# where the tight filter re-draws a diverged cloud (filters/recovery.py; global: filters/relocalise.py)
RECOVERY = {"estimate": 0, "last-healthy": 1, "global": 2}
# where the global recovery searches: around the diverged filter's estimate only, or, when that match is refused,
# also around the navigation solution (always, or only when it lies outside the first square; filters/relocalise.py)
RECOVERY_SEARCH_AROUND = ("estimate", "estimate-then-navigation", "estimate-then-distant-navigation")
# the candidates a second square's match must stand out from (filters/relocalise.py; docs/filters.md 19)
RECOVERY_SECOND_AMBIGUITY = ("its-square", "both-squares")
DISTANCE_INNOVATION = {"none": 0, "particle": 1, "navigation": 2}
LIKELIHOOD = {"student-t": 1, "gaussian": 0}  # beam density of the map-aware kernels (filters/likelihood.py)
LOOSE_ARCHITECTURE = ("kalman-feedback", "fix-only")
# what the loose TAN does with a terrain-only fix that fails filter.loose_fix_prior_gate (docs/filters.md 9.1)
LOOSE_FIX_PRIOR_FALLBACK = ("refuse", "posterior")
# what the loose TAN's first fix after a (re)initialisation sets the KF's position to (docs/filters.md 13)
LOOSE_FIRST_FIX = ("terrain-only", "posterior")
# the heading a loose TAN's KF keeps when it is reopened after rejected fixes (docs/filters.md 14)
LOOSE_REOPEN_HEADING = ("navigation", "cloud")
# what a reopened loose-TAN KF does with a fix it still rejects: nothing, or take its position (docs/filters.md 15)
LOOSE_REOPEN_POSITION = ("prior", "fix")
# which tight-filter states the regularisation jitters (state indices in filters/tight.py)
REGULARISED_STATES = ("position-heading-biases", "heading-biases", "biases")


def choices(values):
    """A ``Literal`` of a table's names (a dict's keys or a tuple), in table order."""
    return Literal[tuple(values)]
# the paper-as-written readings (docs/model.md section 10); kernels test PROPAGATION != exact for the Euler step
PROPAGATION = {"exact": 0, "euler-last-second": 1, "euler-last-sample": 2, "euler-interval-start": 3}
POSITION_NOISE_GROWTH = ("linear", "sqrt")
LIKELIHOOD_R = ("per-component", "scalar-norm", "scalar-determinant")
INITIAL_CLOUD = ("uniform", "gaussian")
COLLAPSE_REINIT = ("respread", "initial")
# the multibeam's beam spacing across the fan (sensors/multibeam.py)
MULTIBEAM_PATTERN = ("equiangular", "equidistant")
# how the multibeam methods thin the swath (methods/multibeam.py): every k-th beam, or the most informative
MULTIBEAM_SELECTION = ("every-kth", "information")
