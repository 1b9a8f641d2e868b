"""What a TAN method is given and what it returns: the plug-in contract.

A method is a function ``run(ctx: MethodContext) -> MethodOutput`` (or a dict with the
same keys). It is given what a real vehicle would have, and nothing else:

* ``ctx.scenario``: the cell's settings (filter, sensors, particles, sampling time,
  range noise, ``method_options``), with the world-only sections withheld
  (``terrain``, ``trajectory`` and ``navigation`` are ``None``: here the planned path
  is the true path, and the navigation section holds the true initial errors);
* ``ctx.obs``: the sensors' outputs and the navigation system's solution
  (:class:`tanbench.simulation.Observations`);
* ``ctx.nmap``: the navigation map (:class:`tanbench.terrain.grid.Map`), never the truth;
* ``ctx.updates``: the sonar pings the method is to use (one every sampling time), their
  IMU sample indices and times;
* ``ctx.rng``: the method's own seeded ``numpy.random.Generator``;
* ``ctx.options``: its own validated options (the record's ``options`` model), or None.

Every array it is given (observations, navigation solution, map, updates) is read-only:
a method that writes into one gets an error naming it (copy an array to change it), and
each method gets its own copies of the objects that hold them, so no method can change
what another method, or a later run in the same worker, is given.

It returns one estimate per update (:class:`MethodOutput`). tanbench scores it against
the truth, stores, tabulates, plots and checks it like any built-in method.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field, fields

import numpy as np

from tanbench.arrays import read_only
from tanbench.config import Scenario
from tanbench.errors import TanbenchError, describe_exception
from tanbench.simulation import NavSolution, Observations, motion_plan
from tanbench.terrain.grid import Map


@dataclass(frozen=True)
class Updates:
    """The updates of a run: sonar ping rows, their IMU sample indices and times (s)."""

    rows: np.ndarray
    imu: np.ndarray
    t: np.ndarray

    @property
    def size(self) -> int:
        return int(self.rows.size)


@dataclass(frozen=True)
class MethodContext:
    """Everything a method is given for one run (see the module docstring)."""

    name: str
    scenario: Scenario
    obs: Observations
    nmap: Map
    updates: Updates
    rng: np.random.Generator
    options: object = None  # an instance of the record's own options model (any pydantic model), or None

    @property
    def nav(self) -> NavSolution:
        """The navigation system's solution at every IMU sample (``obs.nav``)."""
        return self.obs.nav

    def increments(self) -> np.ndarray:
        """The navigation solution's increments between the updates (K - 1, 12)
        (:func:`tanbench.navigation.increments.compute_increments`): computed once per run for
        all its methods, a copy of this method's own."""
        return self.obs.shared_increments.table(self.obs.dt, self.obs.nav, self.updates.imu)


@dataclass
class MethodOutput:
    """A method's estimates, one value per update (arrays of shape ``(K,)``).

    Required: ``east`` and ``north`` (m, the map's local frame). Optional: ``up`` (m),
    the heading as ``heading_deg`` (compass degrees, clockwise from north) or ``yaw``
    (rad, counter-clockwise from north, as the filters carry it); the variances
    ``var_e``, ``var_n``, ``var_u`` (m^2), the east-north covariance ``cov_en`` and
    ``var_heading`` (deg^2); the effective sample size ``ess``; ``reinit`` (True where
    the method re-initialised); ``extra``: further named series of shape ``(K,)``.
    Missing up and heading are the navigation system's.
    """

    east: np.ndarray
    north: np.ndarray
    up: np.ndarray | None = None
    heading_deg: np.ndarray | None = None
    yaw: np.ndarray | None = None
    var_e: np.ndarray | None = None
    var_n: np.ndarray | None = None
    cov_en: np.ndarray | None = None
    var_u: np.ndarray | None = None
    var_heading: np.ndarray | None = None
    ess: np.ndarray | None = None
    reinit: np.ndarray | None = None
    extra: dict = field(default_factory=dict)


OUTPUT_FIELDS = tuple(f.name for f in fields(MethodOutput))
_NON_NEGATIVE = ("var_e", "var_n", "var_u", "var_heading", "ess")


