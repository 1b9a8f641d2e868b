"""Posterior Cramér-Rao bound (PCRB) of terrain-aided navigation, Tichavský's recursion.

How well could *any* estimator do, given the filter's own motion model, the sonar's beam
geometry, the terrain slopes under the true footprints and the range noise? The bound's
information matrix obeys (Tichavský, Muravchik & Nehorai 1998; additive Gaussian
process noise, so in its covariance form, which also holds for a singular Q)

    J_0     = J_prior + J_z(0)
    J_{k+1} = (Q_k + F_k J_k^{-1} F_k^T)^{-1} + J_z(k+1),        PCRB_k = J_k^{-1}

with F_k the Jacobian of the filter's propagation over interval k and Q_k its process
noise. Two state sets (``STATE_SETS``):

* ``position``: (E, N), the loosely coupled filter's state;
* ``full``: (E, N, psi, eps_x, eps_z), the tightly coupled filter's horizontal position,
  heading and gyro biases. Up, pitch and roll are treated as known (the pressure sensor
  and levelling pin them to a few cm and 0.1 deg); knowing more can only lower a bound,
  so this is still a lower bound on the position and heading errors.

The measurement information of a beam i with nav-frame unit vector b_i and true range
r_i hitting the terrain h(E, N) at footprint p_i = x + r_i b_i follows from the implicit
range r(x) defined by f(x + r b) = 0, f(p) = p_u - h(p_e, p_n):

    dr/dE = h_e / D,   dr/dN = h_n / D,   dr/dpsi = -r (h_e b_n - h_n b_e) / D,
    D = b_u - h_e b_e - h_n b_n,

and J_z = sum_i s_i s_i^T / sigma_r^2 with s_i = dr/dx. The terrain gradient (h_e, h_n)
is the navigation map's (what a filter can know) at the *true* footprint. The range
noise is uniform (half-width ``noise_m``), which has no regular Fisher information, so
sigma_r^2 is the variance of the uniform, ``noise_m^2 / 3``: the Gaussian of equal
variance (docs/model.md, section 9, says why). The expectation over the state is a Monte
Carlo average of J_z (and of F) over the runs' true trajectories; tanbench's true
trajectory is fixed by the world (not by the run's seed), so in every committed sweep
this average is exact with one trajectory.

A second bound, reported beside this one and never replacing it (``MAP_BOUND_COLUMN``,
docs/model.md 9.1): the same recursion with each beam's variance sigma_r^2 + m(p_i), m the
navigation map's variance grid that the filters' map-aware likelihood charges
(``terrain.representation.filter_map_variance``: the representation term plus the map's
declared node error) at the true footprint, NaN (off the grid) taken as 0. It treats the
map's error as independent between pings, which it is not, so it is still optimistic.

Prior: the filter's initial square of side ``filter.initial_area_m`` is uniform; its
variance side^2/12 is used (a uniform prior, too, has no regular Fisher information),
with Gaussians of the filter's initial heading and gyro-bias std.

The recursion is a loop of K small (2x2 or 5x5) solves: a few ms in numpy, so there is
no jitted kernel here.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pandas as pd

from tanbench.config import Scenario
from tanbench.filters.bias_walk import tight_bias_walk_std
from tanbench.navigation.increments import D0E, D0N, JAXE, JAXN, JAZE, JAZN, SX, SZ, compute_increments
from tanbench.sensors.sonar import altimeter_beam_vectors, dvl_beam_vectors
from tanbench.sensors.multibeam import sensor_fan
from tanbench.simulation import noise_free_swath, noise_free_world
from tanbench.terrain import navigation_map
from tanbench.terrain.grid import Map
from tanbench.terrain.representation import filter_map_variance
from tanbench.terrain.stats import gradient
from tanbench.vehicle.attitude import dcm_body_to_nav_numpy

STATE_SETS = {"position": ("E", "N"), "full": ("E", "N", "psi", "eps_x", "eps_z")}


# the per-update columns of a bound (what ``bound_frame`` returns besides t)
BOUND_COLUMNS = ("pcrb_e_m", "pcrb_n_m", "pcrb_horizontal_m", "pcrb_heading_deg")
# the horizontal std of the second bound, with the map's declared error in each beam's variance
# (what ``method_bound`` adds to ``BOUND_COLUMNS``; scoring reads it, no method sees it)
MAP_BOUND_COLUMN = "pcrb_map_horizontal_m"


@dataclass(frozen=True)
class TrueTrack:
    """One true trajectory at the filter's update times."""

    t: np.ndarray  # (K,) s
    pos: np.ndarray  # (K, 3) east, north, up
    pitch: np.ndarray  # (K,) rad
    roll: np.ndarray
    yaw: np.ndarray
    ranges: np.ndarray  # (K, m) true ranges of the beams, NaN = no bottom
    increments: np.ndarray  # (K-1, 12) the truth's interval increments (navigation/increments.py)


