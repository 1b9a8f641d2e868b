"""A mission log and a map as what a method is given, and the reference that scoring reads.

:func:`observations` builds the same :class:`~tanbench.simulation.Observations` the
simulator builds: the IMU at its constant rate sets the samples; the navigation solution
and the pressure depth are taken at those samples (linear interpolation when their times
differ, heading unwrapped); each DVL ping sits at the IMU sample nearest its time (at most
half a sample away), its velocity held until the next ping as a navigation computer holds
it (a ping without velocity, NaN, holds the previous one); the altimeter's readings go to
the DVL ping nearest in time, within half a ping interval. Positions in longitude and
latitude are projected into the map's local frame with the map's own georeferencing
(:func:`tanbench.terrain.georef.lonlat_to_local`). A method cannot tell these observations
from simulated ones.

:func:`reference_truth` gives the reference track at the same samples, for scoring only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tanbench.errors import TanbenchError
from tanbench.missions.logfile import MissionLog
from tanbench.missions.spec import ACCEL, GYRO, LONLAT, LOCAL, TIME, VELOCITY, range_columns
from tanbench.simulation import NavSolution, Observations, check_no_holes
from tanbench.methods.api import update_indices
from tanbench.runner.validate import check_sampling_time
from tanbench.terrain.georef import lonlat_to_local

IMU_JITTER = 0.01  # largest departure of an IMU sample interval from 1 / imu_rate_hz, as a fraction of it


@dataclass
class Reference:
    """The reference track at the IMU samples (what scoring reads as the truth); NaN where absent."""

    t: np.ndarray
    dt: float
    pos: np.ndarray  # (n, 3) east, north, up in the map's frame
    pitch: np.ndarray
    roll: np.ndarray
    yaw: np.ndarray  # rad, counter-clockwise from north (-heading)
    true_ranges: dict  # sensor ("dvl", "altimeter", "multibeam") -> (pings, beams) noise-free ranges, if given

    @property
    def has_attitude(self) -> bool:
        return bool(np.isfinite(self.pitch).all() and np.isfinite(self.roll).all() and np.isfinite(self.yaw).all()
                    and np.isfinite(self.pos).all())


@dataclass
class LoggedRun:
    """A log's run as scoring takes a simulated one: what the vehicle observed, and the reference."""

    obs: Observations
    truth: Reference | None


def observations(log: MissionLog, nmap) -> Observations:
    """What a method is given from ``log`` on the navigation map ``nmap`` (see the module docstring)."""
    s = log.meta.sensors
    imu = log.tables["imu"]
    t = np.ascontiguousarray(imu[TIME].to_numpy())
    dt = 1.0 / s.imu_rate_hz
    _check_regular(log, t, dt)
    nav = at_samples(log, "navigation", t)
    ping_t = log.tables["dvl"][TIME].to_numpy()
    ping_idx = nearest_samples(log, "dvl", ping_t, t, dt)
    _check_ping_rate(log, ping_t)
    dvl = log.tables["dvl"]
    velocity = held(log, dvl[list(VELOCITY)].to_numpy(), ping_idx, t.size)
    latitude = s.latitude_deg if "latitude_deg" in s.model_fields_set or not log.lonlat else float(
        np.mean(log.tables["navigation"][LONLAT[1]]))
    return Observations(
        t=t, dt=dt, latitude_rad=math.radians(latitude),
        gyro=_columns(imu, [f"{g}_rad_s" for g in GYRO]), accel=_columns(imu, list(ACCEL)),
        dvl_velocity=velocity, depth=at_samples(log, "depth", t)["depth_m"], ping_idx=ping_idx,
        dvl_beams=log.meta.beam_vectors("dvl"), sbe_beams=log.meta.beam_vectors("altimeter"),
        dvl_ranges=_columns(dvl, range_columns(log.beam_count("dvl"))),
        sbe_ranges=altimeter_at_pings(log, ping_t),
        nav=NavSolution(pos=horizontal_local(log, nav, nmap), pitch=nav["pitch_rad"], roll=nav["roll_rad"],
                        yaw=-nav["heading_rad"]),
        mbe_beams=log.meta.beam_vectors("multibeam") if "multibeam" in log.tables else None,
        mbe_ranges=readings_at_pings(log, "multibeam", ping_t) if "multibeam" in log.tables else None)


