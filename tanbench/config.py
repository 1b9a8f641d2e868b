"""Scenario and sweep specifications, validated with pydantic.

A :class:`Scenario` is everything one Monte Carlo cell needs: terrain, area and
trajectory, sensor grades, navigation-system initial errors and filter settings.
Defaults are the paper's (Tables 1-2, Section 4); the area presets (``A``, ``B``,
``vehicle``) fill in what differs between the paper's runs. Unknown keys are errors.

``Scenario.world_key()`` hashes only what defines the simulated vehicle data (terrain,
trajectory, sensors, initial navigation errors); cells that share it share their random
vehicle data (common random numbers). The range-noise level ``noise_m`` is left out on
purpose: noise is drawn as unit uniforms and scaled, so cells that differ only in
noise share their random numbers too (and the simulation uses ``noise_m`` itself).
``cell_key()`` hashes everything that can change a run's outcome.

Identities survive new options: an option added with :func:`new_option` is left out of
the keys while it holds its *neutral* value (the value that reproduces the behaviour
from before the option existed), so adding a defaulted option changes no cell key, no
seed and no stored result. Changing what a model does without an option is marked by
bumping :data:`MODEL_VERSION`, which enters every key once it is above 1.
"""

from __future__ import annotations

import hashlib
import json
import math
import types
import typing
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator, model_validator

from tanbench.options import (COLLAPSE_REINIT, DISTANCE_INNOVATION, GYRO_BIAS_NOISE, INITIAL_CLOUD, LIKELIHOOD,
                              LIKELIHOOD_R, LOOSE_ARCHITECTURE, LOOSE_FIRST_FIX, LOOSE_FIX_PRIOR_FALLBACK,
                              LOOSE_REOPEN_HEADING, LOOSE_REOPEN_POSITION, MAP_REPRESENTATION, MAX_SEED,
                              MULTIBEAM_PATTERN, POSITION_NOISE_GROWTH, PROPAGATION, RANGE_NOISE, RECOVERY,
                              RECOVERY_SEARCH_AROUND, RECOVERY_SECOND_AMBIGUITY, REGULARISATION, REGULARISED_STATES,
                              RESAMPLING, TIGHT_REGULARISATION, choices)
from tanbench.paperdata import scenario_facts
from tanbench.units import DEG_PER_H, DEG_PER_SQRT_H

# Bump when a model's behaviour changes without a new option (the commit says why): every
# cell key then changes, so no stored run is reused for results that would differ.
# 2: the particle filters' vectorised passes (particles as columns, branch-free trigonometry,
#    logarithm and exponential, block fills of random numbers, fixed-order sums): the same
#    models, other rounding and another order of draws, so runs take other paths.
MODEL_VERSION = 2
_SAME = object()


def new_option(default, *, neutral=_SAME, **field_kwargs):
    """A pydantic ``Field`` for an option added after results were stored.

    ``neutral`` (default: ``default``) is the value under which the model behaves as it
    did before the option existed; while a scenario holds it, the option is left out of
    :meth:`Scenario.cell_key` and :meth:`Scenario.world_key`. To change a recommended
    default on purpose, give the new ``default`` and keep ``neutral`` at the old
    behaviour's value: keys then change for every cell that uses the new default.
    """
    extra = dict(field_kwargs.pop("json_schema_extra", None) or {})
    extra["key_neutral"] = json.loads(json.dumps(default if neutral is _SAME else neutral))
    return Field(default, json_schema_extra=extra, **field_kwargs)


# the loose TAN's options that act only in its loop with heading offsets (filters/loose_turned.py): a value other
# than the neutral one (the key's, ``new_option``) needs filter.loose_heading_offsets (named in this order)
TURNED_LOOP_ONLY = ("loose_bias_gate_sigma", "loose_fix_shape", "loose_fix_prior_gate", "loose_fix_fit_test",
                    "loose_fix_fit_one_wild_beam", "loose_reopen_heading", "loose_reopen_position", "loose_first_fix",
                    "loose_fix_correlation_s")


def _yaml_word(value) -> str:
    """An option's value as a sweep file spells it (true, false, cloud)."""
    if value is None:
        return "null"
    return str(value).lower() if isinstance(value, bool) else str(value)


def _is_numeric(annotation) -> bool:
    """Whether a field takes numbers (int or float, alone, in a union or in a tuple) and no booleans."""
    kinds = set()

    def walk(ann):
        origin = typing.get_origin(ann)
        if origin in (typing.Union, types.UnionType, tuple):
            for arg in typing.get_args(ann):
                walk(arg)
        elif ann in (bool, int, float):
            kinds.add(ann)

    walk(annotation)
    return bool(kinds) and bool not in kinds


def plain_number_check(model: type[BaseModel], value, field_name: str):
    """Refuse a boolean where a number (or text) is expected, and any non-finite number.

    YAML reads ``true`` as a boolean and pydantic would take it as 1; ``.inf`` and
    ``.nan`` are floats that no scenario parameter can mean. (Fields in
    ``NON_FINITE_OK`` take non-finite values on purpose, e.g. a file's ``nodata``.)
    """
    info = model.model_fields.get(field_name)
    if info is None or field_name in NON_FINITE_OK:
        return value
    items = value if isinstance(value, (list, tuple)) else (value,)
    for item in items:
        if isinstance(item, bool) and _is_numeric(info.annotation):
            raise ValueError(f"expected a number, not the boolean {str(item).lower()}")
        if isinstance(item, float) and not math.isfinite(item):
            raise ValueError(f"must be a finite number, not {item}")
    return value


NON_FINITE_OK = {"nodata"}


def _short_repr(value, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit - 20]}... ({len(text)} characters)"


MAX_PROBLEMS = 5  # named in one validation error line; the rest are counted


def format_validation_error(exc: ValidationError, prefix: str = "") -> str:
    """Every pydantic error of a spec (the first MAX_PROBLEMS) as one line: 'key.path: message (got value); ...'."""
    errors = exc.errors()
    parts = [_format_problem(err, prefix) for err in errors[:MAX_PROBLEMS]]
    more = len(errors) - MAX_PROBLEMS
    if more > 0:
        parts.append(f"and {more} more problem{'s' if more > 1 else ''}")
    return "; ".join(parts)