@dataclass(frozen=True)
class BoundModel:
    """The filter's model, as far as the bound needs it (per-update noise, prior)."""

    states: str  # "position" or "full"
    initial_area_m: float
    initial_std_heading_rad: float
    initial_std_bias_rad_s: float
    position_noise_m: float  # per update, each of east and north
    heading_noise_rad: float  # per update
    cross_track_heading_rad: float  # loose filter: the heading uncertainty's cross-track term
    range_std_m: float  # std of the range noise (Gaussian of the uniform's variance)
    bias_noise_rad_s: float = 0.0  # per update, each gyro bias (filter.gyro_bias_noise; 0: Table 2's none)

    @property
    def state_names(self) -> tuple[str, ...]:
        names = STATE_SETS[self.states]
        if self.states == "full" and self.initial_std_bias_rad_s == 0.0 and self.bias_noise_rad_s == 0.0:
            names = names[:3]  # biases known exactly (zero prior, no process noise): not states
        return names

    def prior_information(self) -> np.ndarray:
        d = len(self.state_names)
        j = np.zeros((d, d))
        j[0, 0] = j[1, 1] = 12.0 / self.initial_area_m**2
        if d > 2:
            j[2, 2] = 1.0 / max(self.initial_std_heading_rad, 1e-6) ** 2
        if d > 3:
            j[3, 3] = j[4, 4] = 1.0 / max(self.initial_std_bias_rad_s, 1e-12) ** 2
        return j


def model_for(scenario, states: str, sensor: str = "dvl") -> BoundModel:
    """The bound model for ``states`` ("full": the tight filter's, "position": the loose one's) in ``scenario``;
    the range noise is the sonar's: the multibeam's own std for ``sensor`` "mbe" (its pointing error is left
    out, which can only lower the bound), else the uniform's of half-width ``noise_m``."""
    f = scenario.filter
    if states == "full":
        sig_pos = scenario.position_noise_m()
        cross = 0.0
    else:
        sig_pos = scenario.position_step_m
        cross = f.initial_std_heading_rad if f.loose_heading_noise else 0.0
    return BoundModel(
        states=states, initial_area_m=f.initial_area_m,
        initial_std_heading_rad=f.initial_std_heading_rad,
        initial_std_bias_rad_s=f.initial_std_gyro_bias_rad_s,
        position_noise_m=sig_pos, heading_noise_rad=scenario.attitude_noise_rad,
        cross_track_heading_rad=cross,
        range_std_m=scenario.sensors.multibeam_range_noise_m if sensor == "mbe" else scenario.noise_m / math.sqrt(3.0),
        bias_noise_rad_s=tight_bias_walk_std(scenario) if states == "full" else 0.0)


def range_sensitivities(grad_e, grad_n, beam_nav, ranges) -> np.ndarray:
    """dr/d(E, N, psi) (..., 3) of beams with nav-frame unit vectors ``beam_nav`` (..., 3).

    NaN gradients or ranges (off the map, no bottom) give zero sensitivity: no information.
    """
    be, bn, bu = beam_nav[..., 0], beam_nav[..., 1], beam_nav[..., 2]
    den = bu - grad_e * be - grad_n * bn
    out = np.stack([grad_e / den, grad_n / den, -ranges * (grad_e * bn - grad_n * be) / den], axis=-1)
    return np.where(np.isfinite(out), out, 0.0)


def ping_information(sens: np.ndarray, range_std_m: float, d: int, weights: np.ndarray | None = None) -> np.ndarray:
    """Fisher information (..., d, d) of one ping: sum over beams (axis -2) of s s^T / sigma_r^2.

    ``sens`` (..., m, 3) from :func:`range_sensitivities`; d = 2 keeps (E, N), d >= 3 adds psi
    (and zero rows for the gyro biases, which no ping observes directly). ``weights`` (..., m):
    each beam's sigma_r^2 / (its variance), in (0, 1] (None: the range noise alone); a weight
    of exactly 1 gives the same bits as None.
    """
    s = sens[..., : min(d, 3)]
    if weights is not None:
        s = s * np.sqrt(weights)[..., None]
    info = np.einsum("...bi,...bj->...ij", s, s) / range_std_m**2
    if d > 3:
        pad = np.zeros(info.shape[:-2] + (d, d))
        pad[..., :3, :3] = info
        info = pad
    return info


