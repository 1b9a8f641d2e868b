"""Reading and writing a mission-log directory (the format: :mod:`tanbench.missions.spec`).

In memory a log is a :class:`MissionLog`: its metadata and one pandas frame per table,
every column in canonical units (seconds, metres, radians, tanbench's rfu body frame),
whatever units and frame the files used. Reading checks each table on its own (columns,
units, numbers, times); :mod:`tanbench.missions.observe` checks them against each other.
Every problem is one :class:`~tanbench.errors.TanbenchError` line naming the file.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from tanbench.errors import TanbenchError
from tanbench.missions.spec import (ACCEL, ANGLE_UNITS, ATTITUDE, GYRO, LOCAL, LONLAT, META_FILE, RATE_UNITS,
                                    SUFFIXES, TABLES, TIME, VELOCITY, LogMeta, parse_yaml_model, range_columns,
                                    to_rfu)
from tanbench import store
from tanbench.missions.spec import FORMAT_VERSION


@dataclass
class MissionLog:
    """A mission log: metadata and its tables in canonical units (see the module docstring)."""

    meta: LogMeta
    tables: dict[str, pd.DataFrame]
    path: Path | None = None
    files: list[Path] = field(default_factory=list)  # what was read, for the content hash

    @property
    def lonlat(self) -> bool:
        """Whether positions are WGS84 longitude/latitude (else east/north metres in the map's frame)."""
        return LONLAT[0] in self.tables["navigation"].columns

    def table(self, name: str) -> pd.DataFrame | None:
        return self.tables.get(name)

    def beam_count(self, table: str) -> int:
        """Beams of a sonar table's block (0 without the table)."""
        df = self.tables.get(table)
        return 0 if df is None else sum(1 for c in df.columns if c.startswith("range_"))

    def content_hash(self) -> str:
        """sha256 of the files read (metadata first, then the tables in name order)."""
        digest = hashlib.sha256()
        for path in self.files:
            digest.update(path.name.encode())
            digest.update(hashlib.sha256(path.read_bytes()).digest())
        return digest.hexdigest()


# ---- reading -------------------------------------------------------------------------------


def read_log(directory) -> MissionLog:
    """Read and check the mission log in ``directory``."""
    directory = Path(directory)
    if not directory.is_dir():
        raise TanbenchError(f"{directory}: no such mission-log directory")
    meta_path = directory / META_FILE
    if not meta_path.is_file():
        raise TanbenchError(f"{directory}: not a mission log (no {META_FILE}; docs/missions.md describes the format)")
    try:
        text = meta_path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise TanbenchError(f"{meta_path}: cannot read it ({type(exc).__name__})") from None
    meta = parse_yaml_model(text, str(meta_path), LogMeta, "format, format_version, sensors, ...")
    tables, files = {}, [meta_path]
    for name, required in TABLES.items():
        path = _table_file(directory, name, required)
        if path is None:
            continue
        files.append(path)
        tables[name] = _canonical(name, _read_frame(path), path, meta)
    log = MissionLog(meta=meta, tables=tables, path=directory, files=files)
    _check_beam_blocks(log)
    ref = tables.get("reference")
    if ref is not None and (LONLAT[0] in ref.columns) != log.lonlat:
        raise TanbenchError(f"{directory}: the reference track's positions are in "
                            f"{'lon/lat' if not log.lonlat else 'metres'} but the navigation solution's are not; "
                            f"give both in one system")
    return log


def _table_file(directory: Path, name: str, required: bool) -> Path | None:
    found = [directory / f"{name}{s}" for s in SUFFIXES if (directory / f"{name}{s}").is_file()]
    if len(found) > 1:
        raise TanbenchError(f"{directory}: both {found[0].name} and {found[1].name}; keep one")
    if not found and required:
        raise TanbenchError(f"{directory}: no {name} table ({name}.parquet or {name}.csv; docs/missions.md)")
    return found[0] if found else None


def _read_frame(path: Path) -> pd.DataFrame:
    if path.suffix == ".csv":
        _check_csv_rows(path)
    try:
        df = pd.read_csv(path) if path.suffix == ".csv" else pd.read_parquet(path)
    except Exception as exc:  # noqa: BLE001 - any reader failure is the file's problem, said in one line
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise TanbenchError(f"{path}: not a readable {path.suffix[1:]} table ({first})") from None
    if df.empty:
        raise TanbenchError(f"{path}: the table has no rows")
    for col in df.columns:
        if not pd.api.types.is_numeric_dtype(df[col]) or pd.api.types.is_bool_dtype(df[col]):
            raise TanbenchError(f"{path}: column {col!r} is not numeric ({df[col].dtype})")
    return df.astype(np.float64)


def _check_csv_rows(path: Path) -> None:
    """Every row of a CSV table has as many fields as its header: a row cut short (a truncated file) or with a
    field too many would otherwise be read with NaN for what is missing, or shifted. Files the csv module
    cannot read are left to pandas' reader, which names their problem."""
    import csv

    try:
        with path.open(newline="") as f:
            reader = csv.reader(f)
            header = next(reader, None)
            if header is None:
                return
            row = -1
            for fields in reader:
                if not fields:  # a blank line, which pandas skips too
                    continue
                row += 1
                if len(fields) != len(header):
                    raise TanbenchError(f"{path}: row {row} (line {reader.line_num}) has {len(fields)} fields but the "
                                        f"header has {len(header)}: a truncated or damaged table?")
    except (OSError, UnicodeDecodeError, csv.Error):
        return


def check_ranges(path, name: str, values: np.ndarray) -> None:
    """A range column: slant distances along the beam, positive and finite, NaN where there was no bottom."""
    bad = ~np.isnan(values) & ~(np.isfinite(values) & (values > 0))
    if bad.any():
        k = int(np.argmax(bad))
        raise TanbenchError(f"{path}: {name} is {values[k]:g} m at row {k}; a range is the slant distance along the "
                            f"beam, positive (NaN, an empty CSV field, for no bottom)")


class _Columns:
    """Takes a table's columns one quantity at a time; whatever is left at the end is unknown."""

    def __init__(self, df: pd.DataFrame, path: Path):
        self.df, self.path, self.left = df, path, list(df.columns)
        self.out: dict[str, np.ndarray] = {}

    def take(self, name: str, required: bool = True) -> np.ndarray | None:
        if name not in self.left:
            if required:
                raise TanbenchError(f"{self.path}: no column {name!r} (columns: {', '.join(self.df.columns)})")
            return None
        self.left.remove(name)
        self.out[name] = self.df[name].to_numpy()
        return self.out[name]

    def take_unit(self, base: str, units: dict[str, float], required: bool = True) -> np.ndarray | None:
        """``base_<unit>`` in one of ``units``, stored under the first (canonical) unit."""
        given = [u for u in units if f"{base}_{u}" in self.left]
        if len(given) > 1:
            raise TanbenchError(f"{self.path}: {base} is given twice ({', '.join(f'{base}_{u}' for u in given)})")
        if not given:
            if required:
                wanted = " or ".join(f"{base}_{u}" for u in units)
                raise TanbenchError(f"{self.path}: no column {wanted} (columns: {', '.join(self.df.columns)})")
            return None
        unit = given[0]
        self.left.remove(f"{base}_{unit}")
        values = self.df[f"{base}_{unit}"].to_numpy()
        canonical = f"{base}_{next(iter(units))}"
        self.out[canonical] = values if units[unit] == 1.0 else values * units[unit]
        return self.out[canonical]

    def take_block(self, prefix: str = "") -> int:
        """Every ``<prefix>range_<i>_m`` column, i = 1..m without a gap; returns m."""
        m = 0
        while f"{prefix}range_{m + 1}_m" in self.left:
            check_ranges(self.path, f"{prefix}range_{m + 1}_m", self.take(f"{prefix}range_{m + 1}_m"))
            m += 1
        return m

    def frame(self) -> pd.DataFrame:
        if self.left:
            raise TanbenchError(f"{self.path}: unknown column {self.left[0]!r} (docs/missions.md lists each table's "
                                f"columns, units in the names; drop or rename it)")
        return pd.DataFrame(self.out)


def _canonical(name: str, df: pd.DataFrame, path: Path, meta: LogMeta) -> pd.DataFrame:
    """A table's columns in canonical units, checked (unknown or missing columns, times, numbers)."""
    cols = _Columns(df, path)
    t = cols.take(TIME)
    if not np.isfinite(t).all() or (t.size > 1 and not (np.diff(t) > 0).all()):
        raise TanbenchError(f"{path}: {TIME} must be finite and strictly increasing (first problem at row "
                            f"{_first_bad_time(t)})")
    if name == "imu":
        vectors = [np.stack([cols.take_unit(g, RATE_UNITS) for g in GYRO], axis=1),
                   np.stack([cols.take(a) for a in ACCEL], axis=1)]
        _finite(path, "gyro and accel", *vectors)
        _set_rfu(cols, meta, [f"{g}_rad_s" for g in GYRO], vectors[0])
        _set_rfu(cols, meta, list(ACCEL), vectors[1])
    elif name in ("navigation", "reference"):
        _take_position(cols, path, attitude_required=name == "navigation")
    elif name == "depth":
        _finite(path, "depth_m", cols.take("depth_m"))
    elif name == "dvl":
        velocity = np.stack([cols.take(v) for v in VELOCITY], axis=1)
        _set_rfu(cols, meta, list(VELOCITY), velocity)
        if cols.take_block() == 0:
            raise TanbenchError(f"{path}: no beam ranges (columns range_1_m, range_2_m, ...)")
    elif name in ("altimeter", "multibeam"):
        if cols.take_block() == 0:
            raise TanbenchError(f"{path}: no beam ranges (columns range_1_m, range_2_m, ...)")
    elif name == "reference_ranges":
        if cols.take_block("dvl_") + cols.take_block("altimeter_") + cols.take_block("multibeam_") == 0:
            raise TanbenchError(f"{path}: no ranges (columns dvl_range_1_m, ..., altimeter_range_1_m, "
                                f"multibeam_range_1_m)")
    return cols.frame()


def _first_bad_time(t: np.ndarray) -> int:
    bad = ~np.isfinite(t)
    bad[1:] |= ~(np.diff(t) > 0)
    return int(np.argmax(bad))


def _finite(path: Path, what: str, *arrays) -> None:
    for arr in arrays:
        if not np.isfinite(arr).all():
            raise TanbenchError(f"{path}: {what} has a missing or non-finite value at row "
                                f"{int(np.argmax(~np.isfinite(arr).reshape(arr.shape[0], -1).all(axis=1)))}")


def _set_rfu(cols: _Columns, meta: LogMeta, names: list[str], vectors: np.ndarray) -> None:
    """Store three body-frame columns in tanbench's rfu frame."""
    rfu = to_rfu(vectors, meta.body_frame)
    for k, name in enumerate(names):
        cols.out[name] = rfu[:, k]


def _take_position(cols: _Columns, path: Path, attitude_required: bool) -> None:
    """East/north metres or lon/lat degrees, up or depth metres, and the attitude."""
    local = [c for c in LOCAL if c in cols.left]
    lonlat = [c for c in LONLAT if c in cols.left]
    if local and lonlat:
        raise TanbenchError(f"{path}: give positions as east_m/north_m or as lon_deg/lat_deg, not both")
    for name in (LONLAT if lonlat else LOCAL):
        _finite(path, name, cols.take(name))
    if "depth_m" in cols.left and "up_m" in cols.left:
        raise TanbenchError(f"{path}: give up_m or depth_m, not both")
    if "depth_m" in cols.left:
        cols.left.remove("depth_m")
        cols.out["up_m"] = -cols.df["depth_m"].to_numpy()
    else:
        cols.take("up_m", required=attitude_required)
    for angle in ATTITUDE:
        cols.take_unit(angle, ANGLE_UNITS, required=attitude_required)
    if attitude_required:
        _finite(path, "the navigation solution", *cols.out.values())


def _check_beam_blocks(log: MissionLog) -> None:
    """Each sonar table has as many beams as its geometry in the metadata."""
    for table, sensor in (("dvl", "dvl"), ("altimeter", "altimeter"), ("multibeam", "multibeam")):
        m = log.beam_count(table)
        if m == 0:
            continue
        vectors = log.meta.beam_vectors(sensor)
        if vectors is None:
            raise TanbenchError(f"{log.path}: {table} has {m} beams but {META_FILE} gives no beams.{sensor} "
                                f"(their directions)")
        if vectors.shape[0] != m:
            raise TanbenchError(f"{log.path}: {table} has {m} beam range columns but {META_FILE} describes "
                                f"{vectors.shape[0]} {sensor} beams")


# ---- writing -------------------------------------------------------------------------------


def check_log_directory(directory: Path, overwrite: bool = False) -> None:
    """Refuse a directory a mission log cannot be written into (checked before the run is simulated, and again when
    it is written): a file; a directory that holds something other than a mission log; a mission log, unless
    ``overwrite`` (``simulate --force``) and it is a simulated one (``source.kind: simulation``): a recorded log is
    never overwritten."""
    if directory.exists() and not directory.is_dir():
        raise TanbenchError(f"{directory}: exists and is not a directory")
    if not directory.is_dir() or not any(directory.iterdir()):
        return
    if not (directory / META_FILE).is_file():
        raise TanbenchError(f"{directory}: not empty and not a mission log; use a new directory")
    if not _simulated(directory):
        raise TanbenchError(f"{directory}: holds a recorded mission log ({META_FILE} does not say source.kind: "
                            f"simulation), which tanbench never overwrites; use a new directory")
    if not overwrite:
        raise TanbenchError(f"{directory}: holds a mission log already; give --force to overwrite it, or use a new "
                            f"directory")


def _simulated(directory: Path) -> bool:
    """Whether the mission log in ``directory`` says it is a simulated run (what ``simulate --log`` writes)."""
    import yaml

    try:
        meta = yaml.safe_load((directory / META_FILE).read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    source = meta.get("source") if isinstance(meta, dict) else None
    return isinstance(source, dict) and source.get("kind") == "simulation"


def write_log(directory, log: MissionLog, fmt: str = "parquet", overwrite: bool = False) -> list[Path]:
    """Write ``log`` into ``directory`` (tables as ``fmt``: parquet or csv); returns the files.

    Body-frame vectors are written in the metadata's ``body_frame``. A directory that holds anything but a mission
    log is refused, and so is a mission log unless ``overwrite`` and it is a simulated one
    (:func:`check_log_directory`); so is a table that reading would refuse for its ranges (nothing is written then).
    """
    import yaml

    directory = Path(directory)
    if fmt not in ("parquet", "csv"):
        raise TanbenchError(f"mission-log tables are parquet or csv, not {fmt!r}")
    check_log_directory(directory, overwrite)
    for name, df in log.tables.items():
        for col in df.columns:
            if re.fullmatch(r"([a-z]+_)?range_\d+_m", col):
                check_ranges(f"cannot write the mission log {directory}: its {name} table", col, df[col].to_numpy())
    written = []
    try:
        for name, df in log.tables.items():
            df = _in_body_frame(df, log.meta.body_frame)
            path = directory / f"{name}.{fmt}"
            for stale in (directory / f"{name}{s}" for s in SUFFIXES):
                if stale != path:
                    stale.unlink(missing_ok=True)
            if fmt == "csv":
                store.write_text(df.to_csv(index=False), path)
            else:
                store.write_parquet(df, path, {"kind": "mission-log", "format_version": FORMAT_VERSION})
            written.append(path)
        for name in TABLES:
            if name not in log.tables:
                for stale in (directory / f"{name}{s}" for s in SUFFIXES):
                    stale.unlink(missing_ok=True)
        meta_text = yaml.safe_dump(log.meta.model_dump(mode="json", exclude_unset=True), sort_keys=False)
        store.write_text(meta_text, directory / META_FILE)
    except OSError as exc:
        raise TanbenchError(f"cannot write the mission log {directory}: {exc.strerror or exc}") from None
    return [directory / META_FILE, *written]


def _in_body_frame(df: pd.DataFrame, body_frame: str) -> pd.DataFrame:
    """A canonical (rfu) table with its body-frame vectors in ``body_frame``."""
    if body_frame == "rfu":
        return df
    df = df.copy()
    for names in ([f"{g}_rad_s" for g in GYRO], list(ACCEL), list(VELOCITY)):
        if names[0] in df.columns:
            df[names] = to_rfu(df[names].to_numpy(), body_frame)
    return df


def beam_block(ranges: np.ndarray, prefix: str = "") -> dict[str, np.ndarray]:
    """The ``range_<i>_m`` columns of a (pings, beams) array."""
    return dict(zip(range_columns(ranges.shape[1], prefix), ranges.T))