def _format_problem(err: dict, prefix: str) -> str:
    """One pydantic error as 'key.path: message (got value)'."""
    loc = ".".join(str(p) for p in err["loc"])
    loc = f"{prefix}{loc}" if loc else prefix.rstrip(".")
    msg = err["msg"]
    if err["type"] == "extra_forbidden":
        msg = "unknown key"
    elif msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    got = err.get("input")
    shown = "" if err["type"] in ("extra_forbidden", "missing") or isinstance(got, (dict, list)) else \
        f" (got {_short_repr(got)})"
    return " ".join(f"{loc}: {msg}{shown}".split()) if loc else " ".join(f"{msg}{shown}".split())


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    @field_validator("*", mode="before")
    @classmethod
    def _plain_numbers(cls, value, info: ValidationInfo):
        return plain_number_check(cls, value, info.field_name)


Pos = float  # documentation alias: metres


class TerrainSpec(_Strict):
    """Where the seafloor comes from: the built-in synthetic maps or a bathymetry file."""

    kind: Literal["synthetic", "file"] = "synthetic"
    seed: int = Field(1, ge=0, le=MAX_SEED, description="synthetic seafloor seed")
    layout: Literal["auto", "paper", "vehicle-run"] = Field(
        "auto", description="synthetic layout; auto = 'vehicle-run' for area vehicle, else 'paper'")
    truth_resolution_m: float = Field(2.5, gt=0, le=10, description="synthetic truth grid spacing")
    map_error_m: float = Field(0.4, ge=0, description="std of the navigation map's node errors")
    map_error_correlation_m: float = new_option(
        0.0, ge=0, description="fault: correlation length of the map error field (0: i.i.d. nodes)")
    path: str | list[str] | None = Field(
        None, description="bathymetry file(s) or a glob of tiles, relative to the working directory")
    format: str | None = Field(
        None, description="a registered grid format (geotiff, netcdf, esri-ascii, npy, npz, or a plug-in's); "
                          "default from the file suffix")
    bounds: tuple[float, float, float, float] | None = Field(
        None, description="(west, east, south, north) of a file without georeferencing")
    origin: tuple[float, float] | None = Field(None, description="(e0, n0) of node [0, 0], metres")
    resolution: float | tuple[float, float] | None = Field(None, description="grid spacing, metres")
    rows: Literal["auto", "south_to_north", "north_to_south"] = "auto"
    crs: Literal["metric", "projected", "epsg4326", "geographic", "epsg3857"] | None = Field(
        None, description="grid coordinates: metres, lon/lat degrees or Web Mercator; default from the file")
    nodata: float | None = None
    positive: Literal["up", "down"] = new_option(
        "up", description="what the file's values measure: up = elevation (seafloor negative), down = depth (negated)")
    fill_holes: bool = Field(False, description="fill no-data holes instead of rejecting the map")
    resample_m: float | None = new_option(
        None, gt=0, le=1000, description="file: resample the grid bilinearly onto square nodes of this spacing "
                                         "(terrain/reshape.py)")
    depth_range_m: tuple[float, float] | None = new_option(
        None, description="file: rescale the elevations linearly to [low, high] metres (e.g. [-180, -60])")
    transform: Literal["none", "transpose", "mirror-east"] = new_option(
        "none", description="file: lay the relief out again: east and north swapped, or mirrored east-west")
    region_hurst: dict[str, float] | None = new_option(
        None, description="synthetic: spectral (Hurst) exponent per region name (A, B, flat, rough, background); "
                          "unset regions keep the layout's")
    region_corner_m: dict[str, float] | None = new_option(
        None, description="synthetic: corner length (m) per region name; unset regions keep the layout's")

    @model_validator(mode="after")
    def _roughness_in_range(self):
        for label, values, lo, hi in (("region_hurst", self.region_hurst, 0.1, 3.0),
                                      ("region_corner_m", self.region_corner_m, 10.0, 1e5)):
            for name, v in (values or {}).items():
                if not lo <= v <= hi:
                    raise ValueError(f"{label}.{name} must be in [{lo:g}, {hi:g}] (got {v:g})")
        if (self.region_hurst or self.region_corner_m) and self.kind != "synthetic":
            raise ValueError("region_hurst / region_corner_m apply to synthetic terrain only")
        return self

    @model_validator(mode="after")
    def _depth_range_ordered(self):
        if self.depth_range_m is not None and not self.depth_range_m[0] < self.depth_range_m[1]:
            raise ValueError(f"depth_range_m must be [low, high] with low < high (got {list(self.depth_range_m)})")
        return self

    @model_validator(mode="after")
    def _file_needs_path(self):
        if self.kind == "file" and not self.path:
            raise ValueError("terrain kind 'file' needs a 'path'")
        return self

    @model_validator(mode="after")
    def _settings_of_the_kind(self):
        """A setting of the other kind of terrain would be ignored: refuse it."""
        given = self.model_fields_set
        other = FILE_ONLY if self.kind == "synthetic" else SYNTHETIC_ONLY
        used = [k for k in other if k in given and getattr(self, k) != type(self).model_fields[k].default]
        if used:
            needs = "file" if self.kind == "synthetic" else "synthetic"
            raise ValueError(f"{used[0]} applies to {needs} terrain only (kind: {needs}); this terrain is "
                             f"{self.kind}, so it would be ignored: remove it or set kind: {needs}")
        return self

    def resolved(self, area: str | None = None) -> "TerrainSpec":
        """This spec with a synthetic ``layout: auto`` resolved for ``area``."""
        if self.kind != "synthetic" or self.layout != "auto":
            return self
        return self.model_copy(update={"layout": "vehicle-run" if area == "vehicle" else "paper"})


FILE_ONLY = ("path", "format", "bounds", "origin", "resolution", "rows", "crs", "nodata", "positive", "fill_holes",
             "resample_m", "depth_range_m", "transform")
SYNTHETIC_ONLY = ("layout", "truth_resolution_m", "region_hurst", "region_corner_m")


