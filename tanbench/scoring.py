"""Scoring: a method's estimates against the truth, as per-run metrics and per-update series.

The only place (with the simulation) that reads the truth. A method's output
(:class:`tanbench.methods.api.MethodOutput`) is compared with the true trajectory at
the update times; the navigation system's own error is scored beside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tanbench.terrain import navigation_map
from tanbench.vehicle.attitude import wrap_pi, yaw_to_heading_deg


@dataclass
class RunResult:
    """Per-run metrics (dict of scalars) and per-update series (dict of equal-length arrays)."""

    metrics: dict
    series: dict


def recovery_stats(t: np.ndarray, reinit: np.ndarray, healthy: np.ndarray, steps: int) -> tuple[int, float, float]:
    """(recoveries, time of the first reinitialisation, mean time to recover) of one run.

    A reinitialisation at update k has recovered at the first later update ending a run of
    ``steps`` healthy updates (the method's ``healthy`` series: cloud converged and fitting
    the terrain), before the next reinitialisation. Times are NaN when there is nothing
    to time.
    """
    events = np.nonzero(reinit)[0]
    first = float(t[events[0]] - t[0]) if events.size else float("nan")
    times = []
    for i, k0 in enumerate(events):
        end = events[i + 1] if i + 1 < events.size else t.size
        run = 0
        for k in range(k0 + 1, end):
            run = run + 1 if healthy[k] else 0
            if run >= steps:
                times.append(float(t[k] - t[k0]))
                break
    return len(times), first, float(np.mean(times)) if times else float("nan")


def score(scenario, vehicle, updates, out, wall: float, method: str | None = None, nmap=None,
          bound=None) -> RunResult:
    """Metrics and series of one method's checked output ``out`` on one run.

    ``bound`` is the method's posterior Cramer-Rao bound series in this cell
    (:func:`tanbench.bounds.pcrb.method_bound`; None: no bound); ``nmap`` is the navigation map (default:
    the scenario's). ``vehicle`` has the observations (``obs``) and the truth (``truth``:
    t, pos, yaw at the IMU samples), simulated or a mission log's reference.
    """
    from tanbench.metrics.run_metrics import score_consistency_and_bound

    truth, nav = vehicle.truth, vehicle.obs.nav
    upd = updates.imu
    t = truth.t[upd]
    est_up = out.up if out.up is not None else nav.pos[upd, 2]
    if out.yaw is not None:
        est_yaw = out.yaw
    elif out.heading_deg is not None:
        est_yaw = -np.radians(out.heading_deg)
    else:
        est_yaw = nav.yaw[upd]
    err_e = out.east - truth.pos[upd, 0]
    err_n = out.north - truth.pos[upd, 1]
    err_h = np.hypot(err_e, err_n)
    heading_err = np.degrees(wrap_pi(-(est_yaw - truth.yaw[upd])))
    nav_err_h = np.hypot(nav.pos[upd, 0] - truth.pos[upd, 0], nav.pos[upd, 1] - truth.pos[upd, 1])
    f = scenario.filter
    below = err_h < f.convergence_threshold_m
    if below[-1]:
        last_bad = np.nonzero(~below)[0]
        kc = int(last_bad[-1] + 1) if last_bad.size else 0
        conv_time = float(t[kc] - t[0])
        rmse = float(np.sqrt(np.mean(err_h[kc:] ** 2)))
    else:
        conv_time = rmse = float("nan")
    reinit = out.reinit if out.reinit is not None else np.zeros(t.size, dtype=bool)
    nan = np.full(t.size, np.nan)
    healthy = out.extra.get("healthy", np.zeros(t.size))
    recoveries, first_reinit, mean_recovery = recovery_stats(t, reinit, np.asarray(healthy) > 0.5,
                                                             f.divergence_steps)
    nmap = nmap if nmap is not None else navigation_map(scenario.terrain, scenario.map_resolution_m)
    metrics = {
        "final_horizontal_error_m": float(err_h[-1]),
        "mean_horizontal_error_m": float(err_h.mean()),
        "rmse_after_convergence_m": rmse,
        "final_heading_error_deg": float(abs(heading_err[-1])),
        "convergence_time_s": conv_time,
        "diverged": bool(err_h[-1] > f.divergence_threshold_m),
        "reinitialisations": int(reinit.sum()),
        "final_east_error_m": float(err_e[-1]),
        "final_north_error_m": float(err_n[-1]),
        "filter_wall_s": float(wall),
        "recoveries": recoveries,
        "first_reinit_s": first_reinit,
        "mean_recovery_s": mean_recovery,
        "left_map": bool((~nmap.contains(out.east, out.north)).any()),
        "fixes_accepted": int(np.sum(out.extra.get("fix_accepted", 0))),
        "fixes_rejected": int(np.sum(out.extra.get("fix_rejected", 0))),
    }
    var_e = out.var_e if out.var_e is not None else nan
    var_n = out.var_n if out.var_n is not None else nan
    cov_en = out.cov_en if out.cov_en is not None else nan
    consistency, bound_series = score_consistency_and_bound(scenario, method, t, err_e, err_n, var_e, var_n,
                                                            cov_en, conv_time, rmse, bound)
    metrics.update(consistency)
    series = {
        "t": t,
        "est_e": out.east, "est_n": out.north, "est_u": np.asarray(est_up, dtype=float),
        "est_heading_deg": yaw_to_heading_deg(est_yaw),
        "truth_e": truth.pos[upd, 0], "truth_n": truth.pos[upd, 1], "truth_u": truth.pos[upd, 2],
        "truth_heading_deg": yaw_to_heading_deg(truth.yaw[upd]),
        "nav_e": nav.pos[upd, 0], "nav_n": nav.pos[upd, 1],
        "nav_heading_deg": yaw_to_heading_deg(nav.yaw[upd]),
        "east_error_m": err_e, "north_error_m": err_n, "horizontal_error_m": err_h,
        "heading_error_deg": heading_err, "nav_horizontal_error_m": nav_err_h,
        "ess": out.ess if out.ess is not None else nan, "reinit": reinit,
        "var_e": var_e, "var_n": var_n, "cov_en": cov_en,
        **{k: getattr(out, k) for k in ("var_u", "var_heading") if getattr(out, k) is not None},
        **out.extra, **bound_series,
    }
    return RunResult(metrics=metrics, series=series)