def as_output(name: str, value, k: int) -> MethodOutput:
    """Check a method's return value and give it as a :class:`MethodOutput`.

    Every problem is one :class:`TanbenchError` line naming the method and the field:
    a wrong type, an unknown key, a wrong shape, a value that is not a real number (complex,
    text) or not finite, a negative variance, a reinit flag other than 0 or 1.
    """
    label = f"method {name!r}"
    if isinstance(value, dict):
        unknown = sorted(set(value) - set(OUTPUT_FIELDS))
        if unknown:
            raise TanbenchError(f"{label} returned unknown key(s) {', '.join(map(repr, unknown))}; "
                                f"known: {', '.join(OUTPUT_FIELDS)}")
        missing = [key for key in ("east", "north") if key not in value]
        if missing:
            raise TanbenchError(f"{label} returned no {' and no '.join(missing)}")
        value = MethodOutput(**value)
    if not isinstance(value, MethodOutput):
        raise TanbenchError(f"{label} returned {type(value).__name__}; expected a MethodOutput or a dict "
                            f"with east and north")
    arrays = {}
    for key in OUTPUT_FIELDS:
        if key == "extra":
            continue
        arrays[key] = _series(label, key, getattr(value, key), k, required=key in ("east", "north"))
    if not isinstance(value.extra, dict):
        raise TanbenchError(f"{label}: extra must be a dict of named series, got {type(value.extra).__name__}")
    extra = {}
    for key, arr in value.extra.items():
        if not isinstance(key, str) or not key.isidentifier():
            raise TanbenchError(f"{label}: extra series name {key!r} is not a plain identifier")
        if key in SCORED_SERIES:
            raise TanbenchError(f"{label}: extra series {key!r} clashes with a series tanbench computes")
        extra[key] = _series(label, f"extra[{key!r}]", arr, k, required=True, allow_nan=True)
    if arrays["heading_deg"] is not None and arrays["yaw"] is not None:
        raise TanbenchError(f"{label} returned both heading_deg and yaw; give one")
    for key in _NON_NEGATIVE:
        if arrays[key] is not None and (arrays[key] < 0).any():
            raise TanbenchError(f"{label}: {key} has negative values (first at update "
                                f"{int(np.argmax(arrays[key] < 0))})")
    if arrays["reinit"] is not None:
        flags = (arrays["reinit"] == 0) | (arrays["reinit"] == 1)
        if not flags.all():
            bad = int(np.argmax(~flags))
            raise TanbenchError(f"{label}: reinit holds flags, 0 or 1 (or booleans), not "
                                f"{float(arrays['reinit'][bad])!r} (update {bad})")
        arrays["reinit"] = arrays["reinit"] != 0
    return MethodOutput(**arrays, extra=extra)


def _series(label, key, arr, k, required, allow_nan=False):
    if arr is None:
        if required:
            raise TanbenchError(f"{label} returned no {key}")
        return None
    raw = np.asarray(arr)
    if raw.dtype.kind not in "biufO":  # complex, text, dates: never silently made real numbers
        raise TanbenchError(f"{label}: {key} is not real numbers (dtype {raw.dtype})")
    try:
        out = np.array(raw, dtype=np.float64)
    except (TypeError, ValueError):
        raise TanbenchError(f"{label}: {key} is not numeric ({type(arr).__name__})") from None
    if out.shape != (k,):
        raise TanbenchError(f"{label}: {key} has shape {out.shape}, expected ({k},) (one value per update)")
    if not allow_nan and not np.isfinite(out).all():
        bad = int(np.argmax(~np.isfinite(out)))
        raise TanbenchError(f"{label}: {key} is not finite at update {bad} (t index {bad}: {out[bad]!r})")
    return out


# series the scoring computes from a method's output and the truth (extra names may not clash)
SCORED_SERIES = frozenset({
    "t", "est_e", "est_n", "est_u", "est_heading_deg", "truth_e", "truth_n", "truth_u", "truth_heading_deg",
    "nav_e", "nav_n", "nav_heading_deg", "east_error_m", "north_error_m", "horizontal_error_m",
    "heading_error_deg", "nav_horizontal_error_m", "ess", "reinit", "var_e", "var_n", "cov_en", "var_u",
    "var_heading",
})


