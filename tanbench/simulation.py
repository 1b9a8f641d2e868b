"""One Monte Carlo run's vehicle data: truth, sensor measurements and navigation solution.

Everything here depends only on the scenario's *world* (terrain, trajectory, sensors,
initial navigation errors; see ``Scenario.world_spec``) and on the run's seed, never on
the filter: every method of a run, and cells that differ only in filter settings, take
the same :class:`VehicleData` (common random numbers). It is split in two: the
:class:`Observations` a method is given, and the truth that only scoring reads. Each sensor draws from its
own named stream of the run's ``SeedSequence``, so adding a sensor never shifts another's
random numbers. The truth and the noise-free sonar ranges are deterministic per world
and cached per process.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from tanbench.config import Scenario
from tanbench.errors import TanbenchError
from tanbench.navigation.increments import SharedIncrements
from tanbench.navigation.ins import run_strapdown
from tanbench.sensors.dvl import measure_velocity
from tanbench.sensors.faults import (add_current, add_outliers, delay_pings, dropout_mask, far_start_offset,
                                     map_offset_positions, tide_offset)
from tanbench.sensors.imu import ImuErrors, measure_imu
from tanbench.sensors.multibeam import measure_swath, sensor_fan, true_swath
from tanbench.sensors.pressure import measure_depth
from tanbench.sensors.sonar import altimeter_beam_vectors, dvl_beam_vectors, measure_ranges, true_ranges
from tanbench.terrain import truth_map
from tanbench.terrain.mosaic import find_holes, over_holes
from tanbench.vehicle.trajectory import MotionPlan, Truth, paper_plan, simulate_truth, survey_plan, vehicle_run_plan
from tanbench.vehicle.attitude import yaw_to_heading_deg

# named random streams of a run (spawn-key suffixes)
STREAM_INITIAL, STREAM_IMU, STREAM_DVL_VELOCITY, STREAM_DVL_RANGES, STREAM_SBE_RANGES, STREAM_PRESSURE = range(6)
# world faults (sensors/faults.py): new streams, so faults off leave every number above unchanged
STREAM_TIDE, STREAM_DROPOUT, STREAM_DVL_OUTLIERS, STREAM_SBE_OUTLIERS = range(6, 10)
STREAM_FAR_START = 10
# the multibeam (sensors/multibeam.py): its own streams, so switching it on changes no other number
STREAM_MBE_ANGLES, STREAM_MBE_RANGES, STREAM_MBE_OUTLIERS = range(11, 14)
MIN_ALTITUDE_M = 1.0


@dataclass
class NavSolution:
    """The navigation system's estimate at every IMU sample."""

    pos: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    yaw: np.ndarray


@dataclass
class Observations:
    """What the vehicle itself observes: its sensors' outputs and its navigation solution.

    This is all a method is given (with the scenario and the navigation map); the truth
    stays in :class:`VehicleData` for scoring.
    """

    t: np.ndarray  # time of every IMU sample, s
    dt: float  # IMU sampling interval, s
    latitude_rad: float
    gyro: np.ndarray
    accel: np.ndarray
    dvl_velocity: np.ndarray
    depth: np.ndarray
    ping_idx: np.ndarray  # IMU sample index of each sonar ping
    dvl_beams: np.ndarray  # (4, 3) body-frame unit vectors
    sbe_beams: np.ndarray  # (1, 3)
    dvl_ranges: np.ndarray  # (pings, 4) measured ranges, NaN = no bottom
    sbe_ranges: np.ndarray  # (pings, 1)
    nav: NavSolution
    mbe_beams: np.ndarray | None = None  # (N, 3) the multibeam's nominal fan; None without a multibeam
    mbe_ranges: np.ndarray | None = None  # (pings, N) at the DVL pings, NaN rows where it did not ping
    # the run's increments tables, computed once and shared by its methods (their copies of these observations)
    shared_increments: SharedIncrements = field(default_factory=SharedIncrements, repr=False, compare=False)


