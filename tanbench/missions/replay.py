"""``tanbench replay``: methods over a recorded mission log and a map, scored against its reference.

Every method runs through the registry and the same :func:`tanbench.methods.run_estimates`
the sweep runner uses, on :class:`~tanbench.simulation.Observations` built from the log
(:mod:`tanbench.missions.observe`), so built-in and plug-in methods alike cannot tell a
log from a simulation. The map is used as it is, as the navigation map. With a reference
track, :func:`tanbench.scoring.score` scores each method as a sweep's run; without one,
only the estimates are written.

The methods' settings (particles, sampling time, ``filter``, ``method_options``, a
``profile``) come from an optional settings YAML, the sensors' rates and noise figures from
the log's metadata. Method ``m``'s random numbers come from ``SeedSequence(seed,
spawn_key=(REPLAY_STREAM, seed id of m))``.

Results (``OUT``), every Parquet file with the provenance in its metadata as a sweep's:

* ``runs.parquet``: one row per method, a sweep's run-file columns (the settings as flat
  columns, the metrics only with a reference, status, error, wall time);
* ``estimates.parquet``: every method's estimate at every update, in the log's coordinates;
* ``series.parquet``: with a reference, the scored per-update series (a sweep's series);
* ``replay.yaml``: the inputs (log, map, methods, seed, settings).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from tanbench.errors import TanbenchError
from tanbench.missions.logfile import MissionLog, read_log
from tanbench.missions.observe import (LoggedRun, check_no_holes_near_track, check_sampling_time_in_log,
                                      check_start_on_map, observations, reference_truth)
from tanbench import store
from tanbench.bounds.pcrb import bound_series, update_track
from tanbench.config import SensorSpec, TerrainSpec, flatten, format_validation_error
from tanbench.errors import describe_exception
from tanbench.kernel_cache import is_warm as numba_cache_is_warm
from tanbench.methods import run_estimates
from tanbench.methods.registry import get
from tanbench.missions.spec import parse_yaml_model
from tanbench.profiles import profile_settings
from tanbench.runner.seeds import seed_number
from tanbench.runner.tasks import guard_exits, run_guarded
from tanbench.schema import METRIC_COLUMNS, rows_table
from tanbench.scoring import score
from tanbench.sensors.sonar import true_ranges
from tanbench.sweep import _merge, _set_dotted, make_scenario
from tanbench.terrain.files import load_file_terrain, terrain_content_hash
from tanbench.terrain.georef import local_to_lonlat
from tanbench.vehicle.attitude import yaw_to_heading_deg

REPLAY_STREAM = 3  # spawn-key stream of a replay's methods (runner.seeds uses 1 for vehicles, 2 for filters)
DEFAULT_METHODS = ("tight-dvl", "tight-sbe", "loose-dvl")
# the file-terrain keys a settings file's ``map`` may hold (tanbench.config.TerrainSpec, docs/maps.md)
MAP_KEYS = ("path", "format", "bounds", "origin", "resolution", "rows", "crs", "nodata", "positive", "fill_holes",
            "map_error_m")
# the scenario's world sections: a replay has none of them (they stay empty in runs.parquet)
NOT_IN_REPLAY = ("area", "duration_s", "trajectory", "navigation", "faults")


class ReplaySettings(BaseModel):
    """The settings YAML of ``tanbench replay --settings`` (every key optional)."""

    model_config = ConfigDict(extra="forbid")

    profile: str | None = None
    particles: int | None = None
    sampling_time_s: float | None = None
    filter: dict = Field(default_factory=dict)
    method_options: dict = Field(default_factory=dict)
    map: dict = Field(default_factory=dict)


@dataclass
class ReplayReport:
    """What a replay did: its results directory, one row per method, and notes on the inputs."""

    out: Path
    rows: list[dict]
    has_reference: bool
    notes: list[str] = field(default_factory=list)

    @property
    def failed(self) -> list[dict]:
        return [r for r in self.rows if r["status"] != "ok"]


def method_seed(seed: int, method: str) -> np.random.SeedSequence:
    """The seed of ``method``'s random numbers in a replay with root ``seed``."""
    return np.random.SeedSequence(seed, spawn_key=(REPLAY_STREAM, get(method).seed_id))


