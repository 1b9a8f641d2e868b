"""Sweep files: loading, validation with one clear error line, and expansion into cells.

A sweep names a root seed, a number of Monte Carlo runs per cell, the methods, the
scenario defaults shared by every cell, and designs that vary them:

* ``tables``: one design per table, each a mapping ``parameter -> list of values``;
  the values of one table's parameters are combined (a product), so a table that
  varies one parameter is the paper's one-factor-at-a-time design and single-valued
  entries act as fixed overrides (e.g. ``{area: [B]}``);
* ``grid``: a full factorial over its parameters.

Parameters are scenario keys, nested ones with dots (``filter.resampling``,
``sensors.gyro_arw_deg_sqrt_h``). A cell is a fully resolved :class:`Scenario`;
identical cells reached from several tables run once and remember every table they
belong to.

This is the sweep's specification, beside the scenario's (:mod:`tanbench.config`); what
needs the methods or the worlds (method names and options, maps, tracks, sensors) is
checked by :mod:`tanbench.runner.validate`, ``run``'s first step.
"""

from __future__ import annotations

import copy
import itertools
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator

from tanbench.config import Scenario, flatten, format_validation_error, plain_number_check
from tanbench.errors import TanbenchError
from tanbench.options import MAX_SEED
from tanbench.profiles import PROFILES, profile_settings

Value = Any
DEFAULT_METHODS = ("tight-dvl", "tight-sbe", "loose-dvl")  # the paper's, when a sweep names none


# a name that becomes a file or directory name (results/<sweep>, tables/<table>.parquet):
# letters, digits, '_', '-' and '.', not starting with '.' (no '', '.', '..', hidden files or '/')
PATH_NAME = r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$"
PATH_NAME_RULE = "letters, digits, '_', '-' and '.', not starting with '.'"
# file systems allow 255 bytes per name; a table's file is written as '.<name>.parquet.<pid>.tmp' first
MAX_NAME_LENGTH = 200
MAX_SWEEP_BYTES = 1_000_000  # a sweep file is a page of YAML; this is far above any real one
MAX_YAML_VALUES = 100_000  # values of the YAML once its aliases are expanded (an alias bomb has billions)


def check_path_name(name, what: str) -> str:
    """``name`` if it is safe as one file name component, else a ValueError naming the rule."""
    if not isinstance(name, str) or re.fullmatch(PATH_NAME, name) is None:
        raise ValueError(f"{what} {name!r} cannot be used as a file name (use {PATH_NAME_RULE})")
    if len(name) > MAX_NAME_LENGTH:
        raise ValueError(f"{what} {name[:20]!r}... is {len(name)} characters long; it becomes a file name, "
                         f"which may have at most {MAX_NAME_LENGTH}")
    return name


class SweepSpec(BaseModel):
    """The top level of a sweep file."""

    model_config = ConfigDict(extra="forbid")

    name: str
    description: str = ""
    seed: int = Field(ge=0, le=MAX_SEED)
    runs: int = Field(gt=0, le=100_000)
    methods: list[str] = Field(default_factory=lambda: list(DEFAULT_METHODS), min_length=1)
    profile: str | None = Field(None, description="a named set of settings (tanbench.profiles) under `scenario`")
    scenario: dict[str, Any] = Field(default_factory=dict)
    tables: dict[str, dict[str, list[Value]]] = Field(default_factory=dict)
    grid: dict[str, list[Value]] | None = None
    table_columns: list[Literal["divergence_rate", "mean_filter_wall_s"]] = Field(
        default_factory=list, description="extra columns of this sweep's summary tables")

    @field_validator("*", mode="before")
    @classmethod
    def _plain_numbers(cls, value, info: ValidationInfo):
        return plain_number_check(cls, value, info.field_name)

    @field_validator("name")
    @classmethod
    def _name_is_a_path_name(cls, v):
        return check_path_name(v, "sweep name")

    @field_validator("tables")
    @classmethod
    def _table_names_are_path_names(cls, v):
        for table in v:
            check_path_name(table, "table name")
            if table == "grid":
                raise ValueError("table name 'grid' is taken by the grid design's table")
        return v

    @field_validator("profile")
    @classmethod
    def _known_profile(cls, v):
        if v is not None and v not in PROFILES:
            raise ValueError(f"unknown profile {v!r} (known: {', '.join(PROFILES)})")
        return v

    @field_validator("methods")
    @classmethod
    def _methods_once(cls, v):
        # whether each names a method is checked with the registry (tanbench.runner.validate)
        if len(set(v)) != len(v):
            raise ValueError("a method is listed twice")
        return v


