"""The initial horizontal cloud read as a Gaussian (``filter.initial_cloud: gaussian``).

Section 4.3 says the initial distribution is uniform over 150 m x 150 m (the default,
drawn by ``init_tight`` / ``init_loose``); Table 2's initial covariance
``diag(150 m, 150 m, ...)^2`` can also be read as a Gaussian with a 150 m standard
deviation. This kernel redraws the east and north columns that way.
"""

from __future__ import annotations

import numba as nb


@nb.njit(cache=True)
def gaussian_horizontal(x, rng, centre_e, centre_n, std):
    """Replace columns 0, 1 (east, north) of ``x`` by N(centre, std^2) draws, east then north per row."""
    for j in range(x.shape[0]):
        x[j, 0] = centre_e + std * rng.standard_normal()
        x[j, 1] = centre_n + std * rng.standard_normal()


def gaussian_horizontal_numpy(x, normals, centre_e, centre_n, std):
    """Plain-numpy reference: ``normals`` (M, 2) are the standard normals the kernel would draw."""
    x = x.copy()
    x[:, 0] = centre_e + std * normals[:, 0]
    x[:, 1] = centre_n + std * normals[:, 1]
    return x
