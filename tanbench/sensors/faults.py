"""Everyday faults of the world at sea (``Scenario.faults``; docs/model.md, Section 4.1).

All are off by default, and off they change nothing: every fault that needs random
numbers draws them from its own named stream of the run's ``SeedSequence``
(``simulation.STREAM_*``), so the other streams' numbers stay the same.

* **tide / depth bias**: the pressure depth is referred to the actual sea surface, the
  map to a chart datum; their difference is a constant (datum, atmospheric pressure,
  density) plus a slow tide, b(t) = bias + A sin(2 pi t / P + phi) with a random phase
  (Hagen et al. 2011 and the TRN literature list the tide as an error of the terrain
  profile; the M2 period, 12.42 h, is the default);
* **ocean current**: a constant current (east, north) sets the vehicle off its plan: the
  true path is the plan plus current x time; the DVL, locked on the bottom, measures
  velocity over ground, so the drift is in its velocity (in the body frame);
* **bottom-lock dropouts**: runs of pings without bottom lock (steep slopes, high
  altitude, aeration): a dropout starts at a ping with probability ``rate`` and lasts a
  geometric number of pings of mean ``mean_pings``; during it the DVL gives no ranges
  and the navigation holds its last velocity;
* **range outliers**: a fraction of the ranges is replaced by a wild value uniform on
  [0, max range] (fish, bubbles, multipath, side-lobe returns);
* **sound-speed scale error**: ranges are times of flight scaled by an assumed sound
  speed; a sound-speed error s scales every range by (1 + s) (1 % is 15 m/s, a common
  error without a sound-velocity profile).
"""

from __future__ import annotations

import math

import numpy as np

from tanbench.vehicle.attitude import dcm_body_to_nav_numpy


def tide_offset(t: np.ndarray, bias_m: float, amplitude_m: float, period_s: float, phase: float) -> np.ndarray:
    """Depth-reference error at times ``t``: bias + amplitude sin(2 pi t / period + phase)."""
    return bias_m + amplitude_m * np.sin(2.0 * math.pi * t / period_s + phase)


def add_current(truth, current_en) -> None:
    """Set ``truth`` (a :class:`~tanbench.vehicle.trajectory.Truth`) off its plan in place:
    position + current x t, body velocity + the current in the body frame."""
    ve, vn = float(current_en[0]), float(current_en[1])
    t = truth.t - truth.t[0]
    truth.pos[:, 0] += ve * t
    truth.pos[:, 1] += vn * t
    c_bn = dcm_body_to_nav_numpy(truth.pitch, truth.roll, truth.yaw)
    truth.vel_body[:] = truth.vel_body + np.einsum("kji,j->ki", c_bn, np.array([ve, vn, 0.0]))


def dropout_mask(pings: int, rate: float, mean_pings: float, rng) -> np.ndarray:
    """Boolean (pings,) True on pings without bottom lock: dropouts start with probability
    ``rate`` per ping and last Geometric(1 / mean_pings) pings."""
    lost = np.zeros(pings, dtype=bool)
    if rate <= 0:
        return lost
    starts = np.nonzero(rng.random(pings) < rate)[0]
    lengths = rng.geometric(1.0 / mean_pings, starts.size)
    for s, n in zip(starts, lengths):
        lost[s:s + n] = True
    return lost


def add_outliers(ranges: np.ndarray, fraction: float, max_range: float, rng) -> np.ndarray:
    """``ranges`` with a ``fraction`` of the measured ones replaced by uniform [0, max_range]."""
    if fraction <= 0:
        return ranges
    wild = rng.random(ranges.shape) < fraction
    values = rng.uniform(0.0, max_range, ranges.shape)
    return np.where(wild & ~np.isnan(ranges), values, ranges)


def map_offset_positions(pos: np.ndarray, east_m: float, north_m: float) -> np.ndarray:
    """Positions at which to read a map whose seafloor lies (east, north) metres off: pos - offset."""
    if not east_m and not north_m:
        return pos
    return pos - np.array([east_m, north_m, 0.0])


def delay_pings(ranges: np.ndarray, pings: int) -> np.ndarray:
    """``ranges`` (pings, beams) reported ``pings`` pings late: row k holds row k - pings, NaN before."""
    out = np.full_like(ranges, np.nan)
    if pings < ranges.shape[0]:
        out[pings:] = ranges[:ranges.shape[0] - pings]
    return out


def far_start_offset(fraction: float, distance_m: float, rng) -> np.ndarray:
    """(east, north) offset of the navigation's start: ``distance_m`` in a random direction with
    probability ``fraction``, else zero (two draws from ``rng`` either way)."""
    u, heading = rng.random(), rng.uniform(0.0, 2.0 * math.pi)
    if u >= fraction:
        return np.zeros(2)
    return distance_m * np.array([math.cos(heading), math.sin(heading)])
