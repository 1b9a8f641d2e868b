"""`make heldout-relief`'s builder and summary (examples/prototypes/heldout_relief.py, docs/filters.md 8)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "examples" / "prototypes" / "heldout_relief.py"


@pytest.fixture(scope="module")
def heldout():
    spec = importlib.util.spec_from_file_location("heldout_relief", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _world(root: Path, name: str, rows: list[tuple[str, bool, float]]) -> None:
    d = root / name / "runs" / "cell_id=0"
    d.mkdir(parents=True)
    pd.DataFrame(rows, columns=["method", "diverged", "final_horizontal_error_m"]).to_parquet(d / "runs.parquet")


def test_summary_marks_each_missed_target(heldout, tmp_path):
    ok = [("tight-dvl", False, 3.0), ("tight-sbe", False, 5.0), ("loose-dvl", False, 4.0)]
    _world(tmp_path, "J1", ok * 10)
    # tight-sbe: one lost run is allowed, but not a final error above 200 m; loose-dvl: two lost are allowed
    _world(tmp_path, "J2", ok * 8 + [("tight-sbe", True, 250.0), ("loose-dvl", True, 90.0),
                                     ("loose-dvl", True, 80.0), ("tight-dvl", False, 60.0)])
    _world(tmp_path, "J10", ok * 9 + [("tight-dvl", True, 76.0)])
    (tmp_path / "J7sbe" / "runs").mkdir(parents=True)  # not a world: ignored
    text = heldout.summary(tmp_path)
    rows = [line for line in text.splitlines() if line.startswith("| J")]
    assert [r.split("|")[1].strip() for r in rows] == ["J1", "J2", "J10"]  # numeric order
    assert "**" not in rows[0]
    j2 = [c.strip() for c in rows[1].split("|")[2:5]]
    assert j2 == ["0 of 9 (60.0 m)", "**1 of 9 (250.0 m)**", "2 of 10 (90.0 m)"]
    assert rows[2].split("|")[2].strip() == "**1 of 10 (76.0 m)**"
    assert "tight-dvl 1 of 3, tight-sbe 1 of 3, loose-dvl 0 of 3" in text


def test_summary_refuses_an_empty_directory(heldout, tmp_path):
    with pytest.raises(SystemExit, match="no world results"):
        heldout.summary(tmp_path)


def test_window_is_centred_and_the_path_independent_of_the_checkout(heldout, tmp_path, monkeypatch):
    z = np.arange(200 * 300, dtype=float).reshape(200, 300)
    w = heldout.window(z, 24.0, 24.0, 0.5, 0.5)
    assert w.shape == (101, 101)
    assert w[50, 50] == z[100, 150]  # the centre node
    monkeypatch.chdir(tmp_path)
    assert heldout.sweep_path(tmp_path / "worlds" / "J1.npz") == str(Path("worlds") / "J1.npz")
    assert heldout.sweep_path(Path("/elsewhere/J1.npz")) == "/elsewhere/J1.npz"