def reference_truth(log: MissionLog, obs: Observations, nmap) -> Reference | None:
    """The log's reference track at the IMU samples, in the map's frame (None without one)."""
    if "reference" not in log.tables:
        return None
    ref = at_samples(log, "reference", obs.t, within=obs.t[obs.ping_idx])
    nan = np.full(obs.t.size, np.nan)
    return Reference(t=obs.t, dt=obs.dt, pos=horizontal_local(log, ref, nmap),
                     pitch=ref.get("pitch_rad", nan), roll=ref.get("roll_rad", nan),
                     yaw=-ref["heading_rad"] if "heading_rad" in ref else nan,
                     true_ranges=_true_ranges(log))


def _columns(df, names) -> np.ndarray:
    return np.ascontiguousarray(np.stack([df[c].to_numpy() for c in names], axis=1))


def _check_regular(log: MissionLog, t: np.ndarray, dt: float) -> None:
    if t.size < 2:
        raise TanbenchError(f"{log.path}: the imu table needs at least two samples")
    steps = np.diff(t)
    mean = (t[-1] - t[0]) / (t.size - 1)
    if abs(mean - dt) > 1e-3 * dt:
        raise TanbenchError(f"{log.path}: the imu samples come every {mean:.6g} s on average, not every 1 / "
                            f"sensors.imu_rate_hz = {dt:.6g} s: give the IMU's rate")
    bad = np.abs(steps - dt) > IMU_JITTER * dt
    if bad.any():
        k = int(np.argmax(bad))
        raise TanbenchError(
            f"{log.path}: imu samples {k} and {k + 1} are {steps[k]:.6g} s apart, not 1 / sensors.imu_rate_hz = "
            f"{dt:.6g} s (within {100 * IMU_JITTER:g} %); tanbench needs the IMU at a constant rate: resample it")


def at_samples(log: MissionLog, table: str, t: np.ndarray, within: np.ndarray | None = None) -> dict:
    """A table's columns at the IMU sample times ``t``: as they are when the table's times are ``t``,
    else linearly interpolated (heading unwrapped). The table must span ``within`` (default: ``t``)."""
    df = log.tables[table]
    src = df[TIME].to_numpy()
    cols = [c for c in df.columns if c != TIME]
    if src.shape == t.shape and np.array_equal(src, t):
        return {c: np.ascontiguousarray(df[c].to_numpy()) for c in cols}
    span = t if within is None else within
    if src[0] > span[0] or src[-1] < span[-1]:
        raise TanbenchError(f"{log.path}: the {table} table covers t = {src[0]:.6g}..{src[-1]:.6g} s, but it must "
                            f"cover {span[0]:.6g}..{span[-1]:.6g} s")
    out = {}
    for c in cols:
        values = df[c].to_numpy()
        if c == "heading_rad":
            values = np.unwrap(values)
        inside = (t >= src[0]) & (t <= src[-1])
        out[c] = np.where(inside, np.interp(t, src, values), np.nan)
    return out


def nearest_samples(log: MissionLog, table: str, times: np.ndarray, t: np.ndarray, dt: float) -> np.ndarray:
    """The IMU sample index nearest each of ``times`` (at most half a sample away, within the IMU's span)."""
    if times[0] < t[0] - 0.5 * dt or times[-1] > t[-1] + 0.5 * dt:
        raise TanbenchError(f"{log.path}: {table} pings run t = {times[0]:.6g}..{times[-1]:.6g} s, outside the imu "
                            f"samples' {t[0]:.6g}..{t[-1]:.6g} s")
    after = np.clip(np.searchsorted(t, times), 1, t.size - 1)
    idx = np.where(times - t[after - 1] <= t[after] - times, after - 1, after).astype(np.int64)
    off = np.abs(t[idx] - times)
    if (off > 0.5 * dt * (1 + IMU_JITTER)).any():
        k = int(np.argmax(off))
        raise TanbenchError(f"{log.path}: {table} ping {k} at t = {times[k]:.6g} s is {off[k]:.3g} s from the nearest "
                            f"imu sample")
    if (np.diff(idx) < 1).any():
        raise TanbenchError(f"{log.path}: two {table} pings fall on one imu sample (pings faster than the IMU?)")
    return idx