@dataclass
class VehicleData:
    """One run: what the vehicle observes (``obs``) and the truth that only scoring reads."""

    obs: Observations
    truth: Truth
    imu_errors: ImuErrors
    dvl_scale_error: float
    initial_position_error: np.ndarray  # (2,) nav - truth at t=0, m
    initial_heading_error_deg: float


def motion_plan(scenario: Scenario) -> MotionPlan:
    """The true path of a scenario."""
    tr = scenario.trajectory
    if tr.kind == "paper":
        plan = paper_plan(tr.start_enu_m, tr.speed_mps, tr.legs, tr.leg_spacing_m, tr.leg_length_m,
                          tr.first_turn, tr.dive_pitch_rate_deg_s, tr.cruise_s)
    elif tr.kind == "vehicle-run":
        plan = vehicle_run_plan(tr.start_enu_m, tr.speed_mps, legs=3, leg_spacing=tr.leg_spacing_m,
                                first_turn=tr.first_turn)
    else:
        plan = survey_plan(tr.centre_en_m, tr.heading_deg,
                           tr.leg_length_m if tr.leg_length_m is not None else 400.0,
                           tr.leg_spacing_m, tr.legs, tr.depth_m, tr.speed_mps)
    if scenario.duration_s is not None:
        plan = _cut(plan, scenario.duration_s)
    return plan


def _cut(plan: MotionPlan, duration: float) -> MotionPlan:
    if duration > plan.duration + 1e-9:
        raise TanbenchError(
            f"duration_s ({duration:g} s) is longer than the trajectory ({plan.duration:g} s)")
    ends = np.cumsum(plan.durations)
    keep = np.searchsorted(ends, duration - 1e-9) + 1
    durations = plan.durations[:keep].copy()
    durations[-1] -= ends[keep - 1] - duration if ends[keep - 1] > duration else 0.0
    return MotionPlan(plan.start_enu, plan.speed, plan.yaw0, durations, plan.pitch_rates[:keep],
                      plan.yaw_rates[:keep], plan.pitch0)