def update_indices(scenario: Scenario, obs: Observations) -> Updates:
    """The updates of a run for the scenario's sampling time (every ``T * sonar rate``-th ping), read-only."""
    step = int(round(scenario.sampling_time_s * scenario.sensors.sonar_rate_hz))
    rows = np.arange(0, obs.ping_idx.size, step)
    imu = obs.ping_idx[rows]
    return Updates(rows=read_only(rows), imu=read_only(imu), t=read_only(obs.t[imu]))


def method_view(scenario: Scenario) -> Scenario:
    """The scenario as a method sees it: the world-only sections withheld (None); its own copy."""
    return scenario.model_copy(update={"terrain": None, "trajectory": None, "navigation": None, "faults": None},
                               deep=True)


def _read_only_fields(obj):
    """A shallow copy of a dataclass instance whose array fields are read-only views."""
    values = {f.name: getattr(obj, f.name) for f in fields(obj)}
    return dataclasses.replace(obj, **{k: read_only(v) for k, v in values.items() if isinstance(v, np.ndarray)})


# what a method may read of the navigation map's metadata: what a vehicle's own map carries (its
# node spacing, its declared level error, its georeference). The rest says how the world was built
# (a synthetic terrain's layout and seed, the path of the truth's file, how it was resampled and
# rescaled, the map's name): enough to rebuild the true terrain, so it is withheld.
NAVIGATION_MAP_META = ("resolution_m", "map_error_m", "crs", "m_per_deg_lon", "m_per_deg_lat", "lon0", "lat0",
                       "projection_error_m")
NAVIGATION_MAP_NAME = "navigation map"


def method_inputs(obs: Observations, nmap: Map) -> tuple[Observations, Map]:
    """What one method is given of a run's observations and of the navigation map: its own
    copies of the objects, whose arrays are read-only views of the run's (no data is copied); of
    the map's metadata only :data:`NAVIGATION_MAP_META`, under a neutral name."""
    own_obs = dataclasses.replace(_read_only_fields(obs), nav=_read_only_fields(obs.nav))
    meta = {k: copy.deepcopy(v) for k, v in nmap.meta.items() if k in NAVIGATION_MAP_META}
    return own_obs, dataclasses.replace(nmap, z=read_only(nmap.z), name=NAVIGATION_MAP_NAME, meta=meta)


READ_ONLY_WORDS = ("read-only", "readonly", "WRITEABLE")


def input_write_error(name: str, exc: BaseException) -> TanbenchError | None:
    """The one-line error of a method that wrote into its read-only inputs (None for another error)."""
    if not any(word in str(exc) for word in READ_ONLY_WORDS):
        return None
    return TanbenchError(f"method {name!r} tried to write into its inputs ({describe_exception(exc)}): "
                         f"what a method is given is read-only; copy an array (numpy.array(x)) to change it")


def check_start_on_map(scenario: Scenario, nmap: Map) -> None:
    """Refuse a start whose initial uncertainty could leave the navigation map.

    The worst case: the navigation system's start is off the true start by up to half
    the initial position error on each axis, and the filter's initial square of side
    ``filter.initial_area_m`` is centred on it.
    """
    start = motion_plan(scenario).start_enu
    reach = scenario.navigation.initial_position_error_m / 2.0 + scenario.filter.initial_area_m / 2.0
    e = np.array([start[0] - reach, start[0] + reach])
    n = np.array([start[1] - reach, start[1] + reach])
    if not nmap.contains(e[[0, 1, 0, 1]], n[[0, 0, 1, 1]]).all():
        raise TanbenchError(
            f"the initial uncertainty (up to {reach:.0f} m around the start ({start[0]:.0f}, {start[1]:.0f}) m: "
            f"navigation.initial_position_error_m / 2 + filter.initial_area_m / 2) leaves the navigation map "
            f"(E {nmap.e0:.0f}..{nmap.e_max:.0f}, N {nmap.n0:.0f}..{nmap.n_max:.0f} m); move the start or "
            f"shrink the initial uncertainty")


def heading_to_yaw(heading_deg: np.ndarray) -> np.ndarray:
    """Compass heading (deg, clockwise from north) to the filters' yaw (rad, counter-clockwise)."""
    return -np.radians(heading_deg)