def _check_ping_rate(log: MissionLog, ping_t: np.ndarray) -> None:
    """The DVL's median ping interval is 1 / sensors.sonar_rate_hz (updates are every k-th ping)."""
    if ping_t.size < 2:
        raise TanbenchError(f"{log.path}: the dvl table needs at least two pings")
    rate = log.meta.sensors.sonar_rate_hz
    median = float(np.median(np.diff(ping_t)))
    if abs(median * rate - 1.0) > 0.1:
        raise TanbenchError(f"{log.path}: dvl pings come every {median:.6g} s (median), but sensors.sonar_rate_hz = "
                            f"{rate:g} says every {1 / rate:.6g} s")


def held(log: MissionLog, per_ping: np.ndarray, ping_idx: np.ndarray, n: int) -> np.ndarray:
    """Per-ping DVL velocities held at every IMU sample until the next ping (NaN pings hold the previous
    valid one; samples before the first valid ping take it)."""
    valid = np.isfinite(per_ping).all(axis=1)
    if not valid.any():
        raise TanbenchError(f"{log.path}: the dvl table has no ping with a finite velocity")
    last_valid = np.maximum.accumulate(np.where(valid, np.arange(valid.size), -1))
    last_valid = np.where(last_valid < 0, int(np.argmax(valid)), last_valid)
    pings = per_ping[last_valid]
    held_from = np.searchsorted(ping_idx, np.arange(n), side="right") - 1
    return np.ascontiguousarray(pings[np.clip(held_from, 0, None)])


def altimeter_at_pings(log: MissionLog, ping_t: np.ndarray) -> np.ndarray:
    """(pings, beams) altimeter ranges at the DVL pings: the reading nearest each ping within half a
    ping interval, NaN otherwise (and without an altimeter table)."""
    if log.tables.get("altimeter") is None:
        return np.full((ping_t.size, 1), np.nan)
    return readings_at_pings(log, "altimeter", ping_t)


def readings_at_pings(log: MissionLog, table: str, ping_t: np.ndarray) -> np.ndarray:
    """(pings, beams) ranges of a sonar ``table`` (altimeter, multibeam) at the DVL pings: the reading
    nearest each ping within half a ping interval, NaN otherwise."""
    alt = log.tables[table]
    ranges = _columns(alt, range_columns(log.beam_count(table)))
    at = alt[TIME].to_numpy()
    if at.shape == ping_t.shape and np.array_equal(at, ping_t):
        return ranges
    j = np.clip(np.searchsorted(at, ping_t), 1, at.size - 1)
    j = np.where(np.abs(at[j - 1] - ping_t) <= np.abs(at[j] - ping_t), j - 1, j) if at.size > 1 else np.zeros_like(j)
    close = np.abs(at[j] - ping_t) <= 0.5 / log.meta.sensors.sonar_rate_hz
    return np.ascontiguousarray(np.where(close[:, None], ranges[j], np.nan))