def simulate_vehicle(scenario: Scenario, seed: np.random.SeedSequence) -> VehicleData:
    """Simulate one run's vehicle data for ``scenario`` from the run's ``seed``."""
    world_json = json.dumps(scenario.world_spec(), sort_keys=True)
    truth, ping_idx, dvl_true, sbe_true = noise_free_world(world_json)
    s = scenario.sensors

    def stream(k):
        return np.random.default_rng(np.random.SeedSequence(seed.entropy, spawn_key=tuple(seed.spawn_key) + (k,)))

    fl = scenario.faults
    gyro, accel, imu_errors = measure_imu(truth.omega_ib, truth.f_body, truth.dt, s, stream(STREAM_IMU))
    lost = dropout_mask(ping_idx.size, fl.dropout_rate_per_ping, fl.dropout_mean_pings, stream(STREAM_DROPOUT))
    dvl_velocity, scale = measure_velocity(truth.vel_body, ping_idx, s.dvl_scale_error, s.dvl_noise_mps,
                                           stream(STREAM_DVL_VELOCITY), lost if lost.any() else None)
    depth = measure_depth(truth.pos[:, 2], s.pressure_error_percent, s.pressure_full_scale_m,
                          stream(STREAM_PRESSURE))
    if fl.tide_bias_m or fl.tide_amplitude_m:
        phase = stream(STREAM_TIDE).uniform(0.0, 2.0 * math.pi)
        depth = depth + tide_offset(truth.t, fl.tide_bias_m, fl.tide_amplitude_m, fl.tide_period_s, phase)
    speed_scale = 1.0 + fl.sound_speed_scale_error
    true_noise = scenario.noise_m * fl.range_noise_scale if fl.range_noise_scale != 1.0 else scenario.noise_m
    dvl_ranges = measure_ranges(dvl_true * speed_scale if fl.sound_speed_scale_error else dvl_true,
                                true_noise, stream(STREAM_DVL_RANGES))
    sbe_ranges = measure_ranges(sbe_true * speed_scale if fl.sound_speed_scale_error else sbe_true,
                                true_noise, stream(STREAM_SBE_RANGES))
    dvl_ranges = add_outliers(dvl_ranges, fl.outlier_fraction, s.max_range_m, stream(STREAM_DVL_OUTLIERS))
    sbe_ranges = add_outliers(sbe_ranges, fl.outlier_fraction, s.max_range_m, stream(STREAM_SBE_OUTLIERS))
    if lost.any():
        dvl_ranges = np.where(lost[:, None], np.nan, dvl_ranges)
    if fl.sonar_latency_pings:
        dvl_ranges = delay_pings(dvl_ranges, fl.sonar_latency_pings)
        sbe_ranges = delay_pings(sbe_ranges, fl.sonar_latency_pings)
    mbe_beams = mbe_ranges = None
    if s.multibeam_beams:
        mbe_beams = sensor_fan(s)[1]
        mbe_ranges = measure_swath(s, fl, truth_map(scenario.terrain), truth, ping_idx, noise_free_swath(world_json),
                                   lost if lost.any() else None, stream(STREAM_MBE_ANGLES), stream(STREAM_MBE_RANGES),
                                   stream(STREAM_MBE_OUTLIERS))

    nav_cfg = scenario.navigation
    init = stream(STREAM_INITIAL)
    pos_err = init.uniform(-0.5, 0.5, 2) * nav_cfg.initial_position_error_m
    if fl.far_start_fraction:
        pos_err = pos_err + far_start_offset(fl.far_start_fraction, fl.far_start_m, stream(STREAM_FAR_START))
    yaw_err = -math.radians(nav_cfg.initial_heading_error_deg)  # heading is -yaw
    # A GPS-aided alignment at the surface estimates the accelerometers' turn-on bias (it
    # is observable there, unlike submerged); the in-run part and the noise remain.
    nav_accel = accel - imu_errors.accel_turn_on if nav_cfg.accel_bias_calibrated else accel
    pos, pitch, roll, yaw = run_strapdown(
        truth.dt, gyro, nav_accel, dvl_velocity, depth, truth.pos[0, :2] + pos_err,
        truth.yaw[0] + yaw_err, truth.latitude_rad, nav_cfg.level_window_s, nav_cfg.level_compensation)
    for arr in (pos, pitch, roll, yaw):  # read-only: the run's methods share what is derived from it
        arr.setflags(write=False)
    obs = Observations(
        t=truth.t, dt=truth.dt, latitude_rad=truth.latitude_rad, gyro=gyro, accel=accel,
        dvl_velocity=dvl_velocity, depth=depth, ping_idx=ping_idx,
        dvl_beams=dvl_beam_vectors(s.beam_tilt_deg, s.beam_azimuths_deg), sbe_beams=altimeter_beam_vectors(),
        dvl_ranges=dvl_ranges, sbe_ranges=sbe_ranges, nav=NavSolution(pos, pitch, roll, yaw),
        mbe_beams=mbe_beams, mbe_ranges=mbe_ranges)
    return VehicleData(obs=obs, truth=truth, imu_errors=imu_errors, dvl_scale_error=scale,
                       initial_position_error=pos_err, initial_heading_error_deg=nav_cfg.initial_heading_error_deg)


# worlds handed to this process ready-made (a sweep's workers get the parent's)
_PRELOADED_WORLDS: dict[str, tuple] = {}
PRELOAD_WORLDS_MAX = 4  # a sweep with more worlds lets each worker compute its own


def preload_worlds(worlds: dict[str, tuple]) -> None:
    """Use these :func:`noise_free_world` results (computed by another process, keyed by
    the world JSON) instead of recomputing them; they are made read-only as computed ones."""
    for key, (truth, ping_idx, dvl, sbe) in worlds.items():
        for arr in (truth.pos, truth.pitch, truth.yaw, dvl, sbe, ping_idx):
            arr.setflags(write=False)
        _PRELOADED_WORLDS[key] = (truth, ping_idx, dvl, sbe)


