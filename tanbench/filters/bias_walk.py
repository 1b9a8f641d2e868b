"""The tight filter's gyro-bias random walk (issue 24, docs/filters.md section 5 item 1).

Table 2 gives the gyro biases no process noise, so every particle holds its biases
constant, while a real gyro's in-run bias wanders (the simulated one is a first-order
Gauss-Markov process, ``sensors.gyro_bias_instability_deg_h`` over
``sensors.gyro_bias_corr_time_s``). With ``filter.gyro_bias_noise: data-sheet`` both bias
states random-walk between updates with the std per update that keeps such a process at
its data-sheet std, sigma sqrt(2 T / tau) (:func:`gauss_markov_walk_std`; the loose TAN's
Kalman filter uses the same), and the bound (``bounds/pcrb.transition``) follows.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.state import BX, BZ
from tanbench.units import DEG_PER_H


def gauss_markov_walk_std(sigma: float, corr_time_s: float, interval_s: float) -> float:
    """Std per interval of the random walk that keeps a first-order Gauss-Markov process of
    std ``sigma`` and correlation time ``corr_time_s`` at its std: sigma sqrt(2 T / tau)."""
    return sigma * math.sqrt(2.0 * interval_s / corr_time_s)


def tight_bias_walk_std(scenario) -> float:
    """rad/s per update of ``filter.gyro_bias_noise`` (0 for ``none``)."""
    if scenario.filter.gyro_bias_noise == "none":
        return 0.0
    s = scenario.sensors
    return gauss_markov_walk_std(s.gyro_bias_instability_deg_h * DEG_PER_H, s.gyro_bias_corr_time_s,
                                 scenario.sampling_time_s)


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def walk_biases(x, noise_bx, noise_bz, sig_bias, lo=0):
    """Particles ``lo .. lo + n - 1`` of ``x`` (8, M): both gyro biases += ``sig_bias`` * noise
    (``noise_bx``, ``noise_bz``: n standard normals each)."""
    n = noise_bx.shape[0]
    bx = x[BX, lo:lo + n]
    bz = x[BZ, lo:lo + n]
    for j in range(n):
        bx[j] += sig_bias * noise_bx[j]
        bz[j] += sig_bias * noise_bz[j]


def walk_biases_numpy(x, noise_bx, noise_bz, sig_bias):
    """Plain-numpy reference of :func:`walk_biases` on the whole cloud (returns a new array)."""
    x = np.array(x, dtype=float)
    x[BX] += sig_bias * np.asarray(noise_bx)
    x[BZ] += sig_bias * np.asarray(noise_bz)
    return x