@dataclass
class Cell:
    """One resolved scenario, the tables it belongs to and the values they vary."""

    scenario: Scenario
    tables: list[str] = field(default_factory=list)
    varied: dict[str, Value] = field(default_factory=dict)

    _key: tuple | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def cell_id(self) -> str:
        """The scenario's cell key, hashed once per scenario (a frozen model): plan, run and
        the tables ask for it several times per cell (3 ms each)."""
        if self._key is None or self._key[0] is not self.scenario:
            self._key = (self.scenario, self.scenario.cell_key())
        return self._key[1]


@dataclass
class Sweep:
    """A validated sweep: its spec, the raw YAML text, and its cells in file order."""

    spec: SweepSpec
    text: str
    path: Path | None
    cells: list[Cell]
    table_designs: dict[str, dict[str, list]]  # per table: its varied parameters and their values, in file order

    @property
    def name(self) -> str:
        return self.spec.name

    def with_runs(self, runs: int) -> "Sweep":
        spec = self.spec.model_copy(update={"runs": runs})
        return Sweep(spec, self.text, self.path, self.cells, self.table_designs)


def load_sweep(path) -> Sweep:
    """Read and validate a sweep file; any problem is one ``TanbenchError`` line."""
    path = Path(path)
    try:
        if path.exists() and not path.is_dir() and not path.is_file():  # a FIFO would block the read
            raise TanbenchError(f"{path}: not a regular file (a FIFO, device or socket); give a sweep YAML file")
        if path.is_file() and path.stat().st_size > MAX_SWEEP_BYTES:
            raise TanbenchError(f"{path}: {path.stat().st_size} bytes is too large for a sweep file "
                                f"(at most {MAX_SWEEP_BYTES})")
        text = path.read_text()
    except FileNotFoundError:
        raise TanbenchError(f"{path}: no such sweep file") from None
    except (IsADirectoryError, PermissionError, UnicodeDecodeError) as exc:
        raise TanbenchError(f"{path}: cannot read the sweep file ({exc.__class__.__name__})") from None
    except OSError as exc:
        raise TanbenchError(f"{path}: cannot read the sweep file ({exc.strerror or exc})") from None
    return parse_sweep(text, str(path), path)


def load_results_sweep(directory) -> Sweep:
    """The sweep a results directory was written by (its copy in ``DIR/sweep.yaml``)."""
    path = Path(directory) / "sweep.yaml"
    if not path.exists():
        raise TanbenchError(f"{directory}: no sweep.yaml (not a tanbench results directory?)")
    return load_sweep(path)


class UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key given twice in one mapping (YAML would keep the last)."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.setdefault(key, key_node.start_mark.line)
                except TypeError:  # an unhashable key: the base class says so
                    continue
                if first != key_node.start_mark.line:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"duplicate key {key!r} (first given at line {first + 1})",
                        key_node.start_mark)
        return super().construct_mapping(node, deep=deep)


def parse_sweep(text: str, label: str = "<sweep>", path: Path | None = None) -> Sweep:
    """Validate sweep YAML ``text``; ``label`` names it in error messages."""
    try:
        data = yaml.load(text, Loader=UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise TanbenchError(f"{label}: malformed YAML{where}: {problem}") from None
    except RecursionError:
        raise TanbenchError(f"{label}: the YAML is nested too deeply to be a sweep file") from None
    if not isinstance(data, dict):
        raise TanbenchError(f"{label}: a sweep file must be a mapping of keys (name, seed, runs, ...)")
    values = expanded_size(data)
    if values > MAX_YAML_VALUES:
        raise TanbenchError(f"{label}: the YAML's aliases (*name) expand to {_count(values)} values, more than "
                            f"a sweep file can hold ({MAX_YAML_VALUES}); an alias bomb?")
    try:
        spec = SweepSpec(**data)
    except ValidationError as exc:
        raise TanbenchError(f"{label}: {format_validation_error(exc)}") from None
    except TypeError as exc:
        raise TanbenchError(f"{label}: {exc}") from None
    cells, table_designs = expand(spec, label)
    return Sweep(spec=spec, text=text, path=path, cells=cells, table_designs=table_designs)


def _count(n: int) -> str:
    return f"{n:,}" if n < 10 ** 15 else f"about 10^{len(str(n)) - 1}"


def expanded_size(data) -> int:
    """How many values ``data`` holds with every shared (aliased) node counted each time it is
    reached; a node that contains itself counts as unbounded. Linear in the distinct nodes."""
    sizes: dict[int, int] = {}
    stack: list[tuple[object, bool]] = [(data, False)]
    on_path: set[int] = set()
    while stack:
        node, children_done = stack.pop()
        if not isinstance(node, (dict, list)):
            continue
        key = id(node)
        items = list(node.keys()) + list(node.values()) if isinstance(node, dict) else node
        if children_done:
            on_path.discard(key)
            sizes[key] = 1 + sum(sizes.get(id(c), 1) for c in items)
            continue
        if key in sizes:
            continue
        if key in on_path:  # a recursive alias
            return MAX_YAML_VALUES + 1
        on_path.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in items if isinstance(c, (dict, list)))
    return sizes.get(id(data), 1)