@lru_cache(maxsize=4)
def noise_free_world(world_json: str):
    """Truth at the IMU rate, ping indices and noise-free DVL/SBE ranges (cached per world;
    a world given by :func:`preload_worlds` is used as it is)."""
    given = _PRELOADED_WORLDS.get(world_json)
    if given is not None:
        return given
    world = json.loads(world_json)
    scenario = Scenario(**world)
    s = scenario.sensors
    plan = motion_plan(scenario)
    truth = simulate_truth(plan, s.imu_rate_hz, s.latitude_deg)
    fl = scenario.faults
    if fl.current_east_mps or fl.current_north_mps:
        add_current(truth, (fl.current_east_mps, fl.current_north_mps))
    tmap = truth_map(scenario.terrain)
    check_track_on_map(truth, tmap)
    ping_step = int(round(s.imu_rate_hz / s.sonar_rate_hz))
    ping_idx = np.arange(0, truth.t.size, ping_step)
    p = map_offset_positions(truth.pos[ping_idx], fl.map_offset_east_m, fl.map_offset_north_m)
    args = (p, truth.pitch[ping_idx], truth.roll[ping_idx], truth.yaw[ping_idx])
    bw = s.beam_footprint
    dvl = true_ranges(tmap, *args, dvl_beam_vectors(s.beam_tilt_deg, s.beam_azimuths_deg),
                      s.dvl_beamwidth_deg if bw else 0.0, s.max_range_m)
    sbe = true_ranges(tmap, *args, altimeter_beam_vectors(), s.altimeter_beamwidth_deg if bw else 0.0,
                      s.max_range_m)
    for arr in (truth.pos, truth.pitch, truth.yaw, truth.vel_body, dvl, sbe, ping_idx):
        arr.setflags(write=False)
    return truth, ping_idx, dvl, sbe


_SWATHS: dict[str, tuple] = {}  # world JSON -> (its truth, rows, ranges), for at most SWATHS_KEPT worlds
SWATHS_KEPT = 4


def noise_free_swath(world_json: str) -> tuple[np.ndarray, np.ndarray]:
    """The multibeam's (DVL ping rows of its pings, noise-free ranges (pings, N)) in a world
    (``sensors/multibeam.py``; read-only), kept while the world's cached truth is the same object."""
    truth, ping_idx, _, _ = noise_free_world(world_json)
    kept = _SWATHS.get(world_json)
    if kept is not None and kept[0] is truth:
        return kept[1], kept[2]
    scenario = Scenario(**json.loads(world_json))
    rows, ranges = true_swath(truth_map(scenario.terrain), truth, ping_idx, scenario.sensors)
    rows.setflags(write=False)
    ranges.setflags(write=False)
    if len(_SWATHS) >= SWATHS_KEPT:
        _SWATHS.pop(next(iter(_SWATHS)))
    _SWATHS[world_json] = (truth, rows, ranges)
    return rows, ranges


def check_track_on_map(truth: Truth, tmap) -> None:
    """Refuse a track that leaves the map, crosses a hole or runs into the seafloor."""
    e, n, u = truth.pos[::10, 0], truth.pos[::10, 1], truth.pos[::10, 2]
    t = truth.t[::10]
    inside = tmap.contains(e, n)
    if not inside.all():
        k = int(np.argmin(inside))
        raise TanbenchError(
            f"the trajectory leaves the map at t={t[k]:.0f} s, (E, N) = ({e[k]:.0f}, {n[k]:.0f}) m; "
            f"the map spans E {tmap.e0:.0f}..{tmap.e_max:.0f}, N {tmap.n0:.0f}..{tmap.n_max:.0f} m")
    check_no_holes(tmap, t, e, n, "terrain.fill_holes: true")
    floor = tmap.elevation(e, n)
    clearance = u - floor
    if clearance.min() < MIN_ALTITUDE_M and np.median(floor) > 0:
        raise TanbenchError(
            f"the map looks depth-positive: the seafloor under the track lies above the sea surface "
            f"(median elevation {np.median(floor):+.1f} m, range {floor.min():+.1f}..{floor.max():+.1f} m); "
            f"tanbench reads elevations (up positive, the seafloor negative): if the grid stores depths, "
            f"set terrain.positive: down to negate it")
    if clearance.min() < MIN_ALTITUDE_M:
        k = int(np.argmin(clearance))
        raise TanbenchError(
            f"the vehicle runs into the seafloor at t={t[k]:.0f} s, (E, N) = ({e[k]:.0f}, {n[k]:.0f}) m: "
            f"depth {-u[k]:.1f} m over a {-floor[k]:.1f} m seafloor; raise the trajectory or move it")