def horizontal_local(log: MissionLog, track: dict, nmap) -> np.ndarray:
    """(n, 3) east, north, up of a navigation or reference track in the map's local frame."""
    up = track.get("up_m", np.full(track[LONLAT[0] if log.lonlat else LOCAL[0]].size, np.nan))
    if not log.lonlat:
        return np.ascontiguousarray(np.column_stack([track[LOCAL[0]], track[LOCAL[1]], up]))
    if nmap.meta.get("crs") != "local" or "m_per_deg_lon" not in nmap.meta:
        raise TanbenchError(
            f"{log.path}: positions are lon/lat but the map {nmap.name} is in metres with no geographic reference; "
            f"give a map georeferenced in lon/lat or Web Mercator (docs/maps.md), or the log in the map's metres "
            f"(east_m, north_m)")
    e, n = lonlat_to_local(nmap, track[LONLAT[0]], track[LONLAT[1]])
    return np.ascontiguousarray(np.column_stack([e, n, up]))


def _true_ranges(log: MissionLog) -> dict:
    """The reference's noise-free ranges per sensor, at the DVL pings (``reference_ranges``)."""
    df = log.tables.get("reference_ranges")
    if df is None:
        return {}
    if not np.array_equal(df[TIME].to_numpy(), log.tables["dvl"][TIME].to_numpy()):
        raise TanbenchError(f"{log.path}: reference_ranges must have one row per dvl ping, at the dvl's times")
    out = {}
    for sensor, table in (("dvl", "dvl"), ("altimeter", "altimeter"), ("multibeam", "multibeam")):
        names = [c for c in df.columns if c.startswith(f"{sensor}_range_")]
        if not names:
            continue
        beams = max(log.beam_count(table), 1)
        if len(names) != beams:
            raise TanbenchError(f"{log.path}: reference_ranges has {len(names)} {sensor} ranges, the {sensor} "
                                f"has {beams} beams")
        out[sensor] = _columns(df, names)
    return out


def check_start_on_map(scenario, obs: Observations, nmap, label: str) -> None:
    """Refuse a log whose first update's initial uncertainty (``filter.initial_area_m`` around the
    navigation solution) leaves the map: the log and the map do not belong together."""
    k0 = update_indices(scenario, obs).imu[0]
    e, n = obs.nav.pos[k0, 0], obs.nav.pos[k0, 1]
    half = scenario.filter.initial_area_m / 2.0
    if not nmap.contains(np.array([e - half, e + half, e - half, e + half]),
                         np.array([n - half, n - half, n + half, n + half])).all():
        raise TanbenchError(
            f"{label}: the navigation solution starts at (E, N) = ({e:.0f}, {n:.0f}) m in the map's frame and the "
            f"initial uncertainty (filter.initial_area_m / 2 = {half:g} m around it) leaves the map (E {nmap.e0:.0f}.."
            f"{nmap.e_max:.0f}, N {nmap.n0:.0f}..{nmap.n_max:.0f} m): is it the mission's map, and the log in its frame?")


def check_no_holes_near_track(scenario, obs: Observations, nmap, label: str) -> None:
    """Refuse a map with no data (a hole) under the navigation solution or within the filter's initial uncertainty
    (``filter.initial_area_m`` / 2) of it, at any sample: the sweep's check of its true track
    (:func:`tanbench.simulation.check_no_holes`), for a mission whose true track is not known (docs/missions.md,
    section 5, "Holes in the map"). A map read with ``map.fill_holes`` has none."""
    half = scenario.filter.initial_area_m / 2.0
    try:
        check_no_holes(nmap, obs.t, obs.nav.pos[:, 0], obs.nav.pos[:, 1], "map.fill_holes: true in the --settings file",
                       f"the navigation solution or within filter.initial_area_m / 2 = {half:g} m of it", margin=half)
    except TanbenchError as exc:
        raise TanbenchError(f"{label}: {exc}") from None


def check_sampling_time_in_log(scenario, obs: Observations, label: str) -> None:
    """Refuse a ``sampling_time_s`` longer than the log's DVL pings span (the sweep's check of its run's length,
    :func:`tanbench.runner.validate.check_sampling_time`): the methods would not update after the first ping."""
    pings = obs.t[obs.ping_idx]
    try:
        check_sampling_time(scenario, float(pings[-1] - pings[0]), "the span of the log's DVL pings")
    except TanbenchError as exc:
        raise TanbenchError(f"{label}: {exc}") from None