class TrajectorySpec(_Strict):
    """The vehicle's true path. ``auto`` follows the area: the paper's run or the vehicle run."""

    kind: Literal["auto", "paper", "vehicle-run", "survey"] = "auto"
    start_enu_m: tuple[float, float, float] | None = Field(
        None, description="start (east, north, up); default from the area")
    speed_mps: float = Field(2.0, gt=0, le=20)
    legs: int = Field(4, ge=1, le=100)
    leg_spacing_m: float = Field(80.0, gt=0)
    leg_length_m: float | None = Field(None, gt=0, description="None = fill the cruise time")
    first_turn: Literal["left", "right"] = "left"
    dive_pitch_rate_deg_s: float = Field(0.1, ge=0, le=2)
    cruise_s: float = Field(840.0, gt=0)
    # survey (arbitrary maps): a lawn-mower placed by centre and heading
    centre_en_m: tuple[float, float] | None = None
    heading_deg: float = 0.0
    depth_m: float = Field(30.0, ge=0)


class SensorSpec(_Strict):
    """Sensor grades and error models (Table 1 by default; ``grade: table8`` for the vehicle run)."""

    grade: Literal["auto", "table1", "table8"] = "auto"
    imu_rate_hz: float = Field(100.0, gt=0, le=1000)
    latitude_deg: float = Field(30.0, ge=-80, le=80)
    # upper bounds: far beyond any navigation sensor (a gyro drifting 10 deg/s, an accelerometer off by 1 g)
    gyro_turn_on_bias_deg_h: float | None = Field(None, ge=0, le=36000)
    gyro_bias_instability_deg_h: float | None = Field(None, ge=0, le=36000)
    gyro_bias_corr_time_s: float = Field(300.0, gt=0)
    gyro_arw_deg_sqrt_h: float | None = Field(None, ge=0, le=100)
    accel_turn_on_bias_mg: float | None = Field(None, ge=0, le=1000)
    accel_bias_instability_mg: float | None = Field(None, ge=0, le=1000)
    accel_bias_corr_time_s: float = Field(300.0, gt=0)
    accel_noise_mg_sqrt_hz: float | None = Field(None, ge=0, le=100)
    dvl_scale_error: float = Field(0.004, ge=0, lt=0.5)
    dvl_noise_mps: float = Field(0.002, ge=0, le=5)
    beam_tilt_deg: float = Field(30.0, gt=0, lt=60)
    beam_azimuths_deg: tuple[float, ...] = Field((0.0, 90.0, 180.0, 270.0), min_length=1)
    dvl_beamwidth_deg: float = Field(4.0, ge=0, lt=30)
    altimeter_beamwidth_deg: float = Field(2.1, ge=0, lt=30)
    beam_footprint: bool = Field(False, description="model the beam width (first return in the cone)")
    sonar_rate_hz: float = Field(1.0, gt=0, le=20)
    max_range_m: float = Field(200.0, gt=0)
    pressure_error_percent: float = Field(0.01, ge=0, le=100)
    pressure_full_scale_m: float = Field(200.0, gt=0)
    # the multibeam echo sounder (sensors/multibeam.py, docs/multibeam.md); off (0 beams) by default
    multibeam_beams: int = new_option(0, ge=0, le=1024, description="beams in the multibeam swath (0: no multibeam)")
    multibeam_swath_deg: float = new_option(120.0, gt=0, lt=170, description="multibeam: full fan angle across track")
    multibeam_pattern: choices(MULTIBEAM_PATTERN) = new_option(
        "equiangular", description="multibeam: beams equally spaced in angle, or in across-track distance on a "
                                   "flat seafloor")
    multibeam_range_noise_m: float = new_option(0.1, ge=0, le=10, description="multibeam: range noise std (Gaussian)")
    multibeam_angle_noise_deg: float = new_option(
        0.05, ge=0, le=5, description="multibeam: std of each beam's pointing error (the range is cast along the "
                                      "perturbed beam)")
    multibeam_rate_hz: float = new_option(
        1.0, gt=0, le=20, description="multibeam pings per second: every k-th DVL ping (sonar_rate_hz / this whole)")

    @model_validator(mode="after")
    def _multibeam_on_the_sonar_clock(self):
        if self.multibeam_beams:
            k = self.sonar_rate_hz / self.multibeam_rate_hz
            if abs(k - round(k)) > 1e-6 or round(k) < 1:
                raise ValueError(f"multibeam_rate_hz ({self.multibeam_rate_hz:g}) must divide sonar_rate_hz "
                                 f"({self.sonar_rate_hz:g}): a multibeam ping comes with every k-th DVL ping")
        return self

    @model_validator(mode="after")
    def _a_ping_at_an_imu_sample(self):
        if self.imu_rate_hz < self.sonar_rate_hz:
            raise ValueError(f"imu_rate_hz ({self.imu_rate_hz:g}) must be at least sonar_rate_hz "
                             f"({self.sonar_rate_hz:g}): every sonar ping is taken at an IMU sample")
        return self

    def resolved(self, default_grade: str) -> "SensorSpec":
        """This spec with ``grade: auto`` replaced and unset error figures taken from the grade."""
        grade = self.grade if self.grade != "auto" else default_grade
        presets = SENSOR_GRADES[grade]
        update = {k: v for k, v in presets.items() if getattr(self, k) is None}
        update["grade"] = grade
        return self.model_copy(update=update)


# Table 1 (the AUV's low-cost SINS) and Table 8 (the test vehicle's IMU). Table 8 gives one
# "drift" figure for the gyros; tanbench uses it for both the turn-on bias and the in-run
# instability, and Table 8's accelerometer "bias error" likewise.
SENSOR_GRADES = {
    "table1": dict(gyro_turn_on_bias_deg_h=30.0, gyro_bias_instability_deg_h=25.0,
                   gyro_arw_deg_sqrt_h=2.0, accel_turn_on_bias_mg=50.0,
                   accel_bias_instability_mg=0.2, accel_noise_mg_sqrt_hz=0.5),
    "table8": dict(gyro_turn_on_bias_deg_h=1.0, gyro_bias_instability_deg_h=1.0,
                   gyro_arw_deg_sqrt_h=0.1, accel_turn_on_bias_mg=0.2,
                   accel_bias_instability_mg=0.2, accel_noise_mg_sqrt_hz=0.2),
}


