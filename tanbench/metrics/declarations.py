"""Per-run metrics as declarations: one record per metric, read by every layer that uses it.

A :class:`Metric` says, in one place,

* ``name`` and ``arrow``: the run-file column and its Arrow type (:mod:`tanbench.schema`);
* ``compute``: how a run computes it from the scored run (:class:`RunScore`, built by
  :func:`tanbench.scoring.score`, which alone reads the truth);
* ``summary``: how a cell summarises it in the tables (:func:`tanbench.results.summarize`):
  ``"mean"`` (a ``mean_<name>`` column) or ``None`` (not a table column of its own);
* ``check``: whether and how ``tanbench check`` compares it (:mod:`tanbench.check`):
  ``"lost"`` (the per-run lost flag: lost-run rate, exact tests), ``"accuracy"`` (mean and
  90th percentile over the runs not lost, permutation tests against the margin) or ``None``;
  ``label`` names it in the check's output.

A new metric is one :class:`Metric` appended to :data:`METRICS` (and its test); scoring,
schema, tables and check pick it up. docs/results.md ("Metrics as declarations") lists
the files touched when ``lost_time_fraction`` was added this way.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import pyarrow as pa


@dataclass
class RunScore:
    """What scoring knows about one run of one method, for the metrics to read."""

    t: np.ndarray  # update times, s
    err_e: np.ndarray
    err_n: np.ndarray
    err_h: np.ndarray  # horizontal error at the updates, m
    heading_err: np.ndarray  # deg
    reinit: np.ndarray  # bool per update
    left_map: bool
    filter: Any  # the scenario's FilterSpec (thresholds)
    wall: float  # filter wall time, s
    conv_time: float  # s, NaN if never converged
    rmse: float  # after convergence, NaN if never converged
    recovery: tuple  # (recoveries, first reinit time, mean recovery time): scoring.recovery_stats
    extra: dict = field(default_factory=dict)  # the method's named extra series
    consistency: dict = field(default_factory=dict)  # metrics.run_metrics' NEES and bound metrics


@dataclass(frozen=True)
class Metric:
    """One per-run metric (see the module docstring)."""

    name: str
    arrow: pa.DataType
    compute: Callable[[RunScore], Any]
    description: str
    summary: str | None = None
    check: str | None = None
    label: str | None = None


def _f(x) -> float:
    return float(x)


METRICS: tuple[Metric, ...] = (
    Metric("final_horizontal_error_m", pa.float64(), lambda r: _f(r.err_h[-1]),
           "horizontal error at the last update (the paper's statistic), m", check="accuracy", label="final"),
    Metric("mean_horizontal_error_m", pa.float64(), lambda r: _f(r.err_h.mean()),
           "time-averaged horizontal error over the updates, m", check="accuracy", label="time-avg"),
    Metric("rmse_after_convergence_m", pa.float64(), lambda r: r.rmse,
           "RMS horizontal error from convergence on (NaN if never converged), m"),
    Metric("final_heading_error_deg", pa.float64(), lambda r: _f(abs(r.heading_err[-1])),
           "|heading error| at the last update, deg"),
    Metric("convergence_time_s", pa.float64(), lambda r: r.conv_time,
           "first time after which the error stays below filter.convergence_threshold_m, s"),
    Metric("diverged", pa.bool_(), lambda r: bool(r.err_h[-1] > r.filter.divergence_threshold_m),
           "lost run: final error above filter.divergence_threshold_m (docs/model.md, 6.5)",
           check="lost", label="lost"),
    Metric("reinitialisations", pa.int64(), lambda r: int(r.reinit.sum()), "divergences detected by the filter"),
    Metric("final_east_error_m", pa.float64(), lambda r: _f(r.err_e[-1]), "east error at the last update, m"),
    Metric("final_north_error_m", pa.float64(), lambda r: _f(r.err_n[-1]), "north error at the last update, m"),
    Metric("filter_wall_s", pa.float64(), lambda r: _f(r.wall), "the method's wall time on this run, s"),
    Metric("recoveries", pa.int64(), lambda r: r.recovery[0], "reinitialisations that recovered"),
    Metric("first_reinit_s", pa.float64(), lambda r: r.recovery[1], "time of the first reinitialisation, s"),
    Metric("mean_recovery_s", pa.float64(), lambda r: r.recovery[2], "mean time to recover, s"),
    Metric("left_map", pa.bool_(), lambda r: r.left_map, "an estimate left the navigation map"),
    Metric("fixes_accepted", pa.int64(), lambda r: int(np.sum(r.extra.get("fix_accepted", 0))),
           "loose TAN fixes accepted"),
    Metric("fixes_rejected", pa.int64(), lambda r: int(np.sum(r.extra.get("fix_rejected", 0))),
           "loose TAN fixes rejected"),
    # consistency and efficiency (metrics.consistency, metrics.run_metrics: computed together)
    Metric("nees_mean_after_convergence", pa.float64(), lambda r: r.consistency["nees_mean_after_convergence"],
           "mean NEES after convergence"),
    Metric("nees_above_95", pa.float64(), lambda r: r.consistency["nees_above_95"],
           "fraction of updates with NEES above its one-run 95 % bound"),
    Metric("nees_below_95", pa.float64(), lambda r: r.consistency["nees_below_95"],
           "fraction of updates with NEES below its one-run 95 % bound"),
    Metric("pcrb_after_convergence_m", pa.float64(), lambda r: r.consistency["pcrb_after_convergence_m"],
           "RMS of the cell's PCRB after the run's convergence, m"),
    Metric("rmse_pcrb_ratio", pa.float64(), lambda r: r.consistency["rmse_pcrb_ratio"],
           "RMSE after convergence / PCRB"),
    # the whole-run consistency verdict's inputs (metrics.consistency.whole_run_verdict, docs/model.md 9.2)
    Metric("nees_mean_whole_run", pa.float64(), lambda r: r.consistency["nees_mean_whole_run"],
           "mean NEES over every update of the run"),
    Metric("reported_std_below_bound", pa.float64(), lambda r: r.consistency["reported_std_below_bound"],
           "the method's reported horizontal std below the PCRB (metrics.consistency.reported_below_bound)"),
    # added as one declaration (issue 26): the share of the run spent lost
    Metric("lost_time_fraction", pa.float64(),
           lambda r: _f(np.mean(r.err_h > r.filter.divergence_threshold_m)),
           "fraction of the run's updates with horizontal error above filter.divergence_threshold_m",
           summary="mean"),
    # the second bound, beside the first (issue 24, docs/model.md 9.1): each beam's variance is the range
    # noise's plus the navigation map's declared error at its footprint; the counted ratio stays rmse_pcrb_ratio
    Metric("pcrb_map_after_convergence_m", pa.float64(), lambda r: r.consistency["pcrb_map_after_convergence_m"],
           "RMS after the run's convergence of the cell's second bound, the PCRB whose beams also carry the "
           "navigation map's declared error (representation and node error, docs/model.md 9.1), m; not the "
           "counted bound (pcrb_after_convergence_m)"),
    Metric("rmse_pcrb_map_ratio", pa.float64(), lambda r: r.consistency["rmse_pcrb_map_ratio"],
           "RMSE after convergence / the bound that includes the map's declared error "
           "(pcrb_map_after_convergence_m); the counted ratio is rmse_pcrb_ratio"),
)

BY_NAME = {m.name: m for m in METRICS}


def compute_all(run: RunScore) -> dict:
    """Every declared metric of one run, in declaration order."""
    return {m.name: m.compute(run) for m in METRICS}


def lost_metric() -> Metric:
    """The metric whose per-run flag is a lost run (``diverged``)."""
    return next(m for m in METRICS if m.check == "lost")


def accuracy_metrics() -> tuple[Metric, ...]:
    """The metrics ``tanbench check`` compares on mean and tail."""
    return tuple(m for m in METRICS if m.check == "accuracy")
