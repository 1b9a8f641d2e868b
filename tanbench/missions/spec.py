"""The mission-log format (docs/missions.md is its specification): metadata, tables, columns.

A log is a directory: ``mission.yaml`` (:class:`LogMeta`) and one file per table,
``<table>.parquet`` or ``<table>.csv``. Every column name ends in its unit. Vectors are in
the vehicle body frame (``body_frame``: ``rfu`` x starboard, y forward, z up, tanbench's
own; or ``frd`` x forward, y starboard, z down); attitude is pitch (nose up positive), roll
(starboard down positive) and compass heading (clockwise from north), as tanbench's
navigation carries them. Positions are east/north metres in the map's frame or WGS84
longitude/latitude degrees, and up (or depth) in metres.

Sonar tables are fixed-width beam blocks, one row per ping and one ``range_<i>_m`` column
per beam (``i`` from 1), so one reader and one writer serve 1, 4 or 256 beams; the
beams' body-frame directions are in the metadata (``beams``).
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, Field, field_validator, model_validator

from tanbench.config import SensorSpec, _Strict
from tanbench.errors import TanbenchError
from tanbench.config import format_validation_error
from tanbench.sensors.sonar import altimeter_beam_vectors, dvl_beam_vectors
from tanbench.sweep import MAX_YAML_VALUES, UniqueKeyLoader, expanded_size

FORMAT_NAME = "tanbench-mission-log"
FORMAT_VERSION = 1
META_FILE = "mission.yaml"
SUFFIXES = (".parquet", ".csv")
TIME = "t_s"

# table -> required; what each holds is in docs/missions.md
TABLES = {"imu": True, "navigation": True, "depth": True, "dvl": True, "altimeter": False, "multibeam": False,
          "reference": False, "reference_ranges": False}
BEAM_SENSORS = ("dvl", "altimeter", "multibeam")
GYRO = tuple(f"gyro_{a}" for a in "xyz")  # + _rad_s or _deg_s
ACCEL = tuple(f"accel_{a}_m_s2" for a in "xyz")
VELOCITY = tuple(f"velocity_{a}_m_s" for a in "xyz")
ATTITUDE = ("pitch", "roll", "heading")  # + _rad or _deg
LOCAL = ("east_m", "north_m")
LONLAT = ("lon_deg", "lat_deg")
# accepted units of an angle and an angular rate: suffix -> factor to radians
ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0}
RATE_UNITS = {"rad_s": 1.0, "deg_s": math.pi / 180.0}
# SensorSpec keys that describe the DVL's beams (a Janus array); beams.dvl replaces them
JANUS_KEYS = frozenset({"beam_tilt_deg", "beam_azimuths_deg"})


def range_columns(beams: int, prefix: str = "") -> list[str]:
    """The beam block of a sonar table: ``range_1_m`` .. ``range_<beams>_m`` (``prefix`` before them)."""
    return [f"{prefix}range_{i}_m" for i in range(1, beams + 1)]


def parse_yaml_model(text: str, label: str, model: type[BaseModel], keys: str):
    """YAML ``text`` validated as ``model``; any problem is one TanbenchError line naming ``label``
    (``keys``: the top-level keys, for the message when the text is not a mapping)."""
    import yaml
    from pydantic import ValidationError

    try:
        data = yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        raise TanbenchError(f"{label}: malformed YAML ({str(exc).splitlines()[0]})") from None
    except RecursionError:
        raise TanbenchError(f"{label}: the YAML is nested too deeply") from None
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise TanbenchError(f"{label}: must be a mapping of keys ({keys})")
    if expanded_size(data) > MAX_YAML_VALUES:
        raise TanbenchError(f"{label}: the YAML's aliases (*name) expand to more than {MAX_YAML_VALUES} values")
    try:
        return model(**data)
    except ValidationError as exc:
        raise TanbenchError(f"{label}: {format_validation_error(exc)}") from None


class BeamGeometry(_Strict):
    """Body-frame directions of a sonar's beams, in exactly one of three forms."""

    vectors: tuple[tuple[float, float, float], ...] | None = Field(
        None, min_length=1, description="unit vectors in the log's body frame")
    tilt_deg: float | None = Field(None, ge=0, lt=90, description="a Janus array: tilt from the vertical ...")
    azimuths_deg: tuple[float, ...] | None = Field(
        None, min_length=1, description="... and azimuths clockwise from forward")
    across_track_deg: tuple[float, ...] | None = Field(
        None, min_length=1, description="a fan across track: angles from the vertical, starboard positive")

    @model_validator(mode="after")
    def _one_form(self):
        forms = [name for name, given in (("vectors", self.vectors is not None),
                                          ("tilt_deg with azimuths_deg", self.tilt_deg is not None
                                           or self.azimuths_deg is not None),
                                          ("across_track_deg", self.across_track_deg is not None)) if given]
        if len(forms) != 1:
            raise ValueError(f"give the beams as exactly one of vectors, tilt_deg with azimuths_deg, or "
                             f"across_track_deg (got {', '.join(forms) or 'none'})")
        if (self.tilt_deg is None) != (self.azimuths_deg is None):
            raise ValueError("tilt_deg and azimuths_deg go together")
        for k, v in enumerate(self.vectors or ()):
            if abs(math.hypot(*v) - 1.0) > 1e-6:
                raise ValueError(f"vector {k + 1} {list(v)} is not a unit vector (length {math.hypot(*v):.6g})")
        if any(abs(a) >= 90 for a in self.across_track_deg or ()):
            raise ValueError("across_track_deg must lie strictly between -90 and 90")
        return self

    def body_vectors(self, body_frame: str) -> np.ndarray:
        """(beams, 3) unit vectors in tanbench's body frame (x starboard, y forward, z up)."""
        if self.tilt_deg is not None:
            return dvl_beam_vectors(self.tilt_deg, self.azimuths_deg)  # angles are frame-free
        if self.across_track_deg is not None:
            a = np.radians(np.asarray(self.across_track_deg, dtype=float))
            return np.stack([np.sin(a), np.zeros_like(a), -np.cos(a)], axis=1)
        return to_rfu(np.asarray(self.vectors, dtype=float), body_frame)

    @property
    def count(self) -> int:
        return len(self.vectors or self.azimuths_deg or self.across_track_deg)


