"""Pressure depth sensor: depth with white noise of a percentage of full scale (Table 1: 0.01 %)."""

from __future__ import annotations

import numpy as np

from tanbench.numpy_stream import standard_normal


def measure_depth(up: np.ndarray, error_percent: float, full_scale_m: float, rng) -> np.ndarray:
    """Pressure-sensor depth (positive down), m: white noise of error_percent of full scale."""
    return -up + (error_percent / 100.0) * full_scale_m * standard_normal(rng, up.shape)