def track_information(track: TrueTrack, beams_body: np.ndarray, nav_map: Map, model: BoundModel,
                      map_variance: Map | None = None) -> np.ndarray:
    """J_z(k) (K, d, d) along one true track on ``nav_map``; with ``map_variance`` (a grid of m(p) on
    the map's nodes, :func:`map_variance_grid`), each beam's variance is sigma_r^2 + m(p_i) at its
    true footprint (NaN, off the grid: 0)."""
    c = dcm_body_to_nav_numpy(track.pitch, track.roll, track.yaw)  # (K, 3, 3)
    b_nav = np.einsum("kij,bj->kbi", c, beams_body)  # (K, m, 3)
    foot = track.pos[:, None, :] + track.ranges[..., None] * b_nav
    ge, gn = gradient(nav_map, foot[..., 0], foot[..., 1])
    sens = range_sensitivities(ge, gn, b_nav, track.ranges)
    weights = None
    if map_variance is not None:
        r2 = model.range_std_m**2
        weights = r2 / (r2 + np.nan_to_num(map_variance.elevation(foot[..., 0], foot[..., 1]), nan=0.0))
    return ping_information(sens, model.range_std_m, len(model.state_names), weights)


def map_variance_grid(scenario, nav_map: Map) -> Map:
    """The variance m(p) the filters' map-aware likelihood charges on ``nav_map`` under ``scenario``'s filter
    (``terrain.representation.filter_map_variance``), as a grid on the map's nodes."""
    return Map(filter_map_variance(scenario.filter, nav_map), nav_map.e0, nav_map.n0, nav_map.res_e, nav_map.res_n)


def transition(increments: np.ndarray, model: BoundModel) -> tuple[np.ndarray, np.ndarray]:
    """(F, Q), each (K-1, d, d), of the filter's propagation linearised about the truth."""
    k = increments.shape[0]
    d = len(model.state_names)
    F = np.broadcast_to(np.eye(d), (k, d, d)).copy()
    Q = np.zeros((k, d, d))
    Q[:, 0, 0] = Q[:, 1, 1] = model.position_noise_m**2
    d0 = increments[:, [D0E, D0N]]
    if d >= 3:
        # d(position)/d(psi): the displacement rotates with the heading
        F[:, 0, 2] = -d0[:, 1]
        F[:, 1, 2] = d0[:, 0]
        Q[:, 2, 2] = model.heading_noise_rad**2
    if d >= 5:
        F[:, 0, 3], F[:, 1, 3], F[:, 2, 3] = increments[:, JAXE], increments[:, JAXN], increments[:, SX]
        F[:, 0, 4], F[:, 1, 4], F[:, 2, 4] = -increments[:, JAZE], -increments[:, JAZN], -increments[:, SZ]
        Q[:, 3, 3] = Q[:, 4, 4] = model.bias_noise_rad_s**2  # the filter's gyro-bias random walk, if any
    if model.cross_track_heading_rad > 0:
        perp = np.stack([-d0[:, 1], d0[:, 0]], axis=1)
        Q[:, :2, :2] += model.cross_track_heading_rad**2 * np.einsum("ki,kj->kij", perp, perp)
    return F, Q


def pcrb_recursion(prior_info: np.ndarray, F: np.ndarray, Q: np.ndarray, meas_info: np.ndarray) -> np.ndarray:
    """Bound covariances PCRB_k = J_k^{-1} (K, d, d) of the recursion in the module docstring."""
    K, d = meas_info.shape[0], prior_info.shape[0]
    out = np.empty((K, d, d))
    J = prior_info + meas_info[0]
    eye = np.eye(d)
    for k in range(K):
        P = np.linalg.solve(J, eye)
        P = 0.5 * (P + P.T)
        out[k] = P
        if k + 1 < K:
            pred = Q[k] + F[k] @ P @ F[k].T
            J = np.linalg.solve(pred, eye) + meas_info[k + 1]
    return out


def bound(tracks: list[TrueTrack], beams_body: np.ndarray, nav_map: Map, model: BoundModel,
          map_variance: Map | None = None) -> np.ndarray:
    """PCRB covariances (K, d, d): J_z and F averaged over ``tracks`` (the Monte Carlo expectation);
    with ``map_variance``, the second bound (beam variances with the map's, :func:`track_information`)."""
    if model.range_std_m <= 0:
        d = len(model.state_names)  # noise-free ranges: the bound is not defined (infinite information)
        return np.full((tracks[0].t.size, d, d), np.nan)
    info = np.mean([track_information(tr, beams_body, nav_map, model, map_variance) for tr in tracks], axis=0)
    fq = [transition(tr.increments, model) for tr in tracks]
    F = np.mean([f for f, _ in fq], axis=0)
    Q = np.mean([q for _, q in fq], axis=0)
    return pcrb_recursion(model.prior_information(), F, Q, info)