class NavigationSpec(_Strict):
    """The navigation system's (INS / dead reckoning) initial errors and levelling."""

    initial_heading_error_deg: float | None = Field(None, ge=-180, le=180)
    initial_position_error_m: float | None = Field(
        None, ge=0, description="side of the square of uniform initial horizontal error")
    accel_bias_calibrated: bool = Field(
        True, description="the accelerometer turn-on bias is removed by the surface (GPS-aided) alignment")
    level_window_s: float = Field(1.0, ge=0.01, le=60)
    level_compensation: bool = Field(True, description="remove omega x v from the specific force")


def position_noise(q: float, r: float, dist_mode: int) -> float:
    """East/north noise per update: Table 2's q, or q combined with the distance noise r
    (``filter.distance_innovation: particle``, :mod:`tanbench.filters.propagate`)."""
    if dist_mode == DISTANCE_INNOVATION["particle"]:
        return q * r / math.sqrt(q * q + r * r)
    return q


class FilterSpec(_Strict):
    """Particle-filter settings (Table 2 as read in docs/model.md).

    The defaults live here and only here: every kernel's parameter bundle is built from
    this spec by one constructor next to the kernel (docs/architecture.md), and the derived
    quantities (noise per update, the likelihood's sigmas) are the properties below and
    on :class:`Scenario`.
    """

    initial_area_m: float = Field(150.0, gt=0, description="side of the uniform initial square")
    initial_cloud: choices(INITIAL_CLOUD) = new_option(
        "uniform", description="initial horizontal cloud: uniform square of side initial_area_m, or Gaussian with "
                               "std initial_area_m (Table 2's 150 m read as a standard deviation)")
    propagation: choices(PROPAGATION) = new_option(
        "exact", description="exact 100 Hz increments, or Eq. 1 as one Euler step over the sampling time with the "
                             "DVL velocity and body turn rates averaged over the last second / at the update sample / "
                             "at the interval's start")
    initial_std_up_m: float = Field(0.1, ge=0)
    initial_std_pitch_roll_deg: float = Field(0.1, ge=0)
    initial_std_heading_deg: float = Field(30.0, ge=0)
    initial_std_gyro_bias_deg_h: float = Field(25.0, ge=0)
    process_noise_velocity_mps: float = Field(0.1, ge=0)
    position_noise_growth: choices(POSITION_NOISE_GROWTH) = new_option(
        "linear", description="the tight and loose particle filters' east/north process noise per update: "
                              "process_noise_velocity_mps * T, or * sqrt(T) (a random walk in position)")
    process_noise_up_m: float = Field(0.01, ge=0)
    process_noise_attitude_deg_sqrt_h: float = Field(2.0, ge=0)
    measurement_noise_distance_m: float = Field(0.1, gt=0)
    measurement_noise_altitude_m: float = Field(1.0, gt=0)
    likelihood_r: choices(LIKELIHOOD_R) = new_option(
        "per-component", description="Eq. 20's |R|: per-component variances, or one scalar variance for every "
                                     "term (the norm of R = its largest variance, or its determinant)")
    distance_innovation: choices(DISTANCE_INNOVATION) = "particle"
    resampling: choices(RESAMPLING) = "systematic"
    ess_threshold: float = Field(0.5, gt=0, le=1, description="resample when ESS < threshold * N")
    regularisation: choices(REGULARISATION) = Field(
        "liu-west", description="jitter after resampling: Liu-West shrinkage kernel or Gordon roughening")
    regularised_states: choices(REGULARISED_STATES) = "position-heading-biases"
    regularisation_h: float = Field(0.1, gt=0, lt=1, description="Liu-West kernel width h")
    roughening: float = Field(0.2, ge=0, description="Gordon roughening constant K")
    min_spread_m: float = Field(2.0, ge=0, description="cloud std below which positions are re-spread")
    divergence_sigma: float = Field(4.0, gt=0, description="RMS innovation (in sigmas) meaning divergence")
    divergence_steps: int = Field(10, ge=1)
    divergence_reinit: bool = new_option(
        True, description="reinitialise a diverged filter (divergence_sigma, divergence_steps)")
    collapse_reinit: choices(COLLAPSE_REINIT) = new_option(
        "respread", description="a cloud below min_spread_m: re-spread positions to that std, or redraw the whole "
                                "cloud with its initial spread around the estimate")
    outside_map_sigma: float = Field(5.0, gt=0, description="innovation charged to a beam off the map")
    loose_heading_noise: bool = Field(
        True, description="loose filter: cross-track process noise from the heading uncertainty")
    loose_converged_std_m: float = Field(10.0, gt=0, description="loose filter: std for a position fix")
    random_numbers: Literal["numpy", "fast"] = new_option(
        "fast", neutral="numpy", description="the jitted loops' random numbers: lanes of xoshiro256++ with a "
                                             "ziggurat normal (tanbench/filters/rng.py), or the run's numpy "
                                             "Generator [numpy]")
    convergence_threshold_m: float = Field(20.0, gt=0)
    divergence_threshold_m: float = Field(75.0, gt=0)
    # recommended settings (docs/model.md, Section 6.3); the paper's plain reading in brackets
    loose_architecture: choices(LOOSE_ARCHITECTURE) = new_option(
        "kalman-feedback", neutral="fix-only", description="loose TAN: fixes to the navigation KF, closed loop [fix-only]")
    loose_fix_interval_s: float = new_option(10.0, gt=0, description="loose TAN: time between fixes to the KF")
    loose_fix_gate: float = new_option(13.8, gt=0, description="loose TAN: chi-square (2 dof) gate on fixes")
    loose_fix_floor_m: float = new_option(1.0, neutral=5.0, ge=0, description="loose TAN: std added to a fix's own "
                                                                            "[5: sized for the loose PF without "
                                                                            "heading offsets]")
    loose_fix_correlation_s: float = new_option(
        40.0, neutral=0.0, ge=0, description="loose TAN: correlation time of a fix's error (s); above 0 the KF updates "
                                             "with each fix's covariance times (1 + r) / (1 - r), r = exp(-fix interval "
                                             "/ this), the variance per fix of a mean of such correlated fixes [0: "
                                             "independent fixes]")
    loose_fix_max_std_m: float = new_option(
        25.0, gt=0, description="loose TAN: a window's terrain-only fix weaker than this is not used")
    loose_fix_misses: int = new_option(
        3, ge=1, description="loose TAN: fixes rejected in a row after which the navigation KF is reopened")
    map_aware_likelihood: bool = new_option(
        True, neutral=False, description="beam variance + map representation error + declared map error [false]")
    map_slope_factor: float = new_option(0.2887, ge=0, description="c in (c |grad h| res)^2; 1/sqrt(12)")
    likelihood: choices(LIKELIHOOD) = new_option("student-t", neutral="gaussian", description="beam density [gaussian]")
    student_nu: float = new_option(4.0, gt=0, description="Student-t degrees of freedom")
    keep_on_map: bool = new_option(True, neutral=False, description="clamp the estimate into the map, reinitialise there [false]")
    divergence_spread_m: float | None = new_option(
        100.0, neutral=None, gt=0, description="horizontal cloud std counted as divergence [None: not checked]")
    reinit_area_m: float | None = new_option(
        None, gt=0, description="tight filter: side of the uniform square a reinitialised cloud (divergence, collapse, "
                                "off the map) is redrawn over [None: initial_area_m]; a Gaussian initial_cloud keeps "
                                "its std")

    # issue 24 (docs/filters.md sections 5-6): the tight filters near the bound and never lost
    gyro_bias_noise: choices(GYRO_BIAS_NOISE) = new_option(
        "data-sheet", neutral="none", description="tight PFs: the gyro biases random-walk at the data sheet's in-run "
                                                  "rate (sensors.gyro_bias_instability_deg_h over "
                                                  "gyro_bias_corr_time_s), and the bound follows [none: Table 2]")
    tight_regularisation: choices(TIGHT_REGULARISATION) = new_option(
        "posterior", neutral="shared", description="tight PFs: jitter with the posterior-sized kernel (weighted "
                                                   "covariance, regularisation_bandwidth x h_opt) and re-spread "
                                                   "below tight_min_spread_m [shared: regularisation, min_spread_m]")
    regularisation_bandwidth: float = new_option(
        0.5, gt=0, le=3, description="posterior kernel: factor on the optimal Gaussian kernel width h_opt")
    single_beam_regularisation_bandwidth: float | None = new_option(
        None, gt=0, le=3, description="posterior kernel: the bandwidth factor of a tight PF weighted by a single beam "
                                      "(tight-sbe; docs/filters.md 8) [None: regularisation_bandwidth]")
    single_beam_ess_threshold: float | None = new_option(
        None, gt=0, le=1, description="resample a tight PF weighted by a single beam (tight-sbe) when ESS < threshold * N "
                                      "(docs/filters.md 8) [None: ess_threshold]")
    tight_min_spread_m: float = new_option(
        0.0, ge=0, description="posterior kernel: cloud std below which positions are re-spread (0: never)")
    loose_heading_offsets: bool = new_option(
        True, neutral=False, description="loose TAN (kalman-feedback): each particle carries a heading offset from the "
                                         "corrected heading and sees its beams turned by it (filters/loose_turned.py)")
    loose_bias_gate_sigma: float | None = new_option(
        3.0, neutral=None, gt=0, description="loose TAN with heading offsets: reject a fix that puts the z-gyro bias "
                                             "above this many initial_std_gyro_bias_deg_h [None: no gate]")
    loose_fix_shape: float | None = new_option(
        0.9, neutral=None, gt=0, lt=1, description="loose TAN with heading offsets: no fix from a cloud with less "
                                                   "weight inside its own 95 % ellipse [None: no gate]")
    loose_fix_prior_gate: float | None = new_option(
        None, gt=0, description="loose TAN with heading offsets: refuse a terrain-only fix whose chi-square (2 dof) "
                                "against its own window prior is not below this (docs/filters.md 9; 13.8 helps "
                                "fault-free relief and hurts under world faults) [None: no gate]")
    loose_fix_prior_fallback: choices(LOOSE_FIX_PRIOR_FALLBACK) = new_option(
        "refuse", description="loose TAN: a terrain-only fix that fails loose_fix_prior_gate is refused, or replaced "
                              "by the PF's posterior mean with the window prior's covariance (docs/filters.md 9.1) "
                              "[refuse]")
    loose_fix_fit_test: bool = new_option(
        True, description="loose TAN with heading offsets: a fix needs divergence_steps updates in a row whose best "
                          "particle fits within divergence_sigma / 2 as well as a cloud std below loose_converged_std_m "
                          "(false: the cloud std alone; docs/filters.md 11)")
    loose_fix_fit_one_wild_beam: bool = new_option(
        True, neutral=False,
        description="loose TAN with the fit test: an update that fails it by one beam only (the most likely particle "
                    "fits without its worst beam, 3 beams or more) or has no bottom lock neither counts toward a fix "
                    "nor restarts the count (the default since docs/filters.md 11.3) [false]")
    loose_first_fix: choices(LOOSE_FIRST_FIX) = new_option(
        "terrain-only", description="loose TAN with heading offsets: the first fix after a (re)initialisation resets the "
                                    "KF's position to the terrain-only fix, or to the cloud's posterior mean and "
                                    "covariance (docs/filters.md 13) [terrain-only]")
    loose_reopen_heading: choices(LOOSE_REOPEN_HEADING) = new_option(
        "cloud", neutral="navigation",
        description="loose TAN with heading offsets: a KF reopened after loose_fix_misses rejected fixes keeps its own "
                    "heading, or takes the cloud's weighted mean heading (the default since docs/filters.md 14.2) "
                    "[navigation]")
    loose_reopen_position: choices(LOOSE_REOPEN_POSITION) = new_option(
        "fix", neutral="prior",
        description="loose TAN with heading offsets: a KF reopened after loose_fix_misses rejected fixes gets its initial "
                    "position variance back and the fix is tried again; with fix (the default since docs/filters.md "
                    "15.2), a fix the reopened KF still rejects sets its position like a first fix [prior]")
    recovery: choices(RECOVERY) = new_option(
        "global", neutral="estimate",
        description="tight PFs: re-draw a diverged cloud around its own estimate, around the last healthy estimate "
                    "moved on by dead reckoning (filters/recovery.py), or where a batch terrain match of the "
                    "filter's last updates puts the vehicle (global, the default since docs/filters.md 10.1; "
                    "filters/relocalise.py)")
    recovery_growth_mps: float = new_option(
        0.5, ge=0, description="last-healthy recovery: growth of the re-draw square's half side per second")
    recovery_max_side_m: float = new_option(
        1000.0, gt=0, description="last-healthy recovery: largest side of the re-draw square; global recovery: "
                                  "side of the square searched around the estimate")
    recovery_profile_updates: int = new_option(
        240, ge=2, le=2000, description="global recovery: updates of terrain measurements in the matched profile "
                                         "(all so far while fewer, from 120 on)")
    recovery_heading_span_deg: float = new_option(
        90.0, ge=0, le=180, description="global recovery: largest heading rotation of the profile, either way")
    recovery_heading_step_deg: float = new_option(
        2.0, gt=0, le=90, description="global recovery: step between the profile's heading rotations")
    recovery_fix_std_m: float = new_option(
        10.0, gt=0, description="global recovery: a match whose likelihood std (TERCOM's ambiguity test) is above "
                                "this is not used (the built-in re-draw instead)")
    recovery_search_around: choices(RECOVERY_SEARCH_AROUND) = new_option(
        "estimate-then-distant-navigation", neutral="estimate",
        description="global recovery: search the square around the diverged filter's estimate only, or, when that "
                    "match is refused, a second square around the navigation solution (always, or only when the "
                    "navigation solution lies outside the first square; the default since docs/filters.md 18.1) "
                    "[estimate]")
    recovery_second_ambiguity: choices(RECOVERY_SECOND_AMBIGUITY) = new_option(
        "its-square",
        description="global recovery, second square: TERCOM's ambiguity test of a match around the navigation solution "
                    "weighs that square's candidates only, or both squares' (a candidate in the first square as good "
                    "as the match makes it ambiguous; docs/filters.md 19) [its-square]")
    # issue 24's accuracy study (docs/filters.md section 7): the likelihood's width
    range_noise: choices(RANGE_NOISE) = new_option(
        "table-2", description="every method's range (altitude) noise in the likelihood: Table 2's "
                              "measurement_noise_altitude_m, or the sonar's data sheet: noise_m / sqrt(3), the std "
                              "of its uniform noise of half-width noise_m [table-2]")
    map_representation: choices(MAP_REPRESENTATION) = new_option(
        "slope", description="map-aware likelihood: the map's representation variance as a nearest-node lookup's "
                             "(map_slope_factor |grad h| res)^2, or bilinear interpolation's own error from the "
                             "map's second differences; plus the declared map error either way [slope]")
    # progressive correction (docs/filters.md section 5 item 4 and section 22; filters/tempering.py)
    tempering_ess: float = new_option(
        0.0, ge=0, lt=1, description="tight PFs: progressive correction: an update that would leave fewer than this "
                                     "fraction of the particles effective is applied in stages, each down to that "
                                     "ESS, then resampled, regularised and weighed again [0: off]")
    tempering_stages: int = new_option(
        8, ge=2, le=64, description="tight PFs with tempering_ess above 0: most stages per update (the last applies "
                                    "whatever remains)")
    # an adaptive particle count (docs/model.md 6.1, docs/filters.md section 23; filters/kld.py)
    kld_epsilon: float | None = new_option(
        None, gt=0, lt=1, description="tight PFs: KLD sampling: each resampling draws the particles that bound the "
                                      "histogram's KL divergence by this (delta 0.01), between kld_min_particles and "
                                      "particles [None: a fixed count]")
    kld_bin_m: float = new_option(2.0, gt=0, description="KLD sampling: east and north bin size (m)")
    kld_bin_deg: float = new_option(5.0, gt=0, description="KLD sampling: heading bin size (deg)")
    kld_min_particles: int = new_option(
        300, ge=16, description="KLD sampling: fewest particles a resampling draws (at most particles)")

    @model_validator(mode="after")
    def _gates_need_heading_offsets(self):
        if not self.loose_heading_offsets:
            # every option that acts only in the loop with heading offsets, and the value it must take without it
            allowed = {name: type(self).model_fields[name].json_schema_extra["key_neutral"] for name in TURNED_LOOP_ONLY}
            wrong = [(name, getattr(self, name), value) for name, value in allowed.items()
                     if getattr(self, name) != value]
            if wrong:  # all of them in one line, so that one edit of the sweep file mends them
                raise ValueError(", ".join(f"filter.{name}: {_yaml_word(value)}" for name, value, _ in wrong)
                                 + (" needs" if len(wrong) == 1 else " need")
                                 + " filter.loose_heading_offsets: true (without it set "
                                 + ", ".join(f"{name}: {_yaml_word(value)}" for name, _, value in wrong) + ")")
        if self.kld_epsilon is not None and (self.tight_regularisation != "posterior" or self.regularisation == "none"):
            raise ValueError("filter.kld_epsilon needs filter.tight_regularisation: posterior and a regularisation "
                             "(the adaptive count is built on the posterior-sized kernel)")
        if self.kld_epsilon is not None and self.tempering_ess > 0.0:
            raise ValueError("filter.kld_epsilon with filter.tempering_ess above 0: the tempering stages resample at "
                             "the cloud's count and keep its ESS up, so the count would hardly ever change (set one "
                             "of them)")
        if self.tempering_ess > 0.0 and self.distance_innovation == "navigation":
            raise ValueError("filter.tempering_ess above 0 needs filter.distance_innovation other than navigation "
                             "(a tempering stage weighs resampled particles, whose propagated distances are gone)")
        if self.loose_fix_prior_fallback != "refuse" and self.loose_fix_prior_gate is None:
            raise ValueError("filter.loose_fix_prior_fallback: posterior needs filter.loose_fix_prior_gate "
                             "(the fixes it replaces are the ones that gate refuses)")
        return self

    # ---- derived quantities -----------------------------------------------------
    @property
    def measurement_sigmas_m(self) -> tuple[float, float]:
        """(distance, altitude) noise std of the particle filters' likelihood under ``likelihood_r``
        with Table 2's altitude sigma (:meth:`Scenario.measurement_sigmas_m` applies ``range_noise``).

        ``per-component``: Table 2's diag(0.1, 0.1, 1)^2 as given. ``scalar-norm``: Eq. 20's
        single |R| as the norm of R (its largest variance), for every term.
        ``scalar-determinant``: |R| as the determinant of R, taken as a variance in m^2.
        """
        return self.likelihood_sigmas_m(self.measurement_noise_altitude_m)

    def likelihood_sigmas_m(self, altitude_sigma_m: float) -> tuple[float, float]:
        """:attr:`measurement_sigmas_m` with the altitude sigma ``altitude_sigma_m``."""
        d, u = self.measurement_noise_distance_m, altitude_sigma_m
        if self.likelihood_r == "per-component":
            return d, u
        variance = max(d * d, u * u) if self.likelihood_r == "scalar-norm" else (d * d) * (d * d) * (u * u)
        return math.sqrt(variance), math.sqrt(variance)

    @property
    def initial_std_heading_rad(self) -> float:
        return math.radians(self.initial_std_heading_deg)

    @property
    def initial_std_gyro_bias_rad_s(self) -> float:
        return self.initial_std_gyro_bias_deg_h * DEG_PER_H


