"""The paper's published numbers and scenario facts, copied verbatim from ../shared/paper/.

Configs, tests and reports read these files instead of retyping numbers.
"""

from __future__ import annotations

from functools import lru_cache
from importlib.resources import files

import pandas as pd
import yaml


@lru_cache(maxsize=1)
def scenario_facts() -> dict:
    """Zhou et al. 2017 Sections 4.1-4.3 and Tables 1, 2, 8 as a dict."""
    return yaml.safe_load(files(__package__).joinpath("zhou2017_scenario.yaml").read_text())


def tables_3_7() -> pd.DataFrame:
    """Every row of Tables 3-7 (mean/min/max final horizontal error over 50 runs, metres)."""
    with files(__package__).joinpath("zhou2017_tables_3_7.csv").open() as fh:
        return pd.read_csv(fh)


def table_9() -> pd.DataFrame:
    """Table 9, the vehicle run (25 m map, 5 s sampling)."""
    with files(__package__).joinpath("zhou2017_table_9.csv").open() as fh:
        return pd.read_csv(fh)
