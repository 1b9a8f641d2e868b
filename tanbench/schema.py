"""The columns of tanbench's results: per-run metrics, per-update series, run-file types.

One place for every result column name and Arrow type, read by the scoring, the task
runner, the store, the tables and the regression check.
"""

from __future__ import annotations

import json
import math
import types
import typing
from functools import lru_cache

import pyarrow as pa
from pydantic import BaseModel

from tanbench.config import Scenario
from tanbench.metrics.declarations import METRICS

# per-run metric names, in the order results tables show them (declared in metrics.declarations)
METRIC_COLUMNS = tuple(m.name for m in METRICS)

# the per-update series stored for every run (float32): the scored ones every method has
SERIES_COLUMNS = (
    "t", "est_e", "est_n", "est_u", "est_heading_deg", "truth_e", "truth_n", "truth_u",
    "truth_heading_deg", "nav_e", "nav_n", "nav_heading_deg", "east_error_m", "north_error_m",
    "horizontal_error_m", "heading_error_deg", "nav_horizontal_error_m", "ess", "var_e", "var_n",
    "cov_en", "nees", "pcrb_horizontal_m", "pcrb_heading_deg",
)

# Arrow types of a run row's columns. They are fixed (the scenario parameters' from the
# Scenario model's annotations), so every run file has the same schema whatever its
# values (a failed run's missing metrics, a parameter left at None) and
# ``pd.read_parquet(DIR / "runs")`` can read them together. Metric types are declared with the metrics.
# (``cell_id`` is not among them: it is the Hive partition, in the directory name)
ID_TYPES = {"sweep": pa.string(), "tables": pa.string(), "method": pa.string(),
            "run": pa.int64(), "seed": pa.int64(), "filter_seed": pa.int64()}
METRIC_TYPES = {m.name: m.arrow for m in METRICS}
TAIL_TYPES = {"status": pa.string(), "error": pa.string(), "wall_s": pa.float64()}


def _arrow_type(annotation) -> pa.DataType:
    """bool, int64, float64, or string (plain for str, JSON text for tuples and mixed types)."""
    union = typing.get_origin(annotation) in (typing.Union, types.UnionType)
    kinds = set()
    for arg in typing.get_args(annotation) if union else (annotation,):
        if arg is type(None):
            continue
        if arg is bool:
            kinds.add("bool")
        elif arg is int:
            kinds.add("int")
        elif arg is float:
            kinds.add("float")
        elif arg is str or typing.get_origin(arg) is typing.Literal:
            kinds.add("str")
        else:
            kinds.add("json")
    if kinds == {"bool"}:
        return pa.bool_()
    if kinds == {"int"}:
        return pa.int64()
    if kinds and kinds <= {"int", "float"}:
        return pa.float64()
    return pa.string()


@lru_cache(maxsize=1)
def scenario_column_types() -> dict[str, pa.DataType]:
    """Every flattened scenario parameter (``filter.resampling``) and its Arrow type, in model order."""
    def walk(model, prefix):
        out = {}
        for name, info in model.model_fields.items():
            ann = info.annotation
            if typing.get_origin(ann) is dict:  # mappings (method_options) flatten to dotted columns
                continue
            if isinstance(ann, type) and issubclass(ann, BaseModel):
                out.update(walk(ann, f"{prefix}{name}."))
            else:
                out[f"{prefix}{name}"] = _arrow_type(ann)
        return out

    return walk(Scenario, "")


def run_schema(rows: list[dict]) -> pa.Schema:
    """The schema of a run file: the known columns in a fixed order, then any other (inferred)."""
    metrics = {m: METRIC_TYPES.get(m, pa.float64()) for m in METRIC_COLUMNS}
    known = {**ID_TYPES, **scenario_column_types(), **metrics, **TAIL_TYPES}
    fields = [pa.field(k, t) for k, t in known.items()]
    for k in dict.fromkeys(k for row in rows for k in row):
        if k not in known:
            inferred = pa.array([row.get(k) for row in rows], from_pandas=True).type
            fields.append(pa.field(k, pa.float64() if pa.types.is_null(inferred) else inferred))
    return pa.schema(fields)


def _coerce(value, typ: pa.DataType):
    """A row value as the column's type takes it: NaN is null outside float columns, JSON for lists."""
    if value is None or (isinstance(value, float) and math.isnan(value) and not pa.types.is_floating(typ)):
        return None
    if pa.types.is_string(typ) and not isinstance(value, str):
        return json.dumps(value)
    return value


def rows_table(rows: list[dict]) -> pa.Table:
    """Run rows as an Arrow table of the fixed run-file schema."""
    schema = run_schema(rows)
    data = {}
    for f in schema:
        values = [row.get(f.name) for row in rows]
        if not pa.types.is_floating(f.type):  # a float column takes every value as it is (_coerce's identity)
            values = [_coerce(value, f.type) for value in values]
        data[f.name] = values
    return pa.Table.from_pydict(data, schema=schema)


# every column of a run row that is not a scenario parameter
RESULT_COLUMNS = frozenset({"cell_id", *ID_TYPES, *METRIC_COLUMNS, *TAIL_TYPES})