class FaultSpec(_Strict):
    """Everyday faults of the world (docs/model.md, Section 4.1); all off in the paper's world."""

    tide_bias_m: float = Field(0.0, ge=-100, le=100,
                               description="constant error of the depth reference (tide, datum), m")
    tide_amplitude_m: float = Field(0.0, ge=0, le=20, description="amplitude of the slow sinusoidal tide, m")
    tide_period_s: float = Field(44712.0, gt=0, description="tide period (M2: 12.42 h)")
    current_east_mps: float = Field(0.0, ge=-3, le=3, description="ocean current, east component, m/s")
    current_north_mps: float = Field(0.0, ge=-3, le=3, description="ocean current, north component, m/s")
    dropout_rate_per_ping: float = Field(0.0, ge=0, lt=1, description="chance a bottom-lock dropout starts")
    dropout_mean_pings: float = Field(10.0, ge=1, description="mean length of a dropout, pings")
    outlier_fraction: float = Field(0.0, ge=0, lt=1, description="fraction of wild ranges")
    sound_speed_scale_error: float = Field(0.0, gt=-0.2, lt=0.2, description="range scale error")
    # the check's mutation faults (issue 22; docs/model.md, Section 4.1): off, they change no key and no number
    map_offset_east_m: float = new_option(0.0, ge=-500, le=500,
                                          description="the seafloor lies this far east of where the map has it, m")
    map_offset_north_m: float = new_option(0.0, ge=-500, le=500,
                                           description="the seafloor lies this far north of where the map has it, m")
    sonar_latency_pings: int = new_option(0, ge=0, le=100,
                                          description="ranges reported this many pings late (the first pings: none)")
    range_noise_scale: float = new_option(1.0, gt=0, le=100,
                                          description="true range noise / the noise the methods assume (noise_m)")
    far_start_fraction: float = new_option(0.0, ge=0, le=1,
                                           description="fraction of runs whose navigation starts far off")
    far_start_m: float = new_option(300.0, ge=0, le=5000,
                                    description="how far off those runs start (random direction), m")