def load_settings(path: Path | None) -> tuple[ReplaySettings, str]:
    """The settings file (and its text); no file: every default."""
    if path is None:
        return ReplaySettings(), ""
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise TanbenchError(f"{path}: no such settings file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TanbenchError(f"{path}: cannot read the settings file ({type(exc).__name__})") from None
    settings = parse_yaml_model(text, str(path), ReplaySettings,
                                "profile, particles, sampling_time_s, filter, method_options, map")
    unknown = sorted(set(settings.map) - set(MAP_KEYS))
    if unknown:
        raise TanbenchError(f"{path}: map.{unknown[0]}: unknown key (known: {', '.join(MAP_KEYS)})")
    return settings, text


def read_map(settings: ReplaySettings, map_path: str | None, label: str):
    """The navigation map (used as it is) and its terrain spec; ``map_path`` replaces ``map.path``."""
    keys = dict(settings.map)
    if map_path is not None:
        keys["path"] = map_path
    if not keys.get("path"):
        raise TanbenchError("no map: give --map FILE (or map.path in the --settings file)")
    try:
        spec = TerrainSpec(kind="file", **keys)
    except ValidationError as exc:
        raise TanbenchError(f"{label}: {format_validation_error(exc, 'map.')}") from None
    nmap = load_file_terrain(spec)
    return replace(nmap, meta={**nmap.meta, "map_error_m": spec.map_error_m}), spec


def replay_scenario(log: MissionLog, settings: ReplaySettings, spec, nmap, label: str):
    """The scenario a replay's methods see: the log's sensors and range noise, the settings' methods
    settings, the map (its resolution). Its world sections only make it a valid Scenario: methods
    never see them (``method_view``) and the results leave them empty."""
    base: dict = {}
    for k, v in profile_settings(settings.profile).items():
        _set_dotted(base, k, v)
    given = {k: v for k, v in settings.model_dump().items() if k not in ("profile", "map") and v not in (None, {})}
    base = _merge(base, given)
    base.update(area="custom", terrain=spec.model_dump(mode="json"), map_resolution_m=nmap.resolution,
                sensors=log.meta.sensors.model_dump(mode="json"), noise_m=log.meta.range_noise_half_width_m,
                trajectory={"kind": "survey", "centre_en_m": [0.5 * (nmap.e0 + nmap.e_max),
                                                              0.5 * (nmap.n0 + nmap.n_max)]})
    return make_scenario(base, {}, label, "")


def parse_methods(values) -> list[str]:
    """``--methods a,b --methods c`` as a checked list (registry names or package.module:function)."""
    names = [n.strip() for v in (values or [",".join(DEFAULT_METHODS)]) for n in v.split(",") if n.strip()]
    if not names:
        raise TanbenchError("--methods names no method")
    for name in names:
        get(name)
    return list(dict.fromkeys(names))


def input_notes(log: MissionLog) -> list[str]:
    """What the replay assumed about the log (figures it did not give, data no method reads yet)."""
    notes = []
    missing = [k for k in SensorSpec.model_fields if k not in log.meta.sensors.model_fields_set
               and k not in ("grade", "beam_tilt_deg", "beam_azimuths_deg")]
    if missing:
        notes.append(f"mission.yaml gives no sensors.{', sensors.'.join(missing)}: tanbench's defaults "
                     f"(grade {log.meta.sensors.grade}) are used")
    if "altimeter" not in log.tables:
        notes.append("no altimeter table: the single-beam methods get no ranges")
    if "multibeam" in log.tables:
        notes.append(f"multibeam: {log.beam_count('multibeam')} beams (the *-mbe methods weigh by them)")
    return notes


def replay(log_dir, map_path: str | None = None, methods=None, settings_path=None, seed: int = 0,
           out: Path | None = None, echo=print) -> ReplayReport:
    """Run ``methods`` over the log in ``log_dir`` and the map; write the results to ``out``."""
    import yaml

    log = read_log(log_dir)
    label = str(settings_path or log.path)
    settings, settings_text = load_settings(settings_path)
    names = parse_methods(methods)
    nmap, spec = read_map(settings, map_path, label)
    scenario = replay_scenario(log, settings, spec, nmap, label)
    obs = observations(log, nmap)
    check_sampling_time_in_log(scenario, obs, label)
    check_start_on_map(scenario, obs, nmap, str(log.path))
    check_no_holes_near_track(scenario, obs, nmap, str(log.path))
    truth = reference_truth(log, obs, nmap)
    out = Path(out) if out is not None else Path("results") / f"replay-{log.path.resolve().name}"
    _check_out(out)
    notes = input_notes(log)
    if truth is not None and not truth.true_ranges and not truth.has_attitude:
        notes.append("the reference track has no attitude (or no up): no posterior Cramer-Rao bound")
    elif truth is not None and not truth.true_ranges:
        notes.append("the bound's ranges are the reference track ray-cast on the map (the log gives no "
                     "reference_ranges)")
    if not numba_cache_is_warm():
        echo("compiling the numba kernels (once per install or code change; about 2 minutes)...")
    run = LoggedRun(obs=obs, truth=truth)
    rows, estimates, series = [], [], []
    bounds: dict = {}
    for name in names:
        row, est, ser = _run_one(scenario, name, run, nmap, seed, log, bounds)
        rows.append(row)
        estimates += est
        series += ser
    meta = _provenance(log, spec, settings_text, seed, names)
    inputs = {"log": str(log.path), "map": spec.model_dump(mode="json", exclude_defaults=True), "methods": names,
              "seed": seed, "settings": settings.model_dump(exclude_defaults=True)}
    _write(out, rows, estimates, series, truth is not None, meta, yaml.safe_dump(inputs, sort_keys=False))
    return ReplayReport(out=out, rows=rows, has_reference=truth is not None, notes=notes)


def _run_one(scenario, name, run: LoggedRun, nmap, seed, log, bounds):
    """One method over the run: its row, its estimates frame and (with a reference) its series frame."""
    fseed = method_seed(seed, name)
    settings = {k: v for k, v in flatten(scenario.normalized()).items() if k.split(".")[0] not in NOT_IN_REPLAY}
    row = {"sweep": "replay", "tables": "", "method": name, "run": 0, "seed": seed,
           "filter_seed": seed_number(fseed), **settings, "log": str(log.path)}
    started = time.perf_counter()
    guard_exits()
    try:
        ctx, out, wall = run_guarded(name, lambda: run_estimates(scenario, name, run, fseed, nmap=nmap))
        result = None
        if run.truth is not None:
            result = score(scenario, run, ctx.updates, out, wall, nmap=nmap,
                           bound=_bound(scenario, name, run, nmap, bounds))
    except Exception as exc:  # noqa: BLE001 - a failing method is recorded, the others still run
        return {**row, "status": "error", "error": describe_exception(exc), "wall_s": time.perf_counter() - started}, [], []
    row.update(result.metrics if result is not None else {"filter_wall_s": wall})
    row.update(status="ok", error="", wall_s=time.perf_counter() - started)
    series = [pd.DataFrame({"method": name, **result.series})] if result is not None else []
    return row, [estimates_frame(name, ctx.updates, out, run.obs, log, nmap)], series


def _bound(scenario, name, run: LoggedRun, nmap, cache):
    """The method's posterior Cramer-Rao bound along the reference (None: no bound for it or no ranges)."""
    spec = get(name).bound
    if spec is None:
        return None
    if spec not in cache:
        sensor, states = spec
        ref, obs = run.truth, run.obs
        beams = {"dvl": obs.dvl_beams, "sbe": obs.sbe_beams, "mbe": obs.mbe_beams}[sensor]
        ranges = ref.true_ranges.get({"dvl": "dvl", "sbe": "altimeter", "mbe": "multibeam"}[sensor])
        if ranges is None and ref.has_attitude and beams is not None:
            s = scenario.sensors
            width = (s.dvl_beamwidth_deg if sensor == "dvl" else s.altimeter_beamwidth_deg) if s.beam_footprint else 0.0
            p = obs.ping_idx
            ranges = true_ranges(nmap, ref.pos[p], ref.pitch[p], ref.roll[p], ref.yaw[p], beams,
                                 0.0 if sensor == "mbe" else width, s.max_range_m)
            if sensor == "mbe":  # no bound information where the multibeam did not ping
                ranges[np.isnan(obs.mbe_ranges).all(axis=1)] = np.nan
        cache[spec] = None if ranges is None else bound_series(
            [update_track(scenario, ref, obs.ping_idx, ranges)], beams, nmap, scenario, states, sensor)
    return cache[spec]


def estimates_frame(name, updates, out, obs, log: MissionLog, nmap) -> pd.DataFrame:
    """A method's estimates at its updates, in the log's coordinates (lon/lat beside the map's metres)."""
    upd = updates.imu
    nan = np.full(upd.size, np.nan)
    yaw = out.yaw if out.yaw is not None else (-np.radians(out.heading_deg) if out.heading_deg is not None
                                               else obs.nav.yaw[upd])
    cols = {"method": name, "update": np.arange(upd.size), "t_s": updates.t, "east_m": out.east,
            "north_m": out.north}
    cols.update(_lonlat(log, nmap, "", out.east, out.north))
    cols.update({
        "up_m": out.up if out.up is not None else obs.nav.pos[upd, 2], "heading_deg": yaw_to_heading_deg(yaw),
        "var_east_m2": _or(out.var_e, nan), "var_north_m2": _or(out.var_n, nan),
        "cov_east_north_m2": _or(out.cov_en, nan), "var_up_m2": _or(out.var_u, nan),
        "var_heading_deg2": _or(out.var_heading, nan), "ess": _or(out.ess, nan),
        "reinit": out.reinit if out.reinit is not None else np.zeros(upd.size, dtype=bool),
        "nav_east_m": obs.nav.pos[upd, 0], "nav_north_m": obs.nav.pos[upd, 1]})
    cols.update(_lonlat(log, nmap, "nav_", obs.nav.pos[upd, 0], obs.nav.pos[upd, 1]))
    cols.update({f"extra_{k}": v for k, v in out.extra.items()})
    return pd.DataFrame(cols)


def _or(value, default):
    return default if value is None else value


def _lonlat(log: MissionLog, nmap, prefix: str, east, north) -> dict:
    if not log.lonlat:
        return {}
    lon, lat = local_to_lonlat(nmap, east, north)
    return {f"{prefix}lon_deg": lon, f"{prefix}lat_deg": lat}


def _check_out(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise TanbenchError(f"--out {out}: exists and is not a directory")
    if (out / "sweep.yaml").exists() or (out / "runs").is_dir():
        raise TanbenchError(f"--out {out}: holds a sweep's results; use another directory")


def _provenance(log: MissionLog, spec, settings_text: str, seed: int, names) -> dict:
    return {**store.provenance(settings_text, "replay", seed), "kind": "replay", "log": str(log.path),
            "log_sha256": log.content_hash(), "log_source": log.meta.source, "map": spec.path,
            "map_sha256": terrain_content_hash(spec), "methods": list(names)}


def _write(out: Path, rows, estimates, series, scored: bool, meta: dict, inputs_text: str) -> None:
    """The results files (atomically each); without a reference, no metrics and no series."""
    table = rows_table(rows)
    if not scored:
        table = table.drop_columns([c for c in METRIC_COLUMNS if c != "filter_wall_s"])
    try:
        store.write_text(inputs_text, out / "replay.yaml")
        store.write_table(table, out / "runs.parquet", meta)
        if estimates:
            store.write_parquet(pd.concat(estimates, ignore_index=True), out / "estimates.parquet", meta)
        else:
            (out / "estimates.parquet").unlink(missing_ok=True)
        if series:
            store.write_parquet(pd.concat(series, ignore_index=True), out / "series.parquet", meta)
        else:
            (out / "series.parquet").unlink(missing_ok=True)
    except OSError as exc:
        raise TanbenchError(f"cannot write the results to {out}: {exc.strerror or exc}") from None
