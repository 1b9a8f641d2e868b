"""IMU error model (Table 1): gyros and accelerometers at the IMU rate.

Each axis' error is: a turn-on bias, constant over the run, drawn uniformly in
+-spec (Table 1 prints it as "+-30 deg/h", "+-50 mg"); an in-run bias following a
first-order Gauss-Markov process with steady-state std ``instability`` and
correlation time ``tau``; and white noise. White noise of density ND (deg/sqrt(h)
for the gyro's angle random walk, mg/sqrt(Hz) for the accelerometer) gives a
per-sample std ND * sqrt(rate) in rate units (ND / sqrt(dt)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np

from tanbench.numpy_stream import standard_normal
from tanbench.units import DEG_PER_H, DEG_PER_SQRT_H  # noqa: F401 - re-exported for the sensors

MG = 9.80665e-3  # m/s^2


@dataclass
class ImuErrors:
    """The drawn error processes: biases per sample, (n, 3) each, and the turn-on parts (3,)."""

    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    gyro_turn_on: np.ndarray
    accel_turn_on: np.ndarray


@nb.njit(cache=True)
def first_order_recursion(w: np.ndarray, a: float) -> np.ndarray:
    """y[0] = w[0], y[k] = w[k] + a y[k-1], down the rows of ``w`` (n, axes): the same
    operations, so the same bits, as ``scipy.signal.lfilter([1], [1, -a], w, axis=0)``
    (:func:`first_order_recursion_numpy`), without importing scipy.signal (2-3 s)."""
    y = np.empty_like(w)
    n, axes = w.shape
    if n == 0:
        return y
    for j in range(axes):
        y[0, j] = w[0, j]
    for k in range(1, n):
        for j in range(axes):
            y[k, j] = w[k, j] + a * y[k - 1, j]
    return y


def first_order_recursion_numpy(w: np.ndarray, a: float) -> np.ndarray:
    """Reference of :func:`first_order_recursion`: scipy's IIR filter."""
    from scipy.signal import lfilter

    return lfilter([1.0], [1.0, -a], w, axis=0)


def gauss_markov(n: int, dt: float, sigma: float, tau: float, rng, axes: int = 3) -> np.ndarray:
    """First-order Gauss-Markov samples (n, axes), stationary from the start."""
    a = math.exp(-dt / tau)
    w = standard_normal(rng, (n, axes)) * sigma * math.sqrt(1.0 - a * a)
    w[0] = standard_normal(rng, axes) * sigma
    return first_order_recursion(w, a)


def measure_imu(omega_ib, f_body, dt, sensors, rng):
    """Gyro (rad/s) and accelerometer (m/s^2) outputs and the errors drawn, (n, 3) each."""
    n = omega_ib.shape[0]
    rate = 1.0 / dt
    g_turn_on = rng.uniform(-1, 1, 3) * sensors.gyro_turn_on_bias_deg_h * DEG_PER_H
    g_in_run = gauss_markov(n, dt, sensors.gyro_bias_instability_deg_h * DEG_PER_H,
                            sensors.gyro_bias_corr_time_s, rng)
    g_noise = standard_normal(rng, (n, 3)) * sensors.gyro_arw_deg_sqrt_h * DEG_PER_SQRT_H * math.sqrt(rate)
    a_turn_on = rng.uniform(-1, 1, 3) * sensors.accel_turn_on_bias_mg * MG
    a_in_run = gauss_markov(n, dt, sensors.accel_bias_instability_mg * MG, sensors.accel_bias_corr_time_s, rng)
    a_noise = standard_normal(rng, (n, 3)) * sensors.accel_noise_mg_sqrt_hz * MG * math.sqrt(rate)
    gyro_bias = g_turn_on + g_in_run
    accel_bias = a_turn_on + a_in_run
    gyro = omega_ib + gyro_bias + g_noise
    accel = f_body + accel_bias + a_noise
    return gyro, accel, ImuErrors(gyro_bias=gyro_bias, accel_bias=accel_bias, gyro_turn_on=g_turn_on,
                                  accel_turn_on=a_turn_on)
