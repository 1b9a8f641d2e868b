"""Recorded missions from the docs alone: the README's commands run as written (a simulated log
replayed and scored; a lon/lat log replayed on the Web-Mercator Monterey tiles, with and without
its reference track), and docs/missions.md's recipe writes a log that reads back."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from sweep_support import ROOT, cli_env

MONTEREY = ROOT.parent / "shared" / "data" / "monterey"


def readme_commands() -> list[str]:
    """The command lines of the README's "Recorded missions" code block."""
    section = (ROOT / "README.md").read_text().split("## Recorded missions", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```\n(.*?)```", section, re.S).group(1)
    return [line for line in block.splitlines() if line.strip()]


@pytest.mark.skipif(not MONTEREY.is_dir(), reason=f"Monterey tiles not present at {MONTEREY}")
def test_the_readme_s_mission_commands_work_as_written(tmp_path):
    """Each line in a shell, from a directory laid out like the project root (configs/ and ../shared)."""
    project = tmp_path / "project"
    project.mkdir()
    (project / "configs").symlink_to(ROOT / "configs")
    (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    env = cli_env()
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    commands = readme_commands()
    assert any("--lonlat" in c for c in commands) and any(c.startswith("rm ") for c in commands)
    for line in commands:
        proc = subprocess.run(["bash", "-c", line], cwd=project, env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, (line, proc.stderr[-2000:])
        assert "Traceback" not in proc.stderr
    results = project / "results"
    scored = pd.read_parquet(results / "replay-mission" / "runs.parquet")
    assert list(scored["method"]) == ["tight-dvl", "pmf-dvl"] and (scored["status"] == "ok").all()
    assert scored["final_horizontal_error_m"].notna().all()
    lonlat = pd.read_parquet(results / "replay-monterey" / "estimates.parquet")
    assert {"lon_deg", "lat_deg"} <= set(lonlat.columns)
    assert lonlat["lat_deg"].between(36.79, 36.81).all() and lonlat["lon_deg"].between(-121.825, -121.805).all()
    assert (results / "replay-monterey" / "series.parquet").exists()
    estimates_only = results / "replay-monterey-estimates"
    assert not (estimates_only / "series.parquet").exists()
    assert "final_horizontal_error_m" not in pd.read_parquet(estimates_only / "runs.parquet").columns
    pd.testing.assert_frame_equal(pd.read_parquet(estimates_only / "estimates.parquet"), lonlat, check_exact=True)


def test_the_docs_recipe_writes_a_log_that_reads_back(tmp_path, monkeypatch, capsys):
    """docs/missions.md's "Writing a log from your vehicle" runs as it stands: frd, degrees, lon/lat."""
    recipes = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "missions.md").read_text(), re.S)
    recipe = next(r for r in recipes if "read_log" in r)
    monkeypatch.chdir(tmp_path)
    exec(compile(recipe, "docs/missions.md recipe", "exec"), {"__name__": "__recipe__"})
    assert "lon_deg" in capsys.readouterr().out
    from tanbench.missions.logfile import read_log

    log = read_log(tmp_path / "my-mission")
    imu = log.tables["imu"]
    assert (imu["accel_z_m_s2"] == 9.79).all()  # frd's down-positive specific force, in tanbench's rfu frame
    assert log.tables["navigation"]["heading_rad"].iloc[0] == pytest.approx(3.141592653589793 / 2)
    assert log.tables["navigation"]["up_m"].iloc[0] == -10.0