def check_no_holes(tmap, t, e, n, fill: str, track: str = "the track", margin: float = 0.0) -> None:
    """Refuse a track (times ``t``, positions ``e``, ``n``) whose map look-ups, widened by ``margin`` metres around
    each point, read a hole (a NaN node: :func:`tanbench.terrain.mosaic.over_holes`); ``fill`` names the setting
    that fills holes, ``track`` what the track is. Points off the map are not holes (whether a track may leave the
    map is the caller's to say). Both the sweep's worlds (:func:`check_track_on_map`: the true track, no margin) and
    ``tanbench replay`` (the navigation solution, the filter's initial uncertainty around it:
    ``missions/observe.py``) refuse holes with it."""
    hole = over_holes(tmap, e, n, margin)
    if hole.any():
        k = int(np.argmax(hole))
        where = ""
        if margin > 0:
            he, hn = min(find_holes(tmap, e[k], n[k], margin), key=lambda h: math.hypot(h[0] - e[k], h[1] - n[k]))
            where = (f" (the nearest node without data: (E, N) = ({he:.0f}, {hn:.0f}) m, "
                     f"{math.hypot(he - e[k], hn - n[k]):.0f} m away)")
        raise TanbenchError(
            f"the map has no data (a hole) under {track} at t={t[k]:.0f} s, (E, N) = ({e[k]:.0f}, "
            f"{n[k]:.0f}) m{where}; set {fill} to fill holes")


def vehicle_frame(vehicle: VehicleData, every: int = 1):
    """One run's vehicle data as a table at the IMU rate (every ``every``-th sample).

    Columns: time; true position and attitude; IMU outputs; held DVL velocity; pressure
    depth; the navigation system's solution; and, on sonar ping samples, the measured
    DVL and altimeter ranges (NaN elsewhere). Angles in degrees, headings compass.
    """
    import pandas as pd


    tr, obs = vehicle.truth, vehicle.obs
    nav = obs.nav
    n = tr.t.size
    dvl = np.full((n, obs.dvl_ranges.shape[1]), np.nan)
    dvl[obs.ping_idx] = obs.dvl_ranges
    sbe = np.full(n, np.nan)
    sbe[obs.ping_idx] = obs.sbe_ranges[:, 0]
    cols = {
        "t": tr.t,
        "truth_e": tr.pos[:, 0], "truth_n": tr.pos[:, 1], "truth_u": tr.pos[:, 2],
        "truth_pitch_deg": np.degrees(tr.pitch), "truth_roll_deg": np.degrees(tr.roll),
        "truth_heading_deg": yaw_to_heading_deg(tr.yaw),
        "gyro_x": obs.gyro[:, 0], "gyro_y": obs.gyro[:, 1], "gyro_z": obs.gyro[:, 2],
        "accel_x": obs.accel[:, 0], "accel_y": obs.accel[:, 1], "accel_z": obs.accel[:, 2],
        "dvl_vx": obs.dvl_velocity[:, 0], "dvl_vy": obs.dvl_velocity[:, 1],
        "dvl_vz": obs.dvl_velocity[:, 2], "pressure_depth": obs.depth,
        "nav_e": nav.pos[:, 0], "nav_n": nav.pos[:, 1], "nav_u": nav.pos[:, 2],
        "nav_pitch_deg": np.degrees(nav.pitch), "nav_roll_deg": np.degrees(nav.roll),
        "nav_heading_deg": yaw_to_heading_deg(nav.yaw),
        **{f"dvl_range_{i + 1}": dvl[:, i] for i in range(dvl.shape[1])},
        "sbe_range": sbe,
    }
    return pd.DataFrame(cols).iloc[::every].reset_index(drop=True)
