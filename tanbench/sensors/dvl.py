"""DVL velocity: body-frame velocity with a scale-factor error and white noise (Table 1).

"+-0.4 % +-0.2 cm/s": a scale-factor error drawn uniformly in +-0.4 % once per run, plus
white noise of 0.2 cm/s (1 sigma) per axis on each ping. Measured at the sonar ping
rate and held between pings, as a navigation computer holds the latest DVL fix.
"""

from __future__ import annotations

import numpy as np

from tanbench.numpy_stream import standard_normal


def measure_velocity(vel_body: np.ndarray, ping_index: np.ndarray, scale_error: float,
                     noise_mps: float, rng, lost: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Held DVL velocity at every IMU sample (n, 3), and the scale error drawn.

    ``lost`` (pings,) marks pings without bottom lock (a world fault): the last velocity
    measured before them is held through them (the first ping is always kept).
    """
    scale = rng.uniform(-1.0, 1.0) * scale_error
    pings = vel_body[ping_index] * (1.0 + scale) + noise_mps * standard_normal(rng, (ping_index.size, 3))
    if lost is not None:
        valid = ~lost
        valid[0] = True
        last_valid = np.maximum.accumulate(np.where(valid, np.arange(ping_index.size), 0))
        pings = pings[last_valid]
    held_from = np.searchsorted(ping_index, np.arange(vel_body.shape[0]), side="right") - 1
    return pings[np.clip(held_from, 0, None)], scale
