"""A simulated run as a mission log (``tanbench simulate --log DIR``).

The log holds exactly the arrays the in-process run gives its methods (float64, angles in
radians, the navigation map's frame), so a replay of it is the in-process run bit for bit;
the truth goes to the reference track, and the noise-free ranges the posterior Cramer-Rao
bound uses to ``reference_ranges``. Beside the log, the directory gets the navigation map
the methods used (``map.npz``) and the run's method settings (``settings.yaml``, for
``tanbench replay --settings``); neither is part of the format.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from tanbench.errors import TanbenchError
from tanbench.missions.logfile import MissionLog, beam_block
from tanbench.missions.spec import ACCEL, FORMAT_NAME, FORMAT_VERSION, GYRO, TIME, VELOCITY, BeamGeometry, LogMeta
from tanbench import __version__
from tanbench.config import SensorSpec
from tanbench.sensors.multibeam import ping_rows, sensor_fan
from tanbench.simulation import noise_free_swath, noise_free_world
from tanbench.terrain import truth_map
from tanbench.terrain.georef import local_to_lonlat

MAP_FILE = "map.npz"
SETTINGS_FILE = "settings.yaml"


def simulated_log(scenario, vehicle, seed: int, lonlat: bool = False) -> MissionLog:
    """The mission log of one simulated run (``vehicle`` from ``simulate_vehicle(scenario, SeedSequence(seed))``);
    positions in WGS84 lon/lat with ``lonlat`` (the terrain must be georeferenced)."""
    obs, truth = vehicle.obs, vehicle.truth
    _, ping_idx, dvl_true, sbe_true = noise_free_world(json.dumps(scenario.world_spec(), sort_keys=True))
    frame = lonlat_frame(scenario) if lonlat else None
    pings = obs.t[obs.ping_idx]
    meta = LogMeta(
        format=FORMAT_NAME, format_version=FORMAT_VERSION, body_frame="rfu",
        description=f"tanbench simulate: area {scenario.area}, seed {seed}",
        sensors=SensorSpec(**scenario.sensors.model_dump()), range_noise_half_width_m=scenario.noise_m,
        source={"kind": "simulation", "tanbench_version": __version__, "seed": seed,
                "scenario": scenario.normalized()})
    tables = {
        "imu": pd.DataFrame({TIME: obs.t, **{f"{g}_rad_s": obs.gyro[:, k] for k, g in enumerate(GYRO)},
                             **{a: obs.accel[:, k] for k, a in enumerate(ACCEL)}}),
        "navigation": _track(obs.t, obs.nav.pos, obs.nav.pitch, obs.nav.roll, obs.nav.yaw, frame),
        "depth": pd.DataFrame({TIME: obs.t, "depth_m": obs.depth}),
        "dvl": pd.DataFrame({TIME: pings, **{v: obs.dvl_velocity[obs.ping_idx, k] for k, v in enumerate(VELOCITY)},
                             **beam_block(obs.dvl_ranges)}),
        "altimeter": pd.DataFrame({TIME: pings, **beam_block(obs.sbe_ranges)}),
        "reference": _track(truth.t, truth.pos, truth.pitch, truth.roll, truth.yaw, frame),
        "reference_ranges": pd.DataFrame({TIME: truth.t[ping_idx], **beam_block(np.asarray(dvl_true), "dvl_"),
                                          **beam_block(np.asarray(sbe_true), "altimeter_")}),
    }
    if obs.mbe_ranges is not None:
        meta, tables = _with_multibeam(scenario, obs, meta, tables)
    return MissionLog(meta=meta, tables=tables)


def _with_multibeam(scenario, obs, meta, tables):
    """The multibeam's pings (one row per multibeam ping, at its DVL ping's time), its fan in
    ``beams.multibeam`` and its noise-free ranges beside the others in ``reference_ranges``."""
    rows = ping_rows(scenario.sensors, obs.ping_idx.size)
    angles, _ = sensor_fan(scenario.sensors)
    tables["multibeam"] = pd.DataFrame({TIME: obs.t[obs.ping_idx][rows], **beam_block(obs.mbe_ranges[rows])})
    _, swath = noise_free_swath(json.dumps(scenario.world_spec(), sort_keys=True))
    true_swath = np.full((obs.ping_idx.size, swath.shape[1]), np.nan)
    true_swath[rows] = swath
    ref = tables["reference_ranges"]
    tables["reference_ranges"] = pd.concat([ref, pd.DataFrame(beam_block(true_swath, "multibeam_"), index=ref.index)],
                                           axis=1)
    meta = meta.model_copy(update={"beams": {**meta.beams,
                                             "multibeam": BeamGeometry(across_track_deg=tuple(float(a) for a in angles))}})
    return meta, tables


def _track(t, pos, pitch, roll, yaw, frame) -> pd.DataFrame:
    """A navigation or reference table: position, up and attitude (heading = -yaw, exact)."""
    if frame is None:
        horizontal = {"east_m": pos[:, 0], "north_m": pos[:, 1]}
    else:
        lon, lat = local_to_lonlat(frame, pos[:, 0], pos[:, 1])
        horizontal = {"lon_deg": lon, "lat_deg": lat}
    return pd.DataFrame({TIME: t, **horizontal, "up_m": pos[:, 2], "pitch_rad": pitch, "roll_rad": roll,
                         "heading_rad": -np.asarray(yaw)})


def lonlat_frame(scenario):
    """The georeferenced map whose frame the run's positions are in (for lon/lat positions)."""
    tmap = truth_map(scenario.terrain)
    if "m_per_deg_lon" not in tmap.meta:
        raise TanbenchError(
            f"--lonlat needs a map georeferenced in lon/lat or Web Mercator (docs/maps.md); the {scenario.terrain.kind} "
            f"terrain {tmap.name!r} is in local metres")
    return tmap


def write_map(nmap, path: Path) -> Path:
    """The navigation map as an ``.npz`` (key z, and e0, n0, res_e, res_n: the Map convention, exact)."""
    try:
        np.savez(path, z=nmap.z, e0=nmap.e0, n0=nmap.n0, res_e=nmap.res_e, res_n=nmap.res_n)
    except OSError as exc:
        raise TanbenchError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path


def settings_text(scenario, lonlat: bool = False) -> str:
    """``tanbench replay --settings`` YAML with the method settings of ``scenario`` (what reproduces its run); its
    header says how to replay it: on ``LOG/map.npz``, or, for a log in lon/lat (``lonlat``), on the georeferenced map
    the run was simulated on (``map.npz`` is in metres, with no geographic reference)."""
    import yaml

    d = scenario.normalized()
    data = {"particles": d["particles"], "sampling_time_s": d["sampling_time_s"], "filter": d["filter"],
            "method_options": d["method_options"], "map": {"map_error_m": d["terrain"]["map_error_m"]}}
    if lonlat:
        import shlex

        path = scenario.terrain.path
        where = (shlex.quote(str(path)) if not isinstance(path, list)
                 else "FILE (one of " + ", ".join(str(p) for p in path) + ", or a glob of them)")
        header = (f"# method settings of the simulated run; its positions are lon/lat and LOG/map.npz is in metres with "
                  f"no geographic reference, so replay it on the georeferenced map it was simulated on: `tanbench replay "
                  f"LOG --map {where} --settings THIS`; that replay's navigation map is the file as read, not the "
                  f"run's (LOG/map.npz), so its results are not the simulated run's\n")
    else:
        header = "# method settings of the simulated run: `tanbench replay LOG --map LOG/map.npz --settings THIS`\n"
    return header + yaml.safe_dump(data, sort_keys=False)
