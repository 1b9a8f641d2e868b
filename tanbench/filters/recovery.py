"""Where a diverged tight filter re-draws its cloud (issue 24, "never lost").

Divergence is detected from the filter's own quantities only (``filters/tight.py``: the
best particle's innovation statistic above ``filter.divergence_sigma`` for
``filter.divergence_steps`` updates, or a converged cloud spreading beyond
``filter.divergence_spread_m``); never from the truth. The built-in re-draws the initial
square around the diverged filter's own estimate, which by then has wandered with the
wrong cloud (docs/filters.md 4.3: two R2 runs re-drawn eleven times around their own wrong
estimate). With ``filter.recovery: last-healthy`` the square is centred on the last
*healthy* estimate (cloud std below ``filter.loose_converged_std_m`` and a good fit; the
loop's ``healthy`` series) moved on by the navigation system's dead-reckoned displacement
since then, and its half side grows from the initial one by ``filter.recovery_growth_mps``
per second since that estimate (the dead-reckoning error grows), up to
``filter.recovery_max_side_m`` / 2. Without a healthy estimate yet, the built-in's centre.
"""

from __future__ import annotations

import numba as nb

from tanbench.options import RECOVERY

RECOVER_AT_ESTIMATE, RECOVER_LAST_HEALTHY = RECOVERY["estimate"], RECOVERY["last-healthy"]


@nb.njit(cache=True)
def recovery_square(mode, est_e, est_n, healthy_e, healthy_n, dr_e, dr_n, elapsed_s, half_side, growth, max_half):
    """(centre east, centre north, half side) of the re-draw.

    ``est_*``: the diverged filter's estimate; ``healthy_*``: the last healthy estimate (NaN:
    none yet); ``dr_*``: the navigation displacement since it; ``elapsed_s`` the time since it."""
    if mode != RECOVER_LAST_HEALTHY or not (healthy_e == healthy_e):
        return est_e, est_n, half_side
    half = min(max(half_side + growth * elapsed_s, half_side), max(max_half, half_side))
    return healthy_e + dr_e, healthy_n + dr_n, half


def recovery_square_numpy(mode, est_e, est_n, healthy_e, healthy_n, dr_e, dr_n, elapsed_s, half_side, growth,
                          max_half):
    """Plain-Python reference of :func:`recovery_square`."""
    import math

    if mode != RECOVER_LAST_HEALTHY or math.isnan(healthy_e):
        return est_e, est_n, half_side
    half = min(max(half_side + growth * elapsed_s, half_side), max(max_half, half_side))
    return healthy_e + dr_e, healthy_n + dr_n, half