class Scenario(_Strict):
    """One Monte Carlo cell: everything but the method and the run index."""

    terrain: TerrainSpec = TerrainSpec()
    area: Literal["A", "B", "vehicle", "custom"] = "A"
    map_resolution_m: float = Field(10.0, gt=0)
    noise_m: float = Field(1.0, ge=0, description="half-width of the uniform range noise")
    sampling_time_s: float = Field(1.0, gt=0)
    particles: int = Field(3000, gt=0, le=1_000_000)
    duration_s: float | None = Field(None, gt=0, description="cut the run short (default: whole plan)")
    trajectory: TrajectorySpec = TrajectorySpec()
    sensors: SensorSpec = SensorSpec()
    navigation: NavigationSpec = NavigationSpec()
    filter: FilterSpec = FilterSpec()
    method_options: dict[str, dict[str, Any]] = new_option(
        {}, description="per method: its own options (see `tanbench methods`), e.g. {pmf-dvl: {grid_m: 5}}")
    faults: FaultSpec = new_option(FaultSpec(), neutral=FaultSpec().model_dump(mode="json"),
                                   description="everyday faults of the world; all off by default")

    @model_validator(mode="after")
    def _resolve_area(self):
        facts = scenario_facts()
        vehicle = self.area == "vehicle"
        object.__setattr__(self, "terrain", self.terrain.resolved(self.area))
        traj = self.trajectory
        if traj.kind == "auto":
            kind = "vehicle-run" if vehicle else ("survey" if self.area == "custom" else "paper")
            traj = traj.model_copy(update={"kind": kind})
        if traj.start_enu_m is None and traj.kind != "survey":
            if vehicle:
                start = tuple(facts["vehicle_test"]["start_enu_m"]) + (0.0,)
            elif self.area in ("A", "B"):
                start = tuple(facts["areas"][self.area]["start_enu_m"])
            else:
                raise ValueError("area 'custom' with a paper trajectory needs trajectory.start_enu_m")
            traj = traj.model_copy(update={"start_enu_m": tuple(float(x) for x in start)})
        if traj.kind == "survey" and traj.centre_en_m is None:
            raise ValueError("a survey trajectory needs trajectory.centre_en_m")
        object.__setattr__(self, "trajectory", traj)
        object.__setattr__(self, "sensors", self.sensors.resolved("table8" if vehicle else "table1"))
        nav = self.navigation
        updates = {}
        if nav.initial_heading_error_deg is None:
            updates["initial_heading_error_deg"] = 3.0 if vehicle else float(
                facts["sensors"]["initial_heading_error_deg"])
        if nav.initial_position_error_m is None:
            updates["initial_position_error_m"] = 2 * 10.0 if vehicle else float(
                facts["trajectory"]["initial_horizontal_error_area_m"][0])
        if updates:
            object.__setattr__(self, "navigation", nav.model_copy(update=updates))
        ping = 1.0 / self.sensors.sonar_rate_hz
        steps = self.sampling_time_s / ping
        if abs(steps - round(steps)) > 1e-6 or round(steps) < 1:
            raise ValueError(
                f"sampling_time_s ({self.sampling_time_s:g}) must be a whole number of sonar pings "
                f"({ping:g} s at sensors.sonar_rate_hz={self.sensors.sonar_rate_hz:g})")
        if self.duration_s is not None and self.duration_s < ping - 1e-9:
            raise ValueError(
                f"duration_s ({self.duration_s:g} s) is shorter than one sonar ping ({ping:g} s at "
                f"sensors.sonar_rate_hz={self.sensors.sonar_rate_hz:g})")
        if self.map_resolution_m < (self.terrain.truth_resolution_m if self.terrain.kind == "synthetic" else 0):
            raise ValueError(
                f"map_resolution_m ({self.map_resolution_m:g}) is finer than the truth grid "
                f"({self.terrain.truth_resolution_m:g} m)")
        if self.filter.range_noise == "data-sheet" and self.noise_m <= 0:
            raise ValueError("filter.range_noise: data-sheet takes the likelihood's range noise from noise_m, "
                             "which is 0 here: use filter.range_noise: table-2")
        return self

    # ---- derived quantities (computed here once for every method and the bound) --
    @property
    def range_sigma_m(self) -> float:
        """Every method's range (altitude) noise std: Table 2's ``filter.measurement_noise_altitude_m``, or with
        ``filter.range_noise: data-sheet`` the sonar's own, noise_m / sqrt(3) (uniform of half-width noise_m)."""
        f = self.filter
        return self.noise_m / math.sqrt(3.0) if f.range_noise == "data-sheet" else f.measurement_noise_altitude_m

    @property
    def measurement_sigmas_m(self) -> tuple[float, float]:
        """(distance, altitude) sigmas of the particle filters' likelihood (``filter.likelihood_r``,
        ``filter.range_noise``)."""
        return self.filter.likelihood_sigmas_m(self.range_sigma_m)

    def position_noise_m(self, distance_sigma_m: float | None = None) -> float:
        """East/north process noise std per filter update (Table 2's q over the sampling time,
        combined with the distance noise, by default ``filter.measurement_noise_distance_m``)."""
        f = self.filter
        r = f.measurement_noise_distance_m if distance_sigma_m is None else distance_sigma_m
        return position_noise(self.position_step_m, r, DISTANCE_INNOVATION[f.distance_innovation])

    @property
    def position_step_m(self) -> float:
        """Table 2's east/north process noise over one filter update: ``process_noise_velocity_mps`` times the
        sampling time (``filter.position_noise_growth: linear``) or its square root (``sqrt``)."""
        f, T = self.filter, self.sampling_time_s
        return f.process_noise_velocity_mps * (math.sqrt(T) if f.position_noise_growth == "sqrt" else T)

    @property
    def attitude_noise_rad(self) -> float:
        """Attitude process noise std per filter update (rad)."""
        return self.filter.process_noise_attitude_deg_sqrt_h * DEG_PER_SQRT_H * math.sqrt(self.sampling_time_s)

    @property
    def planned_duration_s(self) -> float:
        """The run's length for cost estimates: ``duration_s``, else the paper's 1190 s run."""
        return self.duration_s or PAPER_RUN_S

    # ---- keys -------------------------------------------------------------------
    def normalized(self) -> dict:
        """The fully resolved spec as plain JSON-able data (every option, neutral ones included)."""
        return json.loads(self.model_dump_json())

    def world_spec(self) -> dict:
        """What defines the simulated vehicle data of a run (not the filter's settings)."""
        d = self.normalized()
        return {k: d[k] for k in WORLD_SECTIONS}

    def identity(self) -> dict:
        """What a cell key hashes: the resolved spec without options at their neutral value."""
        d = _without_neutral(type(self), self.normalized())
        if MODEL_VERSION > 1:
            d["model_version"] = MODEL_VERSION
        return d

    def world_key(self) -> str:
        d = self.identity()
        return stable_hash({k: d[k] for k in (*WORLD_SECTIONS, "model_version") if k in d})

    def pairing_key(self) -> str:
        """The world key without the world faults: what seeds a run's vehicle data, so a cell
        with a fault switched on shares its random numbers (sensor noise, initial errors)
        with the fault-free cell, and the fault's effect is measured on paired runs (so do
        cells that differ only in the multibeam's settings). Equal to :meth:`world_key`
        without faults and multibeam."""
        d = self.identity()
        d.pop("faults", None)
        d["terrain"] = {k: v for k, v in d["terrain"].items() if k != "map_error_correlation_m"}
        # the multibeam draws from streams of its own: cells that differ only in its settings share the rest
        d["sensors"] = {k: v for k, v in d["sensors"].items() if not k.startswith("multibeam_")}
        return stable_hash({k: d[k] for k in (*WORLD_SECTIONS, "model_version") if k in d})

    def cell_key(self) -> str:
        return stable_hash(self.identity())


PAPER_RUN_S = 1190.0  # the paper's run (Section 4.2), what a cost estimate assumes without duration_s
WORLD_SECTIONS = ("terrain", "area", "trajectory", "sensors", "navigation", "duration_s", "faults")


def _without_neutral(model: type[BaseModel], data: dict) -> dict:
    """``data`` (a model's JSON dump) less every :func:`new_option` field at its neutral value."""
    out = {}
    for name, value in data.items():
        info = model.model_fields.get(name)
        extra = info.json_schema_extra if info is not None and isinstance(info.json_schema_extra, dict) else {}
        if "key_neutral" in extra and value == extra["key_neutral"]:
            continue
        ann = info.annotation if info is not None else None
        if isinstance(ann, type) and issubclass(ann, BaseModel) and isinstance(value, dict):
            value = _without_neutral(ann, value)
        out[name] = value
    return out


def stable_hash(data) -> str:
    """A short, stable hex digest of JSON-able data (sorted keys)."""
    blob = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
    return hashlib.sha256(blob).hexdigest()[:16]


def flatten(d: dict, prefix: str = "") -> dict:
    """{'a': {'b': 1}} -> {'a.b': 1}; lists and tuples stay values."""
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, key + "."))
        else:
            out[key] = v
    return out