def _set_dotted(d: dict, key: str, value) -> None:
    parts = key.split(".")
    for p in parts[:-1]:
        nxt = d.get(p)
        if not isinstance(nxt, dict):
            nxt = {}
            d[p] = nxt
        d = nxt
    d[parts[-1]] = value


def _merge(base: dict, top: dict) -> dict:
    """``base`` updated by ``top``, nested mappings merged key by key."""
    out = copy.deepcopy(base)
    for k, v in top.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def _get_dotted(d: dict, key: str):
    for p in key.split("."):
        if not isinstance(d, dict):
            return None
        d = d.get(p)
    return d


def _scenario(data: dict, label: str, where: str) -> Scenario:
    try:
        return Scenario(**data)
    except ValidationError as exc:
        if where.endswith("."):  # a key path: every problem's key under it
            raise TanbenchError(f"{label}: {format_validation_error(exc, where)}") from None
        raise TanbenchError(f"{label}: {where}{format_validation_error(exc)}") from None


def make_scenario(base: dict, overrides: dict, label: str, where: str) -> Scenario:
    """A validated Scenario from defaults plus dotted overrides; errors name the key.

    An override whose value is a mapping replaces that whole section of the defaults; if
    that drops a setting the defaults give (so that the cell differs from the section
    merged key by key), it is refused: the sweep file says it, and it would be ignored.
    """
    data = copy.deepcopy(base)
    for k, v in overrides.items():
        _set_dotted(data, k, v)
    scenario = _scenario(data, label, where)
    for k, v in overrides.items():
        given = _get_dotted(base, k)
        if not (isinstance(v, dict) and isinstance(given, dict)):
            continue
        merged = copy.deepcopy(data)
        _set_dotted(merged, k, _merge(given, v))
        if _scenario(merged, label, where).normalized() != scenario.normalized():
            dropped = sorted(set(flatten(given, f"{k}.")) - set(flatten(v, f"{k}.")))
            raise TanbenchError(
                f"{label}: {where}{k}: this mapping replaces the whole {k} section of the scenario and drops "
                f"{', '.join(dropped)}; give the changed settings with dots ({k}.<key>: [...]) or repeat "
                f"the dropped ones")
    return scenario


def expand(spec: SweepSpec, label: str) -> tuple[list[Cell], dict[str, list[str]]]:
    """Cells of every design, deduplicated by their normalised spec (cell key)."""
    designs: list[tuple[str, dict[str, list]]] = list(spec.tables.items())
    if spec.grid is not None:
        designs.append(("grid", spec.grid))
    if not designs:
        designs = [("default", {})]
    base: dict = {}
    for k, v in profile_settings(spec.profile).items():  # the profile, under the sweep's scenario
        _set_dotted(base, k, v)
    base = _merge(base, spec.scenario)
    make_scenario(base, {}, label, "scenario.")  # the defaults alone must be valid
    cells: dict[str, Cell] = {}
    table_designs: dict[str, dict[str, list]] = {}
    for table, design in designs:
        for key, values in design.items():
            if not values:
                raise TanbenchError(f"{label}: {table}.{key}: needs at least one value")
        keys = list(design)
        table_designs[table] = {k: v for k, v in design.items() if len(v) > 1} or dict(design)
        for combo in itertools.product(*(design[k] for k in keys)):
            overrides = dict(zip(keys, combo))
            where = f"{'tables.' if table != 'grid' else ''}{table}: "
            scenario = make_scenario(base, overrides, label, where)
            key = scenario.cell_key()
            cell = cells.setdefault(key, Cell(scenario=scenario))
            if table not in cell.tables:
                cell.tables.append(table)
            for k, v in overrides.items():
                cell.varied.setdefault(k, v)
    return list(cells.values()), table_designs
