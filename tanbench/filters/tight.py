"""Tightly coupled TAN (Section 3, Algorithm 1): the 8-state particle filter loop.

The loop is jitted end to end and composed of the kernels in ``propagate``,
``likelihood``, ``resample`` and ``estimate``; particles are the columns of ``x`` (8, M),
each kernel a pass over them that compiles to SIMD instructions; random numbers come in
blocks from the generator ``filters/rng.py`` gives the loop. Per update k:

1. propagate every particle over the interval (Eq. 1; skipped at k = 0);
2. weight by the terrain altitude innovations of the beams and the distance
   innovations (Eq. 20), accumulating log-weights; with progressive correction
   (``filter.tempering_ess``, ``filters/tempering.py``) an update that would leave too few
   effective particles is applied in stages, each resampled, regularised and weighed again;
3. record the MMSE estimate and the weighted variances;
4. if the best particle's mean squared normalised innovation stays above
   ``div_sigma^2`` for ``div_steps`` updates, the filter has diverged: reinitialise the
   cloud with the initial spread, positions around the estimate and headings around
   the navigation heading (a diverged filter's own heading is not trusted; the
   paper's Section 3.3);
5. resample when ESS < ``ess_thr * M``, then regularise: jitter position, heading and the
   gyro biases with a mean- and variance-preserving kernel (``resample.regularise``), so
   duplicated particles spread out again; if the horizontal cloud has nevertheless
   collapsed below ``min_spread`` metres, re-spread it (the paper's reinitialisation of a
   too-small cloud).

The loop's settings are the bundles below, each built from the scenario's ``FilterSpec``
by one constructor beside it (:func:`tight_settings` gathers them; the defaults live in the
spec only); the navigation solution at the updates comes in one :class:`TightTrack`.

The paper-as-written readings (``readings``, a :class:`Readings`;
docs/model.md section 10): a non-zero ``propagation`` moves the particles with one Euler
step of Eq. 1 over ``dt`` on ``euler_in`` instead of the exact increments; ``cloud_std``
> 0 draws (and redraws) the horizontal cloud as a Gaussian of that std instead of the
uniform square; ``div_reinit`` False never reinitialises a diverged filter;
``collapse_spread`` > 0 redraws a resampled cloud whose horizontal std is below it with
the initial spread around the estimate (the whole state, as a divergence does).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numba as nb
import numpy as np

from tanbench.filters import FASTMATH
from tanbench.filters.cloud import gaussian_horizontal, uniform_horizontal
from tanbench.filters.estimate import weighted_estimate
from tanbench.filters.likelihood import (BLOCK, beam_constants, beam_vectors, likelihood_of, loglik_tight_pass,
                                        new_likelihood_work, work_block)
from tanbench.filters.bias_walk import tight_bias_walk_std, walk_biases
from tanbench.filters.kld import KLD_Z, bin_table, kld_count, kld_of, occupied_bins
from tanbench.filters.posterior import REG_POSTERIOR, resample_posterior, resample_posterior_into
from tanbench.filters.propagate import DIST_NAVIGATION, propagate_tight, propagate_tight_euler
from tanbench.filters.recovery import recovery_square
from tanbench.filters.relocalise import relocalise_around, relocaliser
from tanbench.filters.resample import (Resampling, _add_scaled, _shift_log_weights, add_log_weights, max_log_weight,
                                      normalise_with_ess, resample_and_regularise, resampling_of)
from tanbench.filters.rng import fill_normals, rng_state, set_rng_state
from tanbench.filters.tempering import tempering_fraction, tempering_of
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.filters.trig import attitude_reference
from tanbench.navigation.increments import D0E, D0N
from tanbench.options import DISTANCE_INNOVATION, PROPAGATION, RECOVERY
from tanbench.units import DEG_PER_H

REGULARISED_STATES = {
    "position-heading-biases": np.array([E, N, YAW, BX, BZ], dtype=np.int64),
    "heading-biases": np.array([YAW, BX, BZ], dtype=np.int64),
    "biases": np.array([BX, BZ], dtype=np.int64),
}

# ---- the loop's bundles (named tuples numba passes by value), each with its constructor ----
# divergence: the best particle's RMS innovation above ``sigma`` for ``steps`` updates; the
# re-draw (``recovery``, options.RECOVERY: 0 around the filter's own estimate, 1 around the last
# healthy estimate moved on by dead reckoning, filters/recovery.py) over a square whose half side
# grows by ``growth`` m per second since that estimate, up to ``max_half`` m
Divergence = namedtuple("Divergence", "sigma steps recovery growth max_half", defaults=(0, 0.0, 0.0))

# process noise (east/north per update, up, attitude), distance innovation mode and std,
# altitude std, innovation charged to a beam off the map, and the gyro biases' random walk per
# update (rad/s; 0: none, Table 2; filters/bias_walk.py)
TightModel = namedtuple("TightModel", "sig_pos sig_up sig_att dist_mode sig_d sig_u outside_sigma sig_bias",
                        defaults=(0.0,))

# initial cloud: uniform square of side 2 * half_side, Gaussian up, attitude, heading and gyro
# biases; a re-initialisation draws the square with half side ``reinit_half_side``
TightPrior = namedtuple("TightPrior", "half_side std_up std_att std_yaw std_bias reinit_half_side")

# the paper-as-written readings (docs/model.md section 10): propagation code (options.PROPAGATION;
# non-zero = one Euler step of Eq. 1 over ``dt`` on the Euler inputs), horizontal std of a Gaussian
# initial cloud (0 = the uniform square), whether a diverged filter is reinitialised, and the
# horizontal std below which a resampled cloud is redrawn with its initial spread (0 = never; the
# Resampling bundle's min_spread re-spreads instead)
Readings = namedtuple("Readings", "propagation dt cloud_std div_reinit collapse_spread")

# divergence guards: a horizontal cloud std above ``spread_limit`` m (once converged) counts as a
# bad update; a cloud std below ``healthy_std`` with a good fit is "healthy" (recovery statistics);
# the estimate is kept in ``bounds`` (e_min, e_max, n_min, n_max), off if e_min > e_max
Guard = namedtuple("Guard", "spread_limit healthy_std bounds")

# everything the loop is set with (``temper``: progressive correction, filters/tempering.py), and the
# navigation solution at the K updates: the (K-1, 12) increments, yaw, pitch, roll and up (K,) and the
# (K-1, 4) Euler-step inputs
TightSettings = namedtuple("TightSettings", "model rs div prior readings lik guard temper kld")
TightTrack = namedtuple("TightTrack", "inc yaw pitch roll up euler_in")
# what the loop fills: est/var (K, 8), cov_en, ess, reinit, healthy, the update's tempering stages and its
# particles (K,)
TightOutputs = namedtuple("TightOutputs", "est var cov_en ess reinit healthy stages particles")


def divergence_of(f) -> Divergence:
    return Divergence(f.divergence_sigma, f.divergence_steps, RECOVERY[f.recovery], float(f.recovery_growth_mps),
                      f.recovery_max_side_m / 2.0)


def readings_of(f, sampling_time_s: float) -> Readings:
    """The :class:`Readings` bundle of a ``FilterSpec`` (docs/model.md section 10)."""
    return Readings(PROPAGATION[f.propagation], float(sampling_time_s),
                    f.initial_area_m if f.initial_cloud == "gaussian" else 0.0, f.divergence_reinit,
                    f.min_spread_m if f.collapse_reinit == "initial" else 0.0)


def guard_of(f, nmap) -> Guard:
    """The :class:`Guard` bundle (spread divergence, keep on the map ``nmap``)."""
    bounds = np.array([nmap.e0, nmap.e_max, nmap.n0, nmap.n_max]) if f.keep_on_map else np.array([1.0, 0.0, 0.0, 0.0])
    spread = float(f.divergence_spread_m) if f.divergence_spread_m is not None else np.inf
    return Guard(spread, f.loose_converged_std_m, bounds)


def collapse_resampling_of(f, regularised_cols: np.ndarray) -> Resampling:
    """The Resampling bundle, without the re-spread when a collapsed cloud is redrawn instead."""
    rs = resampling_of(f, regularised_cols)
    return rs._replace(min_spread=0.0) if f.collapse_reinit == "initial" else rs


def tight_model_of(scenario) -> TightModel:
    f = scenario.filter
    sig_d, sig_u = scenario.measurement_sigmas_m
    return TightModel(scenario.position_noise_m(sig_d), f.process_noise_up_m, scenario.attitude_noise_rad,
                      DISTANCE_INNOVATION[f.distance_innovation], sig_d, sig_u, f.outside_map_sigma,
                      tight_bias_walk_std(scenario))


def tight_prior_of(f) -> TightPrior:
    reinit_area_m = f.initial_area_m if f.reinit_area_m is None else f.reinit_area_m
    return TightPrior(f.initial_area_m / 2.0, f.initial_std_up_m, math.radians(f.initial_std_pitch_roll_deg),
                      f.initial_std_heading_rad, f.initial_std_gyro_bias_deg_h * DEG_PER_H, reinit_area_m / 2.0)


def posterior_bandwidth_factor(f, beams: int) -> float:
    """The posterior kernel's factor on h_opt for a tight PF weighted by ``beams`` beams:
    ``filter.single_beam_regularisation_bandwidth`` for a single beam when it is set, else
    ``filter.regularisation_bandwidth`` (docs/filters.md 8)."""
    if beams == 1 and f.single_beam_regularisation_bandwidth is not None:
        return float(f.single_beam_regularisation_bandwidth)
    return float(f.regularisation_bandwidth)


def tight_resampling_of(f, beams: int = 4) -> Resampling:
    """The tight filters' Resampling bundle: the shared one, or the posterior-sized kernel
    (``filter.tight_regularisation``, filters/posterior.py; on the rows of ``filter.regularised_states``),
    its bandwidth by the filter's beam count (:func:`posterior_bandwidth_factor`); a single-beam
    filter resamples below ``filter.single_beam_ess_threshold`` when it is set.
    ``filter.regularisation: none`` switches the jitter off whichever kernel is chosen."""
    rs = collapse_resampling_of(f, REGULARISED_STATES[f.regularised_states])
    if beams == 1 and f.single_beam_ess_threshold is not None:
        rs = rs._replace(ess_threshold=float(f.single_beam_ess_threshold))
    if f.tight_regularisation == "posterior" and f.regularisation != "none":
        rs = rs._replace(kind=REG_POSTERIOR, size=posterior_bandwidth_factor(f, beams), min_spread=f.tight_min_spread_m)
    return rs


def tight_settings(scenario, nmap, beams: int = 4) -> TightSettings:
    """Every bundle of :func:`tight_filter_loop` from ``scenario`` and its navigation map ``nmap``,
    for a filter weighted by ``beams`` beams."""
    f = scenario.filter
    rs = tight_resampling_of(f, beams)
    return TightSettings(tight_model_of(scenario), rs, divergence_of(f), tight_prior_of(f),
                         readings_of(f, scenario.sampling_time_s), likelihood_of(f), guard_of(f, nmap),
                         tempering_of(f, rs), kld_of(f, scenario.particles))


def new_tight_outputs(k: int) -> TightOutputs:
    return TightOutputs(np.empty((k, N_TIGHT)), np.empty((k, N_TIGHT)), np.empty(k), np.empty(k),
                        np.zeros(k, dtype=np.int64), np.zeros(k, dtype=np.int64), np.ones(k, dtype=np.int64),
                        np.zeros(k, dtype=np.int64))


@nb.njit(cache=True, fastmath=FASTMATH, error_model="numpy")
def _shift_scale(row, centre, std):
    for j in range(row.shape[0]):
        row[j] = centre + std * row[j]


@nb.njit(cache=True)
def init_tight(x, rng, centre_e, centre_n, up, pitch, roll, yaw, prior):
    """Initial cloud (``x`` (8, M)): uniform square of side 2 * prior.half_side around
    (centre_e, centre_n), Gaussians else (``prior`` is a :class:`TightPrior`)."""
    draw_tight(x, rng, centre_e, centre_n, up, pitch, roll, yaw, prior, prior.half_side)


@nb.njit(cache=True)
def draw_tight(x, rng, centre_e, centre_n, up, pitch, roll, yaw, prior, half_side):
    """:func:`init_tight` with the uniform square's half side given (a re-initialisation's)."""
    uniform_horizontal(x, rng, centre_e, centre_n, half_side)
    fill_normals(rng, x[U:])
    _shift_scale(x[U], up, prior.std_up)
    _shift_scale(x[PITCH], pitch, prior.std_att)
    _shift_scale(x[ROLL], roll, prior.std_att)
    _shift_scale(x[YAW], yaw, prior.std_yaw)
    _shift_scale(x[BX], 0.0, prior.std_bias)
    _shift_scale(x[BZ], 0.0, prior.std_bias)


def loop_options(readings, rs) -> tuple[bool, bool]:
    """The rare parts the tight loop compiles for these settings (``Readings``, ``Resampling``):
    (the Euler step, the shared regularisation kernel). :func:`tight_filter_loop` passes their
    inputs as None otherwise, and ``tanbench.runner.plan.kernel_variant`` names a cell's compiled
    variant by them."""
    return readings.propagation != 0, rs.kind != REG_POSTERIOR


def tight_filter_loop(x, rng, track, ranges, beams, grid, settings, out, search=None):
    """Run the filter over all updates; fill the :class:`TightOutputs` ``out``.

    ``x`` (8, M) is the initial cloud, a column per particle; ``track`` the navigation
    solution at the updates (:class:`TightTrack`). ``out.cov_en`` is the cloud's weighted
    east/north covariance (``out.var`` holds the variances). ``grid`` is the navigation
    map's :class:`~tanbench.terrain.grid.NodeGrid` (with the variance grid interleaved for
    the map-aware likelihood); ``settings`` the :class:`TightSettings` (TightModel,
    Resampling, Divergence, TightPrior, Readings, Likelihood, Guard); ``track.euler_in`` the
    Euler-step inputs (used if ``readings.propagation``). A horizontal cloud std above
    ``guard.spread_limit``, once the cloud has converged since its last (re)initialisation,
    counts as a bad update like a poor fit; an estimate off ``guard.bounds`` is clamped into
    them and the cloud reinitialised there (:func:`keep_on_map`). ``healthy_out[k]`` is 1 when
    the cloud std is below ``guard.healthy_std`` and the best fit within half the divergence
    threshold.

    The particles' sines and cosines are taken about references near them (``trig``; they do
    not change the result): the propagation about the navigation heading at the interval
    start plus ``yaw_off``, the cloud's heading offset from the navigation at the last update
    (and, for the Euler step, about the navigation pitch and roll there); the beams about the
    navigation attitude with its yaw moved by the same offset.

    The jitted loop (:func:`_tight_loop`) takes the two options of the paper-as-written readings
    and of the shared regularisation as arguments that are None under the defaults: numba compiles
    every branch of a jitted body and prunes only the ones an argument's type (None) decides, so a
    run with the defaults (the exact increments, the posterior-sized kernel) compiles neither the
    Euler step nor the shared resampling kernel (docs/speed.md, "Compiling less"); a run that sets
    either compiles the loop once more, with both.

    ``search`` (``filters/relocalise.py``: :class:`GlobalSearch`, from ``global_search_of``; None unless
    ``filter.recovery: global``, the default): a diverged filter's cloud is re-drawn where a batch terrain
    match of its last updates puts the vehicle (:func:`tanbench.filters.relocalise.relocalise`), the
    built-in re-draw when the match is refused. Most runs never diverge, so the search is compiled only
    when a run needs it: the loop first runs without the search's bundle (None, as above: no part of the
    search compiles) and stops at the first update where it would search; only then is the run done again
    from its start, from the same cloud and random-number state (:func:`tanbench.filters.rng.rng_state`),
    with the bundle. The two passes draw the same numbers up to that update, so the run's result is the
    one a single pass with the bundle gives (tests/test_global_recovery.py); a diverging run pays its
    updates up to the first search twice, and the first such run in a process compiles the search
    (docs/speed.md, "The global search compiled on first need").
    """
    euler_step, shared_resampling = loop_options(settings.readings, settings.rs)
    euler_in = track.euler_in if euler_step else None
    shared_rs = settings.rs if shared_resampling else None
    if search is None:
        _tight_loop(x, rng, track, ranges, beams, grid, settings, out, None, euler_in, shared_rs, False)
        return
    state = rng_state(rng)  # the loop works on a copy of x, so only the random numbers need putting back
    if _tight_loop(x, rng, track, ranges, beams, grid, settings, out, None, euler_in, shared_rs, True) < 0:
        return
    set_rng_state(rng, state)
    reloc = relocaliser(search, track, beams, ranges, grid, settings.model.sig_u)
    _tight_loop(x, rng, track, ranges, beams, grid, settings, out, reloc, euler_in, shared_rs, False)


@nb.njit(cache=True)
def _tight_loop(cloud, rng, track, ranges, beams, grid, settings, out, reloc, euler_in, shared_rs, stop_to_search):
    """:func:`tight_filter_loop`, with ``reloc`` the global search's ``Relocalise`` bundle
    (``filter.recovery: global``) or None, ``euler_in`` the Euler-step inputs (``track.euler_in``) if
    ``readings.propagation`` asks for the Euler step, else None (the exact increments), and
    ``shared_rs`` the Resampling bundle if the shared kernel regularises
    (``resample.resample_and_regularise``), else None (the posterior-sized kernel). With
    ``stop_to_search`` (and ``reloc`` None) it returns at the first update where a diverged cloud would be
    searched for, before drawing anything there; returns that update, or -1 after the last one.

    The loop works on a copy of ``cloud`` (8, M): with an adaptive count (``settings.kld``, filters/kld.py) the
    cloud is the first ``mc`` particles, each array a contiguous view of the first ``mc`` entries of a buffer for M,
    and a resampling may draw another count; with the fixed count (the default) ``mc`` is M throughout."""
    inc, nav_yaw, nav_pitch, nav_roll, nav_up, _ = track
    model, rs, div, prior, readings, lik, guard, temper, kld = settings
    est, var, cov_en_out, ess_out, reinit_out, healthy_out, stages_out, particles_out = out
    m = cloud.shape[1]  # the most particles
    mc = m  # the cloud's particles now
    steps = ranges.shape[0]
    xbuf = np.empty(N_TIGHT * m)
    for c in range(N_TIGHT):
        for j in range(m):
            xbuf[c * m + j] = cloud[c, j]
    sbuf = np.empty(N_TIGHT * m)
    logw_buf = np.zeros(m)
    ll_buf = np.empty(m)
    w_buf = np.empty(m)
    uni_buf = np.empty(m)
    idx_buf = np.empty(m, dtype=np.int64)
    bin_keys, bin_weights = bin_table(m if kld.epsilon > 0.0 else 1)
    block = min(BLOCK, m)
    walk = model.sig_bias > 0.0  # gyro biases random-walk: two more noise rows per particle
    noise_rows = 8 if walk else 6
    noise_buf = np.empty(noise_rows * block)
    dist_buf = np.zeros(2 * block)
    work = new_likelihood_work(block, 4 * grid.grids)
    mean = np.empty(N_TIGHT)
    v = np.empty(N_TIGHT)
    cov = np.empty((2, 2))
    consts = beam_constants(model.sig_u, model.sig_d, model.outside_sigma)
    with_dist = model.dist_mode == DIST_NAVIGATION
    bad = 0
    locked = False  # the cloud has converged since the last (re)initialisation
    yaw_off = 0.0  # the cloud's heading offset from the navigation (centres the particles' trigonometry)
    healthy_e = np.nan  # the last healthy estimate and the navigation's displacement since (filters/recovery.py)
    healthy_n = np.nan
    healthy_k = 0
    dr_e = 0.0
    dr_n = 0.0
    for k in range(steps):
        x = xbuf[:N_TIGHT * mc].reshape((N_TIGHT, mc))
        scratch = sbuf[:N_TIGHT * mc].reshape((N_TIGHT, mc))
        logw = logw_buf[:mc]
        ll = ll_buf[:mc]
        w = w_buf[:mc]
        uni = uni_buf[:mc]
        idx = idx_buf[:mc]
        particles_out[k] = mc
        if k > 0:
            dr_e += inc[k - 1, D0E]
            dr_n += inc[k - 1, D0N]
        vec = beam_vectors(beams, ranges[k])
        att = attitude_reference(nav_pitch[k], nav_roll[k], nav_yaw[k] + yaw_off)
        best = np.inf
        for lo in range(0, mc, block):  # the particle passes, block by block
            n = min(block, mc - lo)
            dist = dist_buf[:2 * n].reshape((2, n))
            if k > 0:
                noise_all = noise_buf[:noise_rows * n].reshape((noise_rows, n))
                fill_normals(rng, noise_all)
                noise = noise_all[:6]
                if euler_in is not None:
                    propagate_tight_euler(x, euler_in[k - 1], readings.dt, inc[k - 1], noise, model.sig_pos,
                                          model.sig_up, model.sig_att, model.dist_mode, dist,
                                          attitude_reference(nav_pitch[k - 1], nav_roll[k - 1],
                                                             nav_yaw[k - 1] + yaw_off), lo)
                else:
                    propagate_tight(x, inc[k - 1], nav_yaw[k - 1], noise, model.sig_pos, model.sig_up,
                                    model.sig_att, model.dist_mode, dist, yaw_off, lo)
                if walk:
                    walk_biases(x, noise_all[6], noise_all[7], model.sig_bias, lo)
            best = min(best, loglik_tight_pass(x, lo, vec, grid, lik, consts, att, dist, with_dist and k > 0,
                                               work_block(work, n), ll[lo:lo + n]))
        # progressive correction (filters/tempering.py): while the rest of the update would leave fewer than
        # temper.ess_fraction * M effective particles, apply the share that leaves that many, resample and
        # regularise, and weigh the moved particles again; the update's last stage applies what remains
        remaining = 1.0
        stages_out[k] = 1
        while stages_out[k] < temper.stages:
            lam = tempering_fraction(logw, ll, remaining, temper.ess_fraction * mc, w)
            if lam >= remaining:
                break
            if lam > 0.0:
                _add_scaled(logw, lam, ll)
            ess = normalise_with_ess(logw, max_log_weight(logw), w)
            weighted_estimate(x, w, YAW, nav_yaw[k], mean, v, cov)
            spread = math.sqrt(v[E] + v[N])
            if shared_rs is None:
                resample_posterior(x, w, logw, ess, rng, temper.rs, YAW, mean[YAW], spread, uni, idx, scratch)
            else:
                resample_and_regularise(x, w, logw, ess, rng, temper.rs, N_TIGHT, spread, uni, idx, scratch)
            remaining -= lam
            for lo in range(0, mc, block):  # with_dist is False here: FilterSpec refuses tempering with the
                n = min(block, mc - lo)  # navigation's distances (and a literal False would compile the pass again)
                loglik_tight_pass(x, lo, vec, grid, lik, consts, att, dist_buf[:2 * n].reshape((2, n)), with_dist,
                                  work_block(work, n), ll[lo:lo + n])
            stages_out[k] += 1
        if remaining < 1.0:
            _shift_scale(ll, 0.0, remaining)
        mx = add_log_weights(logw, ll)
        ess = normalise_with_ess(logw, mx, w)
        weighted_estimate(x, w, YAW, nav_yaw[k], mean, v, cov)
        yaw_off = mean[YAW] - nav_yaw[k]
        if not abs(yaw_off) < math.pi:  # NaN, or wrapped: centre on the navigation again
            yaw_off = 0.0
        spread = math.sqrt(v[E] + v[N])
        off_map = keep_on_map(mean, guard.bounds)
        for c in range(N_TIGHT):  # element by element: an array assigned to a slice compiles numba's
            est[k, c] = mean[c]  # shape-mismatch error message (string formatting, ~2.7 s cold)
            var[k, c] = v[c]
        cov_en_out[k] = cov[0, 1]
        ess_out[k] = ess
        reinit_out[k] = 0
        healthy_out[k] = 1 if (spread < guard.healthy_std and best < 0.25 * div.sigma * div.sigma) else 0
        locked = locked or healthy_out[k] == 1
        if healthy_out[k] == 1:
            healthy_e = mean[E]
            healthy_n = mean[N]
            healthy_k = k
            dr_e = 0.0
            dr_n = 0.0
        if best < np.inf:  # an update without any bottom lock says nothing about divergence
            bad = bad + 1 if (best > div.sigma * div.sigma or (locked and spread > guard.spread_limit)) else 0
        diverged = readings.div_reinit and bad >= div.steps
        collapsed = ess < rs.ess_threshold * mc and spread < readings.collapse_spread
        if diverged or collapsed or off_map:
            centre_e, centre_n, half = mean[E], mean[N], prior.reinit_half_side
            turn = 0.0  # the re-drawn headings' centre, from the navigation heading
            if diverged and not off_map:
                centre_e, centre_n, half = recovery_square(div.recovery, mean[E], mean[N], healthy_e, healthy_n, dr_e,
                                                           dr_n, (k - healthy_k) * readings.dt,
                                                           prior.reinit_half_side, div.growth, div.max_half)
                if stop_to_search:
                    return k
                if reloc is not None:
                    found, match_e, match_n, match_turn = relocalise_around(inc, nav_up, k, mean[E], mean[N], reloc)
                    if found:
                        centre_e, centre_n, half, turn = match_e, match_n, prior.reinit_half_side, match_turn
            if mc != m:  # a re-drawn cloud is wide: the most particles again
                mc = m
                x = xbuf.reshape((N_TIGHT, m))
            draw_tight(x, rng, centre_e, centre_n, nav_up[k], nav_pitch[k], nav_roll[k], nav_yaw[k] + turn, prior,
                       half)
            if readings.cloud_std > 0.0:
                gaussian_horizontal(x, rng, centre_e, centre_n, readings.cloud_std)
            logw_buf[:mc] = 0.0
            bad = 0
            locked = False
            yaw_off = turn  # the new cloud is drawn about the navigation heading (turned by a global match)
            reinit_out[k] = 1
            continue
        if shared_rs is not None:
            resample_and_regularise(x, w, logw, ess, rng, shared_rs, N_TIGHT, spread, uni, idx, scratch)
            continue
        # posterior.resample_posterior, drawing the cloud's own count, or with KLD sampling (filters/kld.py) the
        # count its occupied bins ask for
        _shift_log_weights(logw)
        if ess < rs.ess_threshold * mc:
            drawn = mc
            if kld.epsilon > 0.0:
                bins = occupied_bins(x, w, kld.bin_m, kld.bin_rad, 1.0 / m, bin_keys, bin_weights)
                drawn = kld_count(bins, kld.epsilon, KLD_Z, kld.min_particles, m)
            resample_posterior_into(x, w, rng, rs, YAW, mean[YAW], spread, uni_buf[:drawn], idx_buf[:drawn],
                                    sbuf[:N_TIGHT * drawn].reshape((N_TIGHT, drawn)),
                                    xbuf[:N_TIGHT * drawn].reshape((N_TIGHT, drawn)))
            mc = drawn
            logw_buf[:mc] = 0.0
    return -1


@nb.njit(cache=True)
def keep_on_map(mean, bounds):
    """Clamp the horizontal estimate ``mean[0:2]`` into ``bounds`` (e_min, e_max, n_min, n_max).

    Returns True if it had left them (the caller then reinitialises the cloud around the
    clamped estimate). Bounds with e_min > e_max disable the check.
    """
    if bounds[0] > bounds[1]:
        return False
    out = False
    if mean[0] < bounds[0] or mean[0] > bounds[1]:
        mean[0] = min(max(mean[0], bounds[0]), bounds[1])
        out = True
    if mean[1] < bounds[2] or mean[1] > bounds[3]:
        mean[1] = min(max(mean[1], bounds[2]), bounds[3])
        out = True
    return out


def keep_on_map_numpy(mean, bounds):
    """Plain-numpy reference of :func:`keep_on_map`: (clamped copy, left the bounds)."""
    mean = np.array(mean, dtype=float)
    if bounds[0] > bounds[1]:
        return mean, False
    clamped = mean.copy()
    clamped[0] = np.clip(mean[0], bounds[0], bounds[1])
    clamped[1] = np.clip(mean[1], bounds[2], bounds[3])
    # beyond a bound, as the kernel compares: a NaN coordinate is not (and stays NaN)
    left = (mean[0] < bounds[0]) | (mean[0] > bounds[1]) | (mean[1] < bounds[2]) | (mean[1] > bounds[3])
    return clamped, bool(left)
