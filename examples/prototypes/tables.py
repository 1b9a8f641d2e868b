"""Compact markdown tables (rows: world x variant) of analyse.py's statistics, for docs/filters.md.

    ../../.venv/bin/python tables.py OUT --worlds A,B --variants tight-dvl,pmf-dvl --columns ratio,final
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from analyse import boot_ci, fmt, t_ci, world_stats  # noqa: E402

MEAN_T = ("final", "wall")


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--worlds", required=True)
    p.add_argument("--variants", required=True)
    p.add_argument("--columns", required=True)
    a = p.parse_args(argv)
    cols = a.columns.split(",")
    print("| world | method | lost | max final (m) | " + " | ".join(cols) + " |")
    print("|---|---|---|---|" + "---|" * len(cols))
    for world in a.worlds.split(","):
        for v in a.variants.split(","):
            s, _ = world_stats(a.out, world, v)
            if s is None:
                continue
            ok = s[~s["lost"]]
            cells = [fmt(*(t_ci(ok[c]) if c in MEAN_T else boot_ci(ok[c]))) if c in ok else "-" for c in cols]
            print(f"| {world} | {v} | {int(s['lost'].sum())}/{len(s)} | {s['final'].max():.1f} | "
                  + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
