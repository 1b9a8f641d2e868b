"""Unit conversions the specs, sensors and filters share (plain Python, no numerical imports)."""

from __future__ import annotations

import math

DEG_PER_H = math.pi / 180.0 / 3600.0  # rad/s
DEG_PER_SQRT_H = math.pi / 180.0 / 60.0  # rad/sqrt(s)
