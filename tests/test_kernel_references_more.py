"""Kernels whose plain-numpy references came after their tests: the loose loops' edits of the navigation
Kalman filter (``loose.position_reset``, ``loose.reopen_kf``), their step of the navigation system
(``loose.navigation_step``: the bias lever and ``propagate.dead_reckon``, whose wound heading offsets
go through ``trig.unwound``), the prior of their fix window (``loose.advance_window_prior``), the PMF's
initial bank (``pmf.pmf_init``) and the end of an update the filters share
(``resample.resample_and_regularise``, whose draws are replayed from the generator's state by the
generator's own references, ``rng.fills_numpy``).

Each kernel and its reference get the same inputs, random (fixed seeds) and adversarial: NaN and
zero entries, heading offsets near and beyond +-pi and beyond ``trig.WOUND``, weights that are zero
or all on one particle, log-weights that are NaN or -inf, heading priors whose weights underflow.
Copies, index moves and the bit arithmetic must agree exactly; arithmetic agrees to ``rtol`` 1e-12
(numpy's sums and trigonometry round differently from the kernels'), with an absolute floor of
1e-12 of the quantity's scale where a result may cancel to near zero.

A kernel that draws is compared exactly on what it draws: the replay's numbers make the reference's
cloud, and the generator's next numbers after the kernel must be the replay's next ones.

Each comparison is a function that raises ``AssertionError``; the mutation tests give each reference
one wrong input or helper (through a module attribute that only the references read, never a kernel,
so that no kernel can be compiled with it) and require the comparison to fail, so that none of them
passes vacuously. The references themselves must run with every jitted function of tanbench made
unusable: they are plain numpy all the way down.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from filters_support import JITTED_CALLED, forbid_jitted_calls
from tanbench.filters import loose, pmf, propagate, trig
from tanbench.filters import resample as rs
from tanbench.filters import rng as fr
from tanbench.filters.state import BX, BZ, E, N, N_TIGHT, PITCH, ROLL, U, YAW
from tanbench.navigation import increments as incmod
from tanbench.navigation.eskf import EB, EE, EN, EPSI, N_ERROR
from tanbench.options import REGULARISATION, RESAMPLING

SEED = 20250611
RTOL = 1e-12


def close(actual, expected, scale=1.0, err_msg=""):
    """``actual`` equals ``expected`` to ``RTOL``, or within ``RTOL * scale`` (a result that cancels to
    near zero); NaN where the other has NaN."""
    np.testing.assert_allclose(actual, expected, rtol=RTOL, atol=RTOL * scale, equal_nan=True, err_msg=err_msg)


def exact(actual, expected, err_msg=""):
    """The same values (NaN where the other has NaN), shapes and dtypes."""
    np.testing.assert_array_equal(actual, expected, err_msg=err_msg, strict=True)


# --------------------------------------------------------------------------------------
# the navigation Kalman filter's edits (loose.position_reset, loose.reopen_kf)
# --------------------------------------------------------------------------------------
def covariance_cases(rng):
    """4x4 covariances: symmetric positive definite, asymmetric, with NaN and infinite entries, all zero."""
    a = rng.normal(0.0, 3.0, (N_ERROR, N_ERROR))
    spd = a @ a.T + np.diag([400.0, 300.0, 0.2, 1e-8])
    wild = rng.normal(0.0, 1e3, (N_ERROR, N_ERROR))  # not symmetric: the kernels copy entries, never mirror them
    holes = spd.copy()
    holes[EE, EPSI] = holes[EB, EN] = np.nan
    holes[EPSI, EB] = np.inf
    holes[EB, EB] = np.nan
    return [spd, wild, holes, np.zeros((N_ERROR, N_ERROR))]


def check_position_reset(p_kf, r, nav, zt):
    p, x = p_kf.copy(), nav.copy()
    loose.position_reset(p, r, x, zt)
    p_ref, x_ref = loose.position_reset_numpy(p_kf, r, nav, zt)
    exact(p, p_ref)
    exact(x, x_ref)


def position_reset_cases():
    rng = np.random.default_rng([SEED, 1])
    for p_kf in covariance_cases(rng):
        for r in (np.array([[25.0, 3.0], [-7.0, 16.0]]), np.diag([1e-6, 4e4]), np.full((2, 2), np.nan)):
            nav = rng.normal(0.0, 1.0, (N_TIGHT, 1)) * 100.0
            zt = rng.normal(0.0, 1e3, 2)
            yield p_kf, r, nav, zt


def test_position_reset_matches_numpy():
    for case in position_reset_cases():
        check_position_reset(*case)


def check_reopen_kf(p_kf, p0_pos, p0_yaw):
    p = p_kf.copy()
    loose.reopen_kf(p, p0_pos, p0_yaw)
    exact(p, loose.reopen_kf_numpy(p_kf, p0_pos, p0_yaw))


def reopen_cases():
    rng = np.random.default_rng([SEED, 2])
    for p_kf in covariance_cases(rng):
        for p0_pos, p0_yaw in ((400.0**2 / 12.0, math.radians(30.0) ** 2), (1e-3, 0.0), (rng.uniform(1, 1e4), 1e-6)):
            yield p_kf, p0_pos, p0_yaw


def test_reopen_kf_matches_numpy():
    for case in reopen_cases():
        check_reopen_kf(*case)
    # the heading variance is set to a quarter of the initial one even when the KF's was larger
    p = np.diag([1.0, 1.0, 4.0, 1e-9])
    loose.reopen_kf(p, 100.0, 1.0)
    assert p[EPSI, EPSI] == 0.25 and p[EB, EB] == 1e-9


# --------------------------------------------------------------------------------------
# the navigation system's step (loose.navigation_step, propagate.dead_reckon, trig.unwound)
# --------------------------------------------------------------------------------------
# heading offsets of the corrected navigation from the navigation heading: small, near and at +-pi, a few
# turns away, around trig.WOUND and far beyond it, not a number
OFFSETS = [0.0, -0.0, 0.3, -1.2, math.pi, -math.pi, math.pi - 1e-9, -math.pi + 1e-9, np.nextafter(math.pi, 4.0),
           3.0 * math.pi + 0.1, -5.0 * math.pi - 0.2, trig.WOUND, -trig.WOUND, np.nextafter(trig.WOUND, np.inf),
           2e6, -7.5e11, 5e15, 1e300, np.nan, np.inf, -np.inf]


def increments_row(rng):
    """One row of the increments table at plausible scales (m, m s, s, rad)."""
    inc = np.empty(incmod.N_INCREMENTS)
    inc[[incmod.D0E, incmod.D0N]] = rng.normal(0.0, 15.0, 2)
    inc[[incmod.JAXE, incmod.JAXN, incmod.JAZE, incmod.JAZN]] = rng.normal(0.0, 80.0, 4)
    inc[[incmod.SX, incmod.SZ]] = rng.normal([0.0, 10.0], [0.1, 0.5])
    inc[[incmod.DYAW, incmod.DPITCH, incmod.DROLL]] = rng.normal(0.0, 0.05, 3)
    inc[incmod.DUP] = rng.normal(0.0, 1.0)
    return inc


def navigation_state(rng, yaw):
    nav = np.empty((N_TIGHT, 1))
    nav[[E, N], 0] = rng.uniform(-3e3, 3e3, 2)
    nav[U, 0] = rng.normal(-40.0, 5.0)
    nav[[PITCH, ROLL], 0] = rng.normal(0.0, 0.05, 2)
    nav[YAW, 0] = yaw
    nav[[BX, BZ], 0] = rng.normal(0.0, 3e-4, 2)
    return nav


def navigation_cases():
    rng = np.random.default_rng([SEED, 3])
    for offset in OFFSETS:
        for _ in range(3):
            yaw_nav = rng.uniform(-math.pi, math.pi)
            nav = navigation_state(rng, yaw_nav + offset)
            if rng.random() < 0.3:
                nav[[BX, BZ], 0] = 0.0
            yield nav, increments_row(rng), yaw_nav, rng.normal(-40.0, 5.0)


def check_navigation_step(nav, inc, yaw_nav, up_nav):
    x = nav.copy()
    got = loose.navigation_step(x, inc, yaw_nav, up_nav)
    x_ref, *ref = loose.navigation_step_numpy(nav, inc, yaw_nav, up_nav)
    lever = max(abs(inc[incmod.JAZE]), abs(inc[incmod.JAZN]))
    move = math.hypot(inc[incmod.D0E], inc[incmod.D0N])
    close(got[:2], ref[:2], move, "displacement")
    close(got[2:], ref[2:], lever, "bias lever")
    close(x[[E, N]], x_ref[[E, N]], move, "position")
    exact(x[[U, PITCH, ROLL, YAW, BX, BZ]], x_ref[[U, PITCH, ROLL, YAW, BX, BZ]], "the other states")


def check_dead_reckon(nav, inc, yaw_nav):
    x = nav.copy()
    propagate.dead_reckon(x, inc, yaw_nav)
    ref = propagate.dead_reckon_numpy(nav, inc, yaw_nav)
    close(x[[E, N]], ref[[E, N]], math.hypot(inc[incmod.D0E], inc[incmod.D0N]), "position")
    exact(x[[U, PITCH, ROLL, YAW, BX, BZ]], ref[[U, PITCH, ROLL, YAW, BX, BZ]], "the other states")


def test_navigation_step_matches_numpy():
    for case in navigation_cases():
        check_navigation_step(*case)


def test_dead_reckon_matches_numpy():
    for nav, inc, yaw_nav, _ in navigation_cases():
        check_dead_reckon(nav, inc, yaw_nav)


def test_navigation_step_moves_by_the_rotated_displacement():
    """Reference-free: no bias and no heading offset, the navigation moves by the increments' own
    displacement and the lever is -[JAZE, JAZN]; a quarter turn rotates both."""
    rng = np.random.default_rng([SEED, 4])
    inc = increments_row(rng)
    nav = navigation_state(rng, 0.7)
    nav[[BX, BZ], 0] = 0.0
    position = 3e3 * RTOL  # the displacement is read back from positions of up to 3 km
    d_e, d_n, b_e, b_n = loose.navigation_step(nav, inc, 0.7, -12.0)
    assert (b_e, b_n) == (-inc[incmod.JAZE], -inc[incmod.JAZN])
    np.testing.assert_allclose([d_e, d_n], inc[[incmod.D0E, incmod.D0N]], rtol=0.0, atol=position)
    assert nav[U, 0] == -12.0 + inc[incmod.DUP]
    nav[YAW, 0] = 0.7 + math.pi / 2
    d_e, d_n, b_e, b_n = loose.navigation_step(nav, inc, 0.7, -12.0)
    np.testing.assert_allclose([b_e, b_n], [inc[incmod.JAZN], -inc[incmod.JAZE]], rtol=RTOL, atol=RTOL * 100)
    np.testing.assert_allclose([d_e, d_n], [-inc[incmod.D0N], inc[incmod.D0E]], rtol=0.0, atol=position)


def unwound_cases():
    rng = np.random.default_rng([SEED, 5])
    d = np.concatenate([rng.uniform(-40.0, 40.0, 200), rng.uniform(trig.WOUND, 1e12, 200), -np.logspace(5, 300, 200),
                        np.array(OFFSETS), [np.nextafter(trig.WOUND, 0.0), np.nextafter(-trig.WOUND, -np.inf),
                                            np.finfo(float).max, -np.finfo(float).max, 5e-324]])
    return d


def check_unwound(d):
    got = np.array([trig.unwound(v) for v in d])
    exact(got, trig.unwound_numpy(d))


def test_unwound_and_wound_angle_match_numpy():
    """The wound-angle stand-in is bit arithmetic: kernel and reference agree exactly."""
    check_unwound(unwound_cases())
    far = unwound_cases()
    far = far[np.isfinite(far) & (np.abs(far) > trig.WOUND)]
    hashed = trig.wound_angle_numpy(far)
    assert ((hashed >= -math.pi) & (hashed < math.pi)).all()
    assert trig.wound_angle_numpy(5e15).shape == ()


# --------------------------------------------------------------------------------------
# the fix window's prior (loose.advance_window_prior, factored out of loose_kalman_loop)
# --------------------------------------------------------------------------------------
def window_cases():
    rng = np.random.default_rng([SEED, 6])
    for sig_heading in (0.0, math.radians(0.5), math.radians(30.0), 2.0):
        for sig_pos in (0.0, 0.3, 12.0):
            a = rng.normal(0.0, 20.0, (2, 2))
            steps = rng.normal(0.0, 15.0, (40, 2))
            steps[5] = 0.0  # the vehicle at rest over an interval
            yield rng.uniform(-3e3, 3e3, 2), a @ a.T, steps, sig_pos, sig_heading


def check_window_prior(m0, p0, steps, sig_pos, sig_heading):
    """40 intervals in a row: the prior accumulates as it does between two fixes."""
    m, p = m0.copy(), p0.copy()
    m_ref, p_ref = m0.copy(), p0.copy()
    for d_e, d_n in steps:
        loose.advance_window_prior(m, p, d_e, d_n, sig_pos, sig_heading)
        m_ref, p_ref = loose.advance_window_prior_numpy(m_ref, p_ref, d_e, d_n, sig_pos, sig_heading)
    close(m, m_ref)
    close(p, p_ref, np.abs(p_ref).max())


def test_window_prior_matches_numpy():
    for case in window_cases():
        check_window_prior(*case)


# --------------------------------------------------------------------------------------
# the PMF's initial bank (pmf.pmf_init)
# --------------------------------------------------------------------------------------
def pmf_init_cases():
    rng = np.random.default_rng([SEED, 7])
    thirty = math.radians(30.0)
    yield (15, 17, 17), np.linspace(-2.5 * thirty, 2.5 * thirty, 15), thirty  # pmf_settings' bank
    yield (1, 9, 9), np.array([0.4]), thirty  # one slice: weight 1, whatever its offset
    yield (4, 5, 5), np.linspace(-math.pi, math.pi, 4), 1.0  # offsets at +-pi
    yield (6, 3, 7), np.sort(rng.uniform(-math.pi, math.pi, 6)), 0.7  # a grid that is not square
    yield (5, 4, 4), np.linspace(-1.0, 1.0, 5), 0.0  # no heading prior: every slice alike
    yield (5, 4, 4), np.linspace(-1.0, 1.0, 5), -0.3  # a negative std: as none
    yield (3, 4, 4), np.array([0.0, 30.0, -40.0]), 1.0  # far slices: weights underflow to zero
    yield (7, 4, 4), np.linspace(-3.0, 3.0, 7) + 0.25, 1e-3  # every weight underflows: 0 / 0
    yield (9, 6, 6), np.linspace(-2.5, 2.5, 11), 1.0  # more offsets than slices: the first H used


def check_pmf_init(shape, deltas, sig_heading0, centre=(1234.5, -678.25)):
    p, centres = np.full(shape, np.nan), np.full((shape[0], 2), np.nan)
    pmf.pmf_init(p, centres, deltas, centre[0], centre[1], sig_heading0)
    p_ref, centres_ref = pmf.pmf_init_numpy(shape, deltas, centre[0], centre[1], sig_heading0)
    np.testing.assert_allclose(p, p_ref, rtol=RTOL, atol=0.0, equal_nan=True)
    exact(centres, centres_ref)


def test_pmf_init_matches_numpy():
    for shape, deltas, sig in pmf_init_cases():
        check_pmf_init(shape, deltas, sig)
        p, centres = pmf.pmf_init_numpy(shape, deltas, 0.0, 0.0, sig)
        if np.isfinite(p).all():
            assert p.sum() == pytest.approx(1.0, rel=1e-12)
        else:  # the one degenerate case: a prior so narrow that no slice keeps a weight
            assert np.isnan(p).all() and sig == 1e-3


# --------------------------------------------------------------------------------------
# the end of an update (resample.resample_and_regularise), its draws replayed
# --------------------------------------------------------------------------------------
GENERATORS = ["fast", "numpy-stream", "numpy-mt19937"]
LOOSE_ROWS = np.array([0, 1], dtype=np.int64)
TIGHT_ROWS = np.array([E, N, YAW, BX, BZ], dtype=np.int64)


def loop_generator(kind, seed):
    """What a loop draws from: the fast generator's words, numpy's PCG64 stepped inline, or a numpy
    Generator on another bit generator (drawn through numba's own Generator support)."""
    if kind == "fast":
        return fr.FastRng.from_seed(np.random.SeedSequence(seed)).state
    if kind == "numpy-stream":
        return fr.loop_rng(np.random.default_rng(seed), "numpy")
    return np.random.Generator(np.random.MT19937(seed))


def cloud(rng, rows, m):
    x = np.empty((rows, m))
    x[0] = rng.uniform(900.0, 1100.0, m)
    x[1] = rng.normal(-500.0, 30.0, m)
    if rows == N_TIGHT:
        x[U] = rng.normal(-30.0, 0.2, m)
        x[[PITCH, ROLL]] = rng.normal(0.0, 1e-3, (2, m))
        x[YAW] = rng.normal(3.0, 0.4, m)  # around and across +pi
        x[[BX, BZ]] = rng.normal(0.0, 2e-4, (2, m))
    return x


def weights(rng, m, how, holes):
    """(log-weights, normalised weights): ``flat`` (ESS about 0.8 M), ``peaked`` (ESS a few particles),
    ``one`` (all weight on one particle), ``lost`` (every log-weight -inf or NaN, the weights uniform);
    ``holes``: some log-weights NaN and some -inf (weight 0)."""
    if how == "lost":
        logw = np.where(rng.random(m) < 0.5, np.nan, -np.inf)
        return logw, np.full(m, 1.0 / m)
    logw = rng.normal(0.0, 0.5 if how == "flat" else 8.0, m)
    if holes:
        logw[rng.choice(m, max(1, m // 7), replace=False)] = np.nan
        logw[rng.choice(m, max(1, m // 11), replace=False)] = -np.inf
    w = np.exp(np.nan_to_num(logw, nan=-np.inf) - np.nanmax(logw))
    if how == "one":
        w[:] = 0.0
        w[m // 2] = 1.0
    return logw, w / w.sum()


def resample_cases(kind):
    """(x, w, logw, ess, threshold, kind, rows, size, dim, spread): clouds of 1, 37, 64 and 1500 (more than
    a fill's chunk) particles, loose and tight, the ESS above, at and below the threshold, the cloud's
    spread below and above the re-spread's minimum (1 m), the log-weights of :func:`weights`."""
    rng = np.random.default_rng([SEED, 8, REGULARISATION[kind]])
    size = 0.2 if kind == "gordon" else 0.1
    cases = []
    for m, rows, how, holes, spread in ((1, 2, "flat", False, 0.1), (37, 2, "peaked", True, 0.5),
                                        (37, N_TIGHT, "one", False, 30.0), (64, 2, "lost", False, 0.5),
                                        (1500, 2, "flat", True, 30.0), (1500, N_TIGHT, "peaked", False, 0.5),
                                        (1500, N_TIGHT, "flat", False, 0.2)):
        cols, dim = (LOOSE_ROWS, 2) if rows == 2 else (TIGHT_ROWS, N_TIGHT)
        logw, w = weights(rng, m, how, holes)
        ess = 1.0 / np.sum(w * w)
        x = cloud(rng, rows, m)
        for threshold, at in ((0.5, ess), (1.0 + 1e-9, ess), (0.5, 0.5 * m)):  # 1 + 1e-9: always resample
            cases.append((x, w, logw, at, threshold, REGULARISATION[kind], cols, size, dim, spread))
    return cases


def check_resample_and_regularise(x0, w, logw0, ess, generator, rs_bundle, dim, spread):
    draw = fr.fills_numpy(generator)  # the replay, from the generator's state before the kernel
    x, logw = x0.copy(), logw0.copy()
    m = x.shape[1]
    rs.resample_and_regularise(x, w, logw, ess, generator, rs_bundle, dim, spread, np.empty(m),
                               np.empty(m, dtype=np.int64), np.empty_like(x))
    x_ref, logw_ref = rs.resample_and_regularise_numpy(x0, w, logw0, ess, draw, rs_bundle, dim, spread)
    exact(logw, logw_ref, "log-weights")
    if rs_bundle.kind == rs.REG_NONE:  # copies and the re-spread's x + s n: the same operations
        exact(x, x_ref, "cloud")
    else:  # the jitter's mean and spread are summed in another order; per state: biases against metres
        scale = np.abs(x0).max(axis=1, keepdims=True)
        np.testing.assert_allclose((x - x_ref) / scale, 0.0, atol=RTOL, err_msg="cloud")
    # the generator advanced by exactly the kernel's draws: its next numbers are the replay's
    after_u, after_n = np.empty(19), np.empty(300)
    fr.fill_uniforms(generator, after_u)
    fr.fill_normals(generator, after_n)
    exact(after_u, draw(19, False), "next uniforms")
    exact(after_n, draw(300, True), "next normals")


def run_resample_case(case, scheme, generator_kind, seed):
    x0, w, logw0, ess, threshold, kind_code, cols, size, dim, spread = case
    bundle = rs.Resampling(RESAMPLING[scheme], threshold, kind_code, cols, size, 1.0)
    check_resample_and_regularise(x0, w, logw0, ess, loop_generator(generator_kind, seed), bundle, dim, spread)


@pytest.mark.parametrize("generator_kind", GENERATORS)
@pytest.mark.parametrize("scheme", sorted(RESAMPLING))
@pytest.mark.parametrize("kind", sorted(REGULARISATION))
def test_resample_and_regularise_matches_numpy(kind, scheme, generator_kind):
    for i, case in enumerate(resample_cases(kind)):
        run_resample_case(case, scheme, generator_kind, [SEED, 9, i])


def test_fast_fills_replay_fill_after_fill():
    """The fast generator's replay (``rng.fills_numpy``, by ``rng.fill_numpy``) gives the fills' numbers and
    state, fill after fill: uniforms and normals of lengths that are and are not multiples of LANES, beyond a
    chunk."""
    words = loop_generator("fast", [SEED, 10])
    draw = fr.fills_numpy(words)
    for n, normal in ((1, False), (37, True), (2 * fr.CHUNK + 3, True), (fr.LANES, False), (5, True),
                      (fr.CHUNK + fr.LANES, False), (3000, True)):
        out = np.empty(n)
        (fr.fill_normals if normal else fr.fill_uniforms)(words, out)
        exact(out, draw(n, normal), f"n={n}")
    state = words.copy()
    fr.fill_numpy(state, 40, True)
    fr.fill_normals(words, np.empty(40))
    exact(words, state)


# --------------------------------------------------------------------------------------
# the references are plain numpy: they run with every jitted function of tanbench unusable
# --------------------------------------------------------------------------------------
def test_references_call_no_jitted_function(monkeypatch):
    """Each reference of this file (and the replay of the draws) runs with every numba dispatcher that a
    tanbench module holds replaced by a function that raises: none of them calls compiled code, directly
    or through a helper."""
    nav, inc, yaw_nav, up_nav = next(iter(navigation_cases()))
    resample_inputs = []
    for kind in ("liu-west", "gordon"):
        x0, w, logw0, ess, _, code, cols, size, dim, spread = resample_cases(kind)[-2]
        bundle = rs.Resampling(rs.MULTINOMIAL, 1.0 + 1e-9, code, cols, size, 1.0)
        for generator_kind in GENERATORS:
            resample_inputs.append((x0, w, logw0, ess, loop_generator(generator_kind, [SEED, 12]), bundle, dim, spread))

    assert forbid_jitted_calls(monkeypatch) > 100
    for kernel in (loose.position_reset, rs.fill_uniforms, fr.fill_normals):
        with pytest.raises(AssertionError, match=JITTED_CALLED):
            kernel()
    loose.position_reset_numpy(*next(iter(position_reset_cases())))
    loose.reopen_kf_numpy(*next(iter(reopen_cases())))
    loose.navigation_step_numpy(nav, inc, yaw_nav, up_nav)
    propagate.dead_reckon_numpy(nav, inc, yaw_nav)
    trig.unwound_numpy(unwound_cases())
    m0, p0, steps, sig_pos, sig_heading = next(iter(window_cases()))
    loose.advance_window_prior_numpy(m0, p0, *steps[0], sig_pos, sig_heading)
    shape, deltas, sig = next(iter(pmf_init_cases()))
    pmf.pmf_init_numpy(shape, deltas, 0.0, 0.0, sig)
    for x0, w, logw0, ess, generator, bundle, dim, spread in resample_inputs:
        rs.resample_and_regularise_numpy(x0, w, logw0, ess, fr.fills_numpy(generator), bundle, dim, spread)
    # and it would tell: a reference that took the kernel's unwinding
    monkeypatch.setattr(propagate, "unwound_numpy", propagate.unwound)
    with pytest.raises(AssertionError, match="jitted"):
        propagate.dead_reckon_numpy(nav, inc, yaw_nav)


# --------------------------------------------------------------------------------------
# every comparison can fail: one wrong input or constant in each reference
# --------------------------------------------------------------------------------------
def _on_changed_inputs(change):
    """A patch: the reference called on its inputs changed by ``change`` (a list of them, changed in place)."""
    def patch(real):
        def mutated(*args):
            args = list(args)
            change(args)
            return real(*args)
        return mutated
    return patch


def _transpose_r(args):
    args[1] = args[1].T


def _whole_heading_variance(args):
    args[2] = 4.0 * args[2]


def _lever_swapped(args):
    inc = args[1].copy()
    inc[[incmod.JAZE, incmod.JAZN]] = inc[[incmod.JAZN, incmod.JAZE]]
    args[1] = inc


def _one_ulp_up(args):
    with np.errstate(over="ignore"):  # the largest double's next is inf
        args[0] = np.nextafter(args[0], np.inf)


def _displacement_swapped(args):
    args[2], args[3] = args[3], args[2]


def _wider_prior(args):
    args[4] = 1.001 * args[4]


def _one_uniform_late(args):
    args[4](1, False)  # the replay draws one uniform before the reference starts


MUTATIONS = {
    "position_reset: r transposed": (loose, "position_reset_numpy", _on_changed_inputs(_transpose_r),
                                     lambda: [check_position_reset(*c) for c in position_reset_cases()]),
    "reopen_kf: the whole initial heading variance": (
        loose, "reopen_kf_numpy", _on_changed_inputs(_whole_heading_variance),
        lambda: [check_reopen_kf(*c) for c in reopen_cases()]),
    "navigation_step: JAZE and JAZN swapped": (loose, "navigation_step_numpy", _on_changed_inputs(_lever_swapped),
                                               lambda: [check_navigation_step(*c) for c in navigation_cases()]),
    "dead_reckon: wound offsets taken as they are": (
        propagate, "unwound_numpy", lambda real: (lambda d: np.asarray(d, dtype=np.float64)),
        lambda: [check_dead_reckon(*c[:3]) for c in navigation_cases()]),
    "unwound: the wound angle of the next double": (trig, "wound_angle_numpy", _on_changed_inputs(_one_ulp_up),
                                                    lambda: check_unwound(unwound_cases())),
    "window prior: d_e and d_n swapped": (loose, "advance_window_prior_numpy",
                                          _on_changed_inputs(_displacement_swapped),
                                          lambda: [check_window_prior(*c) for c in window_cases()]),
    "pmf_init: heading std 0.1 % wider": (pmf, "pmf_init_numpy", _on_changed_inputs(_wider_prior),
                                          lambda: [check_pmf_init(*c) for c in pmf_init_cases()]),
    "resample_and_regularise: draws one uniform late": (
        rs, "resample_and_regularise_numpy", _on_changed_inputs(_one_uniform_late),
        lambda: [run_resample_case(c, "systematic", "fast", [SEED, 11, i])
                 for i, c in enumerate(resample_cases("none"))]),
}


@pytest.mark.parametrize("name", MUTATIONS)
def test_each_comparison_fails_on_a_mutated_reference(name, monkeypatch):
    module, attr, patch, compare = MUTATIONS[name]
    compare()  # the references as they are pass (and every kernel is compiled before anything is patched)
    monkeypatch.setattr(module, attr, patch(getattr(module, attr)))
    with pytest.raises(AssertionError):
        compare()