class LogMeta(_Strict):
    """``mission.yaml``: what the tables cannot say (docs/missions.md, "Metadata")."""

    format: Literal["tanbench-mission-log"]
    format_version: int
    description: str = ""
    body_frame: Literal["rfu", "frd"] = "rfu"
    sensors: SensorSpec = SensorSpec()
    range_noise_half_width_m: float = Field(
        1.0, ge=0, description="half-width of the uniform range noise of every beam (std = this / sqrt(3))")
    beams: dict[Literal["dvl", "altimeter", "multibeam"], BeamGeometry] = Field(default_factory=dict)
    source: dict[str, Any] = Field(default_factory=dict, description="free provenance, kept with replay results")

    @field_validator("format_version")
    @classmethod
    def _known_version(cls, v):
        if v != FORMAT_VERSION:
            raise ValueError(f"this tanbench reads mission-log version {FORMAT_VERSION}, not {v}")
        return v

    @model_validator(mode="after")
    def _dvl_geometry_once(self):
        given = sorted(JANUS_KEYS & self.sensors.model_fields_set)
        if "dvl" in self.beams and given:
            raise ValueError(f"the DVL beams are given twice: beams.dvl and sensors.{given[0]}; keep one")
        return self

    def beam_vectors(self, sensor: str) -> np.ndarray | None:
        """(beams, 3) body-frame (rfu) directions of ``sensor``'s beams; None for a multibeam not described."""
        if sensor in self.beams:
            return self.beams[sensor].body_vectors(self.body_frame)
        if sensor == "dvl":
            return dvl_beam_vectors(self.sensors.beam_tilt_deg, self.sensors.beam_azimuths_deg)
        if sensor == "altimeter":
            return altimeter_beam_vectors()
        return None


def to_rfu(vectors: np.ndarray, body_frame: str) -> np.ndarray:
    """(..., 3) body-frame vectors in tanbench's rfu frame (an frd x, y, z is rfu y, x, -z)."""
    if body_frame == "rfu":
        return vectors
    return np.stack([vectors[..., 1], vectors[..., 0], -vectors[..., 2]], axis=-1)
