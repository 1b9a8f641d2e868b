"""Parameter bundles of the jitted filter loops (named tuples numba passes by value).

The loops take a handful of these instead of dozens of positional numbers; each bundle
groups the settings of one mechanism, named as in ``FilterSpec``. ``MapArgs`` is the
navigation map as the grid-based estimators read it (``Map.kernel_args()``); the particle
filters read it as a ``terrain.grid.CellGrid``.
"""

from __future__ import annotations

from collections import namedtuple

from tanbench.terrain.grid import MapArgs  # noqa: F401 - the map bundle, defined with the Map

# resampling when ESS < ess_threshold * M, then regularisation of ``cols`` with kernel
# ``kind`` of size ``size``; a horizontal cloud below ``min_spread`` m std is re-spread
Resampling = namedtuple("Resampling", "scheme ess_threshold kind cols size min_spread")

# divergence: the best particle's RMS innovation above ``sigma`` for ``steps`` updates; the
# tight filter's re-draw (``recovery``, options.RECOVERY: 0 around its own estimate, 1 around the
# last healthy estimate moved on by dead reckoning, filters/recovery.py) over a square whose
# half side grows by ``growth`` m per second since that estimate, up to ``max_half`` m
Divergence = namedtuple("Divergence", "sigma steps recovery growth max_half", defaults=(0, 0.0, 0.0))

# tight filter: process noise (east/north per update, up, attitude), distance innovation
# mode and std, altitude std, innovation charged to a beam off the map, and the gyro biases
# random walk per update (rad/s; 0: none, Table 2; filters/bias_walk.py)
TightModel = namedtuple("TightModel", "sig_pos sig_up sig_att dist_mode sig_d sig_u outside_sigma sig_bias",
                        defaults=(0.0,))

# tight filter initial cloud (and re-initialisation): uniform square of side 2 * half_side,
# Gaussian up, attitude, heading and gyro biases
TightPrior = namedtuple("TightPrior", "half_side std_up std_att std_yaw std_bias")

# loose filter: position process noise, heading-induced cross-track noise, altitude std,
# off-map innovation, and the horizontal std below which its estimate is a position fix
LooseModel = namedtuple("LooseModel", "sig_pos sig_heading sig_u outside_sigma converged_std")

# the paper-as-written readings (docs/model.md section 10): propagation code (options.PROPAGATION; non-zero = one
# Euler step of Eq. 1 over ``dt`` on the Euler inputs), horizontal std of a Gaussian initial cloud (0 = the uniform
# square), whether a diverged filter is reinitialised, and the horizontal std below which a resampled cloud is
# redrawn with its initial spread (0 = never; the Resampling bundle's min_spread re-spreads instead)
Readings = namedtuple("Readings", "propagation dt cloud_std div_reinit collapse_spread")

# measurement model (filters/likelihood.py): the map-aware density (``mapaware``: the beam
# variance includes the map's variance grid, whose coefficients then follow the map's in the
# loop's cell table, terrain.grid.cell_grid), the beam density code (``kind``,
# options.LIKELIHOOD) and the Student-t degrees of freedom ``nu``
Likelihood = namedtuple("Likelihood", "mapaware kind nu")

# divergence guards: a horizontal cloud std above ``spread_limit`` m (once converged) counts
# as a bad update; a cloud std below ``healthy_std`` with a good fit is "healthy" (recovery
# statistics); the estimate is kept in ``bounds`` (e_min, e_max, n_min, n_max), off if e_min > e_max
Guard = namedtuple("Guard", "spread_limit healthy_std bounds")

# the closed-loop loose TAN's navigation KF (navigation/eskf.py): process noise std per
# update (position, heading, z-gyro bias), a fix every ``fix_every`` updates, chi-square
# gate, std added to a fix, the weakest terrain-only fix used, and the gate rejections in
# a row after which the KF is reopened
LooseKalman = namedtuple("LooseKalman", "q_pos q_yaw q_bias fix_every gate r_floor fix_max_std misses")