def bound_frame(t: np.ndarray, P: np.ndarray) -> pd.DataFrame:
    """Per-update bound stds: east, north, horizontal sqrt(P_EE + P_NN), heading (deg; NaN if absent)."""
    heading = np.degrees(np.sqrt(P[:, 2, 2])) if P.shape[1] > 2 else np.full(t.size, np.nan)
    return pd.DataFrame({"t": t, "pcrb_e_m": np.sqrt(P[:, 0, 0]), "pcrb_n_m": np.sqrt(P[:, 1, 1]),
                         "pcrb_horizontal_m": np.sqrt(P[:, 0, 0] + P[:, 1, 1]), "pcrb_heading_deg": heading})


def true_tracks(scenario, sensor: str) -> tuple[list[TrueTrack], np.ndarray]:
    """The runs' true trajectories of ``scenario`` at its filter updates, and the sensor's beams.

    ``sensor`` is "dvl", "sbe" or "mbe" (the multibeam's nominal fan; NaN rows where it does not
    ping). The truth and its noise-free ranges depend on the world
    only (``noise_free_world``), so every run of a cell shares them: one track is the
    exact Monte Carlo average.
    """
    world_json = json.dumps(scenario.world_spec(), sort_keys=True)
    truth, ping_idx, dvl_true, sbe_true = noise_free_world(world_json)
    s = scenario.sensors
    if sensor == "mbe":
        rows, swath = noise_free_swath(world_json)
        ranges = np.full((ping_idx.size, swath.shape[1]), np.nan)
        ranges[rows] = swath
        beams = sensor_fan(s)[1]
    elif sensor == "dvl":
        ranges, beams = dvl_true, dvl_beam_vectors(s.beam_tilt_deg, s.beam_azimuths_deg)
    else:
        ranges, beams = sbe_true, altimeter_beam_vectors()
    return [update_track(scenario, truth, ping_idx, ranges)], beams


def update_track(scenario, truth, ping_idx: np.ndarray, ranges) -> TrueTrack:
    """A true trajectory at the scenario's filter updates: ``truth`` (t, dt, pos, pitch, roll, yaw at
    the IMU samples; a simulation's truth or a mission log's reference), the pings' IMU sample
    indices and the beams' true ranges (pings, m)."""
    step = int(round(scenario.sampling_time_s * scenario.sensors.sonar_rate_hz))
    rows = np.arange(0, ping_idx.size, step)
    upd = ping_idx[rows]
    inc = compute_increments(truth.dt, truth.pos, truth.pitch, truth.roll, truth.yaw, upd)
    return TrueTrack(t=truth.t[upd], pos=truth.pos[upd], pitch=truth.pitch[upd], roll=truth.roll[upd],
                     yaw=truth.yaw[upd], ranges=np.asarray(ranges)[rows], increments=inc)


def bound_series(tracks: list[TrueTrack], beams_body: np.ndarray, nav_map: Map, scenario, states: str,
                 sensor: str = "dvl") -> pd.DataFrame:
    """The PCRB series (t, ``BOUND_COLUMNS``) along ``tracks`` for the filter of ``scenario`` (``states``)
    weighing by ``sensor``'s beams, and beside it the second bound's horizontal std (``MAP_BOUND_COLUMN``:
    the beams' variances with the map's that the filter of ``scenario`` charges on ``nav_map``)."""
    model = model_for(scenario, states, sensor)
    out = bound_frame(tracks[0].t, bound(tracks, beams_body, nav_map, model))
    with_map = bound(tracks, beams_body, nav_map, model, map_variance_grid(scenario, nav_map))
    out[MAP_BOUND_COLUMN] = bound_frame(tracks[0].t, with_map)["pcrb_horizontal_m"]
    return out


def method_bound(scenario, bound: tuple[str, str] | None) -> pd.DataFrame | None:
    """The PCRB series (t, ``BOUND_COLUMNS``, then ``MAP_BOUND_COLUMN``: the second bound's horizontal std)
    of a method in ``scenario``; ``bound`` is its registry record's (sensor, states), handed down by the
    caller (None: no bound)."""
    if bound is None:
        return None
    return _bound_cached(json.dumps(scenario.normalized(), sort_keys=True), *bound).copy()


@lru_cache(maxsize=32)
def _bound_cached(scenario_json: str, sensor: str, states: str) -> pd.DataFrame:
    scenario = Scenario(**json.loads(scenario_json))
    tracks, beams = true_tracks(scenario, sensor)
    return bound_series(tracks, beams, navigation_map(scenario.terrain, scenario.map_resolution_m), scenario, states,
                        sensor)
