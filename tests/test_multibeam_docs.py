"""A multibeam sweep on real relief from the docs alone: docs/multibeam.md's sweep file and
commands (section 4) run as written, from a directory laid out like the project root, on the
Monterey tiles (with one run per cell instead of the file's five, to keep the test short)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from sweep_support import ROOT, cli_env

MONTEREY = ROOT.parent / "shared" / "data" / "monterey"


def section_blocks() -> tuple[str, list[str]]:
    """The sweep file and the command lines of docs/multibeam.md's section 4."""
    section = (ROOT / "docs" / "multibeam.md").read_text().split("## 4.", 1)[1].split("\n## ", 1)[0]
    sweep = re.search(r"```yaml\n(.*?)```", section, re.S).group(1)
    commands = re.search(r"```\n(.*?)```", section.replace(f"```yaml\n{sweep}```", ""), re.S).group(1)
    return sweep, [line for line in commands.splitlines() if line.strip()]


@pytest.mark.skipif(not MONTEREY.is_dir(), reason=f"Monterey tiles not present at {MONTEREY}")
def test_the_docs_multibeam_sweep_runs_as_written(tmp_path):
    project = tmp_path / "project"
    project.mkdir()
    (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    sweep, commands = section_blocks()
    data = yaml.safe_load(sweep)
    assert data["methods"] == ["tight-mbe", "pmf-mbe"] and data["scenario"]["terrain"]["kind"] == "file"
    (project / "my-multibeam.yaml").write_text(sweep.replace("runs: 5", "runs: 1"))
    env = cli_env()
    env["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])
    assert [c.split()[1] for c in commands] == ["validate", "run", "plot"]
    for line in commands:
        proc = subprocess.run(["bash", "-c", line], cwd=project, env=env, capture_output=True, text=True, timeout=1500)
        assert proc.returncode == 0, (line, proc.stdout[-2000:], proc.stderr[-2000:])
    runs = pd.read_parquet(project / "results" / "my-multibeam" / "runs")
    assert set(runs["method"]) == {"tight-mbe", "pmf-mbe"} and (runs["status"] == "ok").all()
    assert sorted(set(runs["sensors.multibeam_beams"])) == [8, 32] and len(runs) == 4
    assert (project / "results" / "my-multibeam" / "figures" / "accuracy_cost.png").is_file()
