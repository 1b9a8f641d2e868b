"""Our tables beside Zhou et al. 2017's published ones (package data, never retyped).

Rows are matched on the table number (``table3`` .. ``table7``, ``table9``), the scenario
columns and the method; each gets the paper's mean/min/max and the ratio ours/paper of
the mean final error. Table 9 (the vehicle run) also carries the paper's time-averaged
error ("mean horizontal position error ... with simulated data"), matched to ours.
"""

from __future__ import annotations

import re

import pandas as pd

from tanbench.paperdata import table_9, tables_3_7

KEYS = ["map_resolution_m", "noise_m", "sampling_time_s", "particles", "method"]


def paper_rows(table: str) -> pd.DataFrame | None:
    """The paper's rows for one of our table names, or None if the paper has no such table."""
    m = re.fullmatch(r"table_?(\d+)", table)
    if not m:
        return None
    number = int(m.group(1))
    if number == 9:
        p = table_9().rename(columns={"mean_error_m": "paper_mean_time_avg_error_m",
                                      "min_error_m": "paper_min_time_avg_error_m",
                                      "max_error_m": "paper_max_time_avg_error_m"})
    else:
        p = tables_3_7()
        p = p[p["table"] == number]
        if p.empty:
            return None
    p = p.rename(columns={"mean_final_error_m": "paper_mean_final_error_m",
                          "min_final_error_m": "paper_min_final_error_m",
                          "max_final_error_m": "paper_max_final_error_m"})
    keep = KEYS + [c for c in p.columns if c.startswith("paper_")]
    return p[keep]


def compare_with_paper(tables: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """Each table with the paper's values beside it and the ratio ours / paper."""
    out = {}
    for name, table in tables.items():
        paper = paper_rows(name)
        if paper is None:
            out[name] = table
            continue
        cols = ["table"] + [c for c in ("area",) + tuple(KEYS) if c in table.columns] + [
            "n_runs", "mean_final_error_m", "min_final_error_m", "max_final_error_m", "mean_time_avg_error_m"]
        ours = table[cols].copy()
        merged = ours.merge(paper, on=KEYS, how="left")
        merged["ratio_final"] = merged["mean_final_error_m"] / merged["paper_mean_final_error_m"]
        if "paper_mean_time_avg_error_m" in merged:
            merged["ratio_time_avg"] = merged["mean_time_avg_error_m"] / merged["paper_mean_time_avg_error_m"]
        out[name] = merged
    return out


# our table names that have a published counterpart (configs/zhou2017.yaml names them so)
PAPER_TABLES = ("table3", "table4", "table5", "table6", "table7", "table9")
