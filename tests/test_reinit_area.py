"""``filter.reinit_area_m``: the square a reinitialised tight cloud is redrawn over.

The option is the worked example of docs/architecture.md ("a new particle-filter option
is the spec, the kernel that reads it and this test"): its neutral value (None: the
initial square) changes no cell key and no number; a small square gives a reinitialised
cloud that small.
"""

from __future__ import annotations

import numpy as np

from filters_support import filter_seed, short_scenario, vehicle_seed
from tanbench.config import Scenario
from tanbench.filters.rng import loop_rng
from tanbench.filters.tight import draw_tight, tight_prior_of
from tanbench.methods import run_method
from tanbench.simulation import simulate_vehicle


def test_neutral_value_keeps_the_cell_key():
    assert Scenario().cell_key() == Scenario(filter={"reinit_area_m": None}).cell_key()
    assert Scenario().cell_key() != Scenario(filter={"reinit_area_m": 40.0}).cell_key()


def test_prior_half_sides():
    prior = tight_prior_of(Scenario(filter={"initial_area_m": 150.0, "reinit_area_m": 40.0}).filter)
    assert (prior.half_side, prior.reinit_half_side) == (75.0, 20.0)
    assert tight_prior_of(Scenario().filter).reinit_half_side == 75.0


def test_draw_tight_stays_in_its_square():
    prior = tight_prior_of(Scenario(filter={"reinit_area_m": 40.0}).filter)
    x = np.empty((8, 20000))
    draw_tight(x, loop_rng(np.random.default_rng(3), "fast"), 100.0, -50.0, -30.0, 0.0, 0.0, 0.0, prior,
               prior.reinit_half_side)
    assert np.abs(x[0] - 100.0).max() <= 20.0 and np.abs(x[1] + 50.0).max() <= 20.0
    # a uniform square of half side 20 m: std 20/sqrt(3) = 11.5 m per axis (20000 draws: +-0.1 m)
    assert abs(x[0].std() - 20.0 / np.sqrt(3.0)) < 0.3


def _reinit_run(reinit_area_m):
    # divergence_sigma far below any fit: the filter is declared diverged every divergence_steps updates
    sc = short_scenario(duration_s=60.0, particles=300,
                        filter={"divergence_sigma": 1e-3, "divergence_steps": 5, "reinit_area_m": reinit_area_m})
    vehicle = simulate_vehicle(sc, vehicle_seed(0))
    return run_method(sc, "tight-dvl", vehicle, filter_seed(0, 1))


def test_neutral_value_reproduces_the_filter_bit_for_bit():
    default, same = _reinit_run(None), _reinit_run(150.0)
    for name in ("est_e", "est_n", "var_e", "var_n", "reinit"):
        np.testing.assert_array_equal(default.series[name], same.series[name])


def test_small_square_gives_a_small_reinitialised_cloud():
    wide, small = _reinit_run(None), _reinit_run(10.0)
    after = np.flatnonzero(small.series["reinit"])[:-1] + 1  # the updates right after a redraw
    assert after.size >= 5
    np.testing.assert_array_equal(wide.series["reinit"], small.series["reinit"])
    spread_small = np.sqrt(small.series["var_e"][after] + small.series["var_n"][after])
    spread_wide = np.sqrt(wide.series["var_e"][after] + wide.series["var_n"][after])
    # a cloud inside a 10 m square has at most 5 m std per axis whatever its weights: at most
    # 5 sqrt(2) = 7.07 m horizontally, plus one update's process noise (0.07 m) after the redraw
    assert spread_small.max() < 5.0 * np.sqrt(2.0) + 0.1
    assert spread_wide.mean() > spread_small.mean()
