"""``filter.recovery: global`` (filters/relocalise.py): a diverged tight filter re-drawn where a batch
terrain match of its own last updates puts the vehicle.

Each kernel against its plain-numpy reference; the match finds a known position and heading on a
toy map and refuses a flat one (TERCOM's ambiguity test); the option keeps every default cell key
and names its own compiled variant; the tight loop runs through the search.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from filters_support import short_scenario
from tanbench.config import Scenario
from tanbench.filters import relocalise as rl
from tanbench.filters.tercom import surface_likelihood_moments_numpy
from tanbench.navigation.increments import D0E, D0N, N_INCREMENTS
from tanbench.terrain.grid import MapArgs, bilinear_numpy


def _toy_map(flat=False, res=5.0, n=240):
    """A smooth, non-repeating toy relief (sum of a few bumps and waves) on an n x n grid of ``res`` m."""
    e = np.arange(n) * res
    ee, nn = np.meshgrid(e, e)
    z = -100.0 + 0.0 * ee
    if not flat:
        rng = np.random.default_rng(12)
        for _ in range(800):
            ce, cn = rng.uniform(0, n * res, 2)
            z += rng.uniform(-8, 8) * np.exp(-((ee - ce) ** 2 + (nn - cn) ** 2) / (2 * rng.uniform(8, 25) ** 2))
    return MapArgs(np.ascontiguousarray(z), 0.0, 0.0, 1.0 / res, 1.0 / res)


def _survey(k=80, turn_deg=17.0, start=(400.0, 350.0)):
    """True positions (k, 2) of a gently curving track at 2 m per update and the navigation's
    displacements between them, turned by -``turn_deg`` (a navigation heading error)."""
    heading = np.radians(30.0) + np.linspace(0.0, np.radians(50.0), k)
    d = 2.0 * np.stack([np.sin(heading), np.cos(heading)], axis=1)
    truth = np.asarray(start) + np.concatenate([[[0.0, 0.0]], np.cumsum(d[:-1], axis=0)])
    c, s = math.cos(math.radians(-turn_deg)), math.sin(math.radians(-turn_deg))
    step = np.diff(truth, axis=0)
    inc = np.zeros((k - 1, N_INCREMENTS))
    inc[:, D0E] = c * step[:, 0] - s * step[:, 1]
    inc[:, D0N] = s * step[:, 0] + c * step[:, 1]
    return truth, inc


def _reloc(zmap, offsets, window, half_side=150.0, fix_std=10.0, span_deg=30.0, step_deg=2.0, nav_en=None,
           nav_min_offset=0.0, both_squares=False):
    res = 1.0 / zmap.inv_re
    return rl.Relocalise(offsets, zmap, rl.heading_candidates(math.radians(span_deg), math.radians(step_deg)),
                         int(math.ceil(half_side / res)), res, window, 1.0, fix_std,
                         np.empty((0, 2)) if nav_en is None else np.ascontiguousarray(nav_en, dtype=np.float64),
                         nav_min_offset, both_squares)


def test_heading_candidates():
    d = rl.heading_candidates(math.radians(90.0), math.radians(2.0))
    assert d.size == 91 and d[45] == 0.0 and d[0] == pytest.approx(-math.pi / 2) and d[-1] == pytest.approx(math.pi / 2)
    np.testing.assert_array_equal(d, -d[::-1])
    assert rl.heading_candidates(0.0, math.radians(2.0)).tolist() == [0.0]


def test_relative_profile_matches_numpy():
    rng = np.random.default_rng(3)
    k_all, m = 50, 4
    inc = rng.normal(size=(k_all - 1, N_INCREMENTS))
    offsets = rng.normal(size=(k_all, m, 3))
    offsets[rng.random((k_all, m)) < 0.2] = np.nan  # beams without a range
    up = rng.normal(size=k_all)
    for k, window in ((49, 20), (10, 20), (0, 5), (30, 31)):
        pe, pn, ph = np.empty(window * m), np.empty(window * m), np.empty(window * m)
        npts = rl.relative_profile(inc, offsets, up, k, window, pe, pn, ph)
        ref = rl.relative_profile_numpy(inc, offsets, up, k, window)
        assert npts == ref[0].size
        for got, want in zip((pe, pn, ph), ref):
            np.testing.assert_allclose(got[:npts], want, rtol=0, atol=1e-12)
    # the newest point is the current footprint
    assert pe[0] == offsets[30, 0, 0] or np.isnan(offsets[30, 0, 2])


def _single_beam_case(zmap, turn_deg=17.0, k_all=80, noise=0.0):
    truth, inc = _survey(k_all, turn_deg)
    offsets = np.zeros((k_all, 1, 3))
    offsets[:, 0, 2] = -30.0  # a vertical beam, 30 m range (the vehicle 30 m above the bottom)
    bottom = bilinear_numpy(*zmap, truth[:, 0], truth[:, 1]) + noise * np.random.default_rng(8).normal(size=k_all)
    up = bottom + 30.0
    return truth, inc, offsets, up


def test_global_match_finds_position_and_heading():
    zmap = _toy_map()
    truth, inc, offsets, up = _single_beam_case(zmap, noise=0.3)
    k, window = 79, 60
    reloc = _reloc(zmap, offsets, window)
    est = truth[k] + np.array([110.0, -85.0])  # a diverged estimate far off
    found, e, n, delta = rl.relocalise(inc, up, k, est[0], est[1], reloc)
    assert found
    assert math.hypot(e - truth[k, 0], n - truth[k, 1]) < 4.0
    assert math.degrees(delta) == pytest.approx(17.0, abs=5.0)


def test_global_match_matches_numpy():
    zmap = _toy_map()
    truth, inc, offsets, up = _single_beam_case(zmap, noise=0.3)
    k, window = 79, 60
    reloc = _reloc(zmap, offsets, window, half_side=100.0, span_deg=20.0, step_deg=4.0)
    pe, pn, ph = rl.relative_profile_numpy(inc, offsets, up, k, window)
    for centre in (truth[k] + [60.0, 40.0], truth[k] - [30.0, 70.0], truth[k] + [99.0, 0.0]):
        got = rl.global_match(pe, pn, ph, centre[0], centre[1], window, reloc)
        want = rl.global_match_numpy(pe, pn, ph, centre[0], centre[1], window, reloc)
        assert got[0] == want[0]
        np.testing.assert_allclose(got[1:], want[1:], rtol=0, atol=1e-9)


@pytest.mark.parametrize("where", ["inside", "near-the-edge", "with-a-hole"])
def test_aligned_msd_surface_matches_numpy(where):
    """The coarse search's whole-cell surface against TERCOM's numpy reference: the same candidates off
    the map (+inf) and the same MSD elsewhere up to rounding, on a profile of several beams."""
    from tanbench.filters.tercom import profile_surface_numpy

    zmap = _toy_map(n=120)
    if where == "with-a-hole":
        z = zmap.z.copy()
        z[50:53, 60:64] = np.nan
        zmap = zmap._replace(z=z)
    rng = np.random.default_rng(5)
    pe, pn = rng.uniform(-60.0, 60.0, 150), rng.uniform(-60.0, 60.0, 150)
    ph = -100.0 + rng.normal(size=150)
    centre = {"inside": (300.0, 290.0), "near-the-edge": (75.0, 520.0), "with-a-hole": (310.0, 260.0)}[where]
    deltas = rl.heading_candidates(math.radians(10.0), math.radians(5.0))
    half = 12
    got = np.empty((deltas.size, 2 * half + 1, 2 * half + 1))
    rl.aligned_msd_surface(pe + centre[0], pn + centre[1], ph, *centre, half, deltas, zmap, got)
    want, _ = profile_surface_numpy(pe + centre[0], pn + centre[1], ph, *centre, half, 5.0, deltas, zmap)
    assert np.array_equal(np.isinf(got), np.isinf(want))
    assert np.isinf(got).any() == (where != "inside")
    ok = np.isfinite(want)
    np.testing.assert_allclose(got[ok], want[ok], rtol=1e-9, atol=1e-9)
    general = np.empty_like(got)  # non-square cells: the general kernel
    rect = zmap._replace(inv_rn=1.0 / 5.000001)
    rl.coarse_surface(pe + centre[0], pn + centre[1], ph, *centre, half, 5.0, deltas, rect, general)
    want_rect, _ = profile_surface_numpy(pe + centre[0], pn + centre[1], ph, *centre, half, 5.0, deltas, rect)
    np.testing.assert_allclose(general, want_rect, rtol=1e-12, atol=1e-12)


def test_ambiguous_or_early_match_is_refused():
    flat = _toy_map(flat=True)
    truth, inc, offsets, up = _single_beam_case(flat)
    reloc = _reloc(flat, offsets, 60)
    assert not rl.relocalise(inc, up, 79, truth[79, 0] + 50.0, truth[79, 1], reloc)[0]  # flat: ambiguous
    pe, pn, ph = rl.relative_profile_numpy(inc, offsets, up, 79, 60)
    assert not rl.global_match_numpy(pe, pn, ph, truth[79, 0] + 50.0, truth[79, 1], 60, reloc)[0]
    zmap = _toy_map()
    truth, inc, offsets, up = _single_beam_case(zmap)
    reloc = _reloc(zmap, offsets, 60)
    assert not rl.relocalise(inc, up, 40, truth[40, 0], truth[40, 1], reloc)[0]  # the profile is not full yet
    assert rl.relocalise(inc, up, 79, truth[79, 0], truth[79, 1], reloc)[0]


def test_a_match_at_the_end_of_the_headings_is_refused():
    """A vehicle turned beyond the headings searched: the best candidate sits at their end, refused."""
    zmap = _toy_map()
    truth, inc, offsets, up = _single_beam_case(zmap, turn_deg=40.0)
    reloc = _reloc(zmap, offsets, 60, half_side=15.0, span_deg=20.0)  # a small square about the truth
    pe, pn, ph = rl.relative_profile_numpy(inc, offsets, up, 79, 60)
    assert not rl.relocalise(inc, up, 79, truth[79, 0], truth[79, 1], reloc)[0]
    assert not rl.global_match_numpy(pe, pn, ph, truth[79, 0], truth[79, 1], 60, reloc)[0]
    wide = _reloc(zmap, offsets, 60, half_side=15.0, span_deg=50.0)
    assert rl.relocalise(inc, up, 79, truth[79, 0], truth[79, 1], wide)[0]


def test_a_refused_match_around_the_estimate_is_tried_around_the_navigation_solution():
    """``recovery_search_around: estimate-then-navigation``: an estimate that has run farther from the vehicle
    than half the square is refused (the truth is outside it); the second square, around the navigation
    solution, holds the vehicle and finds it. Without navigation centres (the default) nothing more is tried;
    an accepted first match is not searched again; the jitted kernel against its reference."""
    zmap = _toy_map()
    truth, inc, offsets, up = _single_beam_case(zmap, noise=0.3)
    k = 79
    far = truth[k] + [180.0, -160.0]  # the diverged estimate: the truth is outside its +-100 m square
    nav = np.tile(truth[k] + [35.0, 25.0], (k + 1, 1))  # the navigation solution, 43 m off
    alone = _reloc(zmap, offsets, 60, half_side=100.0)
    both = _reloc(zmap, offsets, 60, half_side=100.0, nav_en=nav)
    assert not rl.relocalise(inc, up, k, far[0], far[1], alone)[0]
    assert not rl.relocalise_around(inc, up, k, far[0], far[1], alone)[0]
    found, east, north, _ = rl.relocalise_around(inc, up, k, far[0], far[1], both)
    assert found and math.hypot(east - truth[k, 0], north - truth[k, 1]) < 3.0
    want = rl.relocalise_around_numpy(inc, up, k, far[0], far[1], both)
    assert want[0]
    np.testing.assert_allclose((east, north), want[1:3], rtol=0, atol=1e-9)
    near = truth[k] + [20.0, -10.0]  # a first match accepted: the same answer with or without the second square
    np.testing.assert_array_equal(rl.relocalise_around(inc, up, k, near[0], near[1], both),
                                  rl.relocalise(inc, up, k, near[0], near[1], alone))
    short = _reloc(zmap, offsets, 60, half_side=100.0, nav_en=nav[:k])  # no centre at this update: not tried
    assert not rl.relocalise_around(inc, up, k, far[0], far[1], short)[0]
    # estimate-then-distant-navigation: the second square only for a navigation solution outside the first one
    outside = _reloc(zmap, offsets, 60, half_side=100.0, nav_en=nav, nav_min_offset=100.0)
    np.testing.assert_array_equal(rl.relocalise_around(inc, up, k, far[0], far[1], outside),
                                  (found, east, north, _))  # 145 m east of the estimate: searched
    assert rl.relocalise_around_numpy(inc, up, k, far[0], far[1], outside)[0]
    near_far = truth[k] + [130.0, 20.0]  # the truth outside this square too, the navigation inside it (95 m west)
    assert not rl.relocalise_around(inc, up, k, near_far[0], near_far[1], outside)[0]
    assert not rl.relocalise_around_numpy(inc, up, k, near_far[0], near_far[1], outside)[0]
    assert rl.relocalise_around(inc, up, k, near_far[0], near_far[1], both)[0]


def test_both_squares_std_matches_numpy_and_sees_a_rival_in_the_first_square():
    """``both_squares_std``: the ambiguity statistic over two squares' coarse surfaces equals its numpy reference; a
    first square without a competitive candidate leaves the second square's own std, a candidate in it as good as the
    second square's best makes the pair ambiguous (about half the distance between the two), and candidates of the
    second square inside the first are counted once."""
    rng = np.random.default_rng(11)
    half, step, pings, sig_u = 6, 10.0, 200, 1.0
    side = 2 * half + 1
    second = 1.0 + rng.random((3, side, side))
    second[1, half + 1, half - 2] = 0.2  # one clear minimum
    second[0, 0, 0] = np.inf
    flat = np.full((3, side, side), 5.0)
    args = (half, step, pings, sig_u)
    deltas = np.zeros(3)
    own = rl.both_squares_std(flat, 0.0, 0.0, second, 500.0, 300.0, deltas, *args)
    moments = surface_likelihood_moments_numpy(second, np.zeros(3), half, step, pings, sig_u)
    assert own == pytest.approx(math.sqrt(max(moments[2], moments[3])), abs=1e-9)
    rival = flat.copy()
    rival[2, half, half] = 0.2  # as good as the second square's best, 583 m away
    both = rl.both_squares_std(rival, 0.0, 0.0, second, 500.0, 300.0, deltas, *args)
    assert both > 200.0
    for first, e2, n2 in ((flat, 500.0, 300.0), (rival, 500.0, 300.0), (rival, 40.0, -30.0), (second, 20.0, 0.0)):
        np.testing.assert_allclose(rl.both_squares_std(first, 0.0, 0.0, second, e2, n2, deltas, *args),
                                   rl.both_squares_std_numpy(first, 0.0, 0.0, second, e2, n2, *args), rtol=1e-9)
    # the second square inside the first (same centre): only the first square's candidates count
    assert rl.both_squares_std(rival, 0.0, 0.0, second, 0.0, 0.0, deltas, *args) == pytest.approx(
        rl.both_squares_std(rival, 0.0, 0.0, flat, 5000.0, 5000.0, deltas, *args), abs=1e-6)


def test_a_second_square_match_without_a_rival_is_kept_with_both_squares():
    """``recovery_second_ambiguity: both-squares`` keeps section 17's rescue when the first square holds nothing as
    good (the truth outside it), jitted and numpy alike; its neutral value ``its-square`` leaves the cell key and the
    search bundle as they were."""
    zmap = _toy_map()
    truth, inc, offsets, up = _single_beam_case(zmap, noise=0.3)
    k = 79
    far = truth[k] + [180.0, -160.0]
    nav = np.tile(truth[k] + [35.0, 25.0], (k + 1, 1))
    own = _reloc(zmap, offsets, 60, half_side=100.0, nav_en=nav)
    both = _reloc(zmap, offsets, 60, half_side=100.0, nav_en=nav, both_squares=True)
    np.testing.assert_array_equal(rl.relocalise_around(inc, up, k, far[0], far[1], both),
                                  rl.relocalise_around(inc, up, k, far[0], far[1], own))
    assert rl.relocalise_around(inc, up, k, far[0], far[1], both)[0]
    want = rl.relocalise_around_numpy(inc, up, k, far[0], far[1], both)
    assert want[0]
    np.testing.assert_allclose(want[1:3], rl.relocalise_around(inc, up, k, far[0], far[1], both)[1:3], atol=1e-9)
    assert Scenario(filter={"recovery_second_ambiguity": "its-square"}).cell_key() == Scenario().cell_key()
    assert Scenario(filter={"recovery_second_ambiguity": "both-squares"}).cell_key() != Scenario().cell_key()
    assert not rl.global_search_of(Scenario().filter, nav).both_squares
    assert rl.global_search_of(Scenario(filter={"recovery_second_ambiguity": "both-squares"}).filter, nav).both_squares


def test_the_second_square_is_an_option_with_a_neutral_value():
    """``estimate`` (the neutral value, the literal profile's) leaves every cell key as it was before the option and
    the search bundle without navigation centres; ``estimate-then-navigation`` and the default since docs/filters.md
    18.1, ``estimate-then-distant-navigation``, keep the navigation solution the method passes."""
    from tanbench.profiles import profile_settings

    nav = np.arange(20.0).reshape(10, 2)
    neutral = Scenario(filter={"recovery_search_around": "estimate"})
    assert Scenario().filter.recovery_search_around == "estimate-then-distant-navigation"
    assert "recovery_search_around" not in str(neutral.identity())
    assert neutral.cell_key() != Scenario().cell_key()
    assert profile_settings("zhou2017-literal")["filter.recovery_search_around"] == "estimate"
    second = Scenario(filter={"recovery_search_around": "estimate-then-navigation"})
    assert second.cell_key() != Scenario().cell_key() != neutral.cell_key()
    assert rl.global_search_of(neutral.filter, nav).nav_en is None
    np.testing.assert_array_equal(rl.global_search_of(second.filter, nav).nav_en, nav)
    no_search = Scenario(filter={"recovery": "estimate", "recovery_search_around": "estimate-then-navigation"})
    assert rl.global_search_of(no_search.filter, nav) is None
    assert not rl.global_search_of(second.filter, nav).distant_only
    distant = Scenario(filter={"recovery_search_around": "estimate-then-distant-navigation"})
    search = rl.global_search_of(distant.filter, nav)
    assert search.distant_only and search.nav_en is not None


def test_global_is_the_default_and_estimate_its_neutral_value():
    """Since docs/filters.md 10.1 the default is global; "estimate" (the behaviour before the option) leaves
    the cell key as it was, and every cell compiles the same loop (the search compiles on a run's first need)."""
    from tanbench.runner import plan

    before = Scenario(filter={"recovery": "estimate"})
    assert before.cell_key() == Scenario(filter={"recovery": "estimate", "recovery_profile_updates": 240,
                                                 "recovery_heading_span_deg": 90.0,
                                                 "recovery_heading_step_deg": 2.0,
                                                 "recovery_fix_std_m": 10.0}).cell_key()
    assert Scenario().filter.recovery == "global"
    assert Scenario().cell_key() != before.cell_key()
    assert Scenario().cell_key() == Scenario(filter={"recovery": "global"}).cell_key()
    assert rl.global_search_of(before.filter) is None
    search = rl.global_search_of(Scenario().filter)
    assert search.window == 240 and search.half_side == 500.0
    assert plan.kernel_variant("tight-sbe", Scenario()) == ""
    assert plan.kernel_variant("tight-sbe", before) == ""
    assert plan.kernel_variant("loose-dvl", before) == ""


def test_map_of_grid_reads_the_heights():
    from tanbench.terrain.grid import node_grid_of

    zmap = _toy_map(n=30)
    for z2 in (None, np.ones_like(zmap.z)):
        got = rl.map_of_grid(node_grid_of(*zmap, z2=z2))
        np.testing.assert_array_equal(got.z, zmap.z)
        assert got[1:] == tuple(zmap[1:])


@pytest.mark.parametrize("name", ["tight-sbe"])
def test_tight_loop_runs_through_the_search(name):
    """A filter made to diverge often (a tight divergence test) runs through the global search."""
    from tanbench.methods import get, method_context
    from tanbench.runner.seeds import vehicle_seed
    from tanbench.simulation import simulate_vehicle

    scenario = short_scenario(duration_s=120.0, particles=300,
                              filter={"recovery": "global", "recovery_profile_updates": 30,
                                      "divergence_sigma": 0.5, "divergence_steps": 2})
    vehicle = simulate_vehicle(scenario, vehicle_seed(11, scenario, 0))
    out = get(name).run(method_context(scenario, name, vehicle, np.random.SeedSequence(5, spawn_key=(0, 2)), get(name)))
    assert np.all(np.isfinite(out.east)) and np.all(np.isfinite(out.north))
    assert out.reinit[30:].sum() > 0


def _one_pass_with_the_search(x, rng, track, ranges, beams, grid, settings, out, search=None):
    """The tight loop as it ran before the search was compiled on first need: one pass, the search's
    bundle given from the start."""
    from tanbench.filters import tight

    euler_step, shared = tight.loop_options(settings.readings, settings.rs)
    reloc = None if search is None else rl.relocaliser(search, track, beams, ranges, grid, settings.model.sig_u)
    tight._tight_loop(x, rng, track, ranges, beams, grid, settings, out, reloc,
                      track.euler_in if euler_step else None, settings.rs if shared else None, False)


@pytest.mark.parametrize("random_numbers", ["fast", "numpy"])
def test_a_diverging_run_is_the_one_pass_run(monkeypatch, random_numbers):
    """The loop stops at its first search and the run is done again from its start with the search
    (tight_filter_loop): every output is the one a single pass with the search's bundle gives, with
    either random-number stream (their states put back by rng_state / set_rng_state); a run that never
    searches takes one pass."""
    from tanbench.filters import tight
    from tanbench.methods import get, method_context
    from tanbench.methods import tight as tight_method
    from tanbench.runner.seeds import vehicle_seed
    from tanbench.simulation import simulate_vehicle

    def run(scenario, seed):
        vehicle = simulate_vehicle(scenario, vehicle_seed(11, scenario, 0))
        ctx = method_context(scenario, "tight-sbe", vehicle, np.random.SeedSequence(seed, spawn_key=(0, 2)),
                             get("tight-sbe"))
        return get("tight-sbe").run(ctx)

    passes = []
    loop = tight._tight_loop
    monkeypatch.setattr(tight, "_tight_loop", lambda *args: passes.append(args[-1]) or loop(*args))
    diverging = short_scenario(duration_s=120.0, particles=300,
                               filter={"recovery_profile_updates": 30, "divergence_sigma": 0.5,
                                       "divergence_steps": 2, "random_numbers": random_numbers})
    two = run(diverging, 5)
    assert passes == [True, False] and two.reinit[30:].sum() > 0
    with monkeypatch.context() as m:
        m.setattr(tight_method, "tight_filter_loop", _one_pass_with_the_search)
        one = run(diverging, 5)
    for name in ("east", "north", "up", "yaw", "var_e", "var_n", "cov_en", "ess", "reinit"):
        np.testing.assert_array_equal(getattr(two, name), getattr(one, name), err_msg=name)
    np.testing.assert_array_equal(two.extra["healthy"], one.extra["healthy"])
    passes.clear()
    calm = run(short_scenario(duration_s=60.0, particles=300, filter={"random_numbers": random_numbers}), 5)
    assert passes == [True] and not calm.reinit[1:].any()


@pytest.mark.parametrize("random_numbers", ["fast", "numpy"])
def test_rng_state_puts_the_stream_back(random_numbers):
    from tanbench.filters.rng import fill_normals, loop_rng, rng_state, set_rng_state

    rng = loop_rng(np.random.default_rng(np.random.SeedSequence(3)), random_numbers)
    first, again = np.empty(1001), np.empty(1001)
    state = rng_state(rng)
    fill_normals(rng, first)
    set_rng_state(rng, state)
    fill_normals(rng, again)
    np.testing.assert_array_equal(first, again)
    fill_normals(rng, again)
    assert not np.array_equal(first, again)
