"""Progressive correction (likelihood tempering) of a very informative update (issue 24,
docs/filters.md section 5 item 4).

When one update's likelihood would leave fewer than ``target`` effective particles, the
update is applied in stages: the log-weights take a share lambda of the log-likelihood
chosen so that the effective sample size falls to ``target`` and no lower, the cloud is
resampled and regularised (the moved particles then sit where the partial posterior is),
the log-likelihood is computed again at the moved particles, and the next stage takes its
share of what remains. The last stage (``filter.tempering_stages``) takes whatever remains,
so the shares add up to one whole update (Musso, Oudjane & Le Gland 2001, progressive
correction; Oudjane & Musso 2000). A stage resamples whatever its ESS, which is what moves
the cloud towards the likelihood's peak before the full weight is applied.

Kernels: :func:`tempered_ess` (the ESS of ``logw + lambda ll``) and
:func:`tempering_fraction` (bisection on lambda, 30 halvings of the remaining share), each
with a plain-numpy reference (``*_numpy``) the tests check. The stages themselves run inside
the tight loop (``filters/tight.py``), which owns the likelihood pass.

The ESS need not fall monotonically in lambda when the log-weights carried into the update
are not uniform; the bisection then returns the largest lambda it saw keep the target, one of
possibly several crossings. With uniform log-weights it is monotone.
"""

from __future__ import annotations

from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.resample import exp_weights, max_log_weight, sum_sq4

HALVINGS = 30

# the loop's tempering settings: at most ``stages`` stages per update (1: no tempering, the neutral
# value), each down to an ESS of ``ess_fraction`` * M; ``rs`` the stages' Resampling bundle (the
# filter's own, with an ESS threshold that always resamples)
Tempering = namedtuple("Tempering", "stages ess_fraction rs")

ALWAYS = 2.0  # an ESS threshold (times M) every cloud is below: a stage always resamples


def tempering_of(f, rs) -> Tempering:
    """The :class:`Tempering` bundle of a ``FilterSpec`` ``f`` whose updates end with the
    Resampling bundle ``rs``: ``filter.tempering_ess`` 0 (the default) is one stage, no tempering."""
    stages = int(f.tempering_stages) if f.tempering_ess > 0.0 else 1
    return Tempering(stages, float(f.tempering_ess), rs._replace(ess_threshold=ALWAYS))


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _tempered(logw, ll, lam, out):
    for j in range(logw.shape[0]):
        out[j] = logw[j] + lam * ll[j]


@nb.njit(cache=True)
def tempered_ess(logw, ll, lam, work):
    """The effective sample size (sum w)^2 / sum w^2 of the weights exp(``logw`` + ``lam`` ``ll``);
    ``work`` (M,) is overwritten."""
    _tempered(logw, ll, lam, work)
    mx = max_log_weight(work)
    total = exp_weights(work, mx, work)
    return total * total / sum_sq4(work)


def tempered_ess_numpy(logw, ll, lam):
    """Plain-numpy reference of :func:`tempered_ess`."""
    t = np.asarray(logw) + lam * np.asarray(ll)
    w = np.exp(t - t.max())
    return float(w.sum() ** 2 / (w * w).sum())


@nb.njit(cache=True)
def tempering_fraction(logw, ll, remaining, target, work):
    """The share of ``remaining`` the next stage takes: ``remaining`` itself if the whole of it keeps
    an ESS of at least ``target`` (a count, not a fraction of M), else the largest lambda in
    [0, remaining) the bisection (:data:`HALVINGS` halvings) finds whose ESS is still at least
    ``target`` (0 if none). ``work`` (M,) is overwritten."""
    if tempered_ess(logw, ll, remaining, work) >= target:
        return remaining
    lo, hi = 0.0, remaining
    for _ in range(HALVINGS):
        mid = 0.5 * (lo + hi)
        if tempered_ess(logw, ll, mid, work) >= target:
            lo = mid
        else:
            hi = mid
    return lo


def tempering_fraction_numpy(logw, ll, remaining, target):
    """Plain-numpy reference of :func:`tempering_fraction`."""
    if tempered_ess_numpy(logw, ll, remaining) >= target:
        return remaining
    lo, hi = 0.0, remaining
    for _ in range(HALVINGS):
        mid = 0.5 * (lo + hi)
        if tempered_ess_numpy(logw, ll, mid) >= target:
            lo = mid
        else:
            hi = mid
    return lo
