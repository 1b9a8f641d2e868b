"""`tanbench check`: statistics of the regression check and its command-line behaviour."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from check_support import BASELINE, copy_of_baseline, rewrite_runs  # noqa: F401 (a fixture)
from tanbench.check import CheckOptions, compare, holm
from tanbench.cli import app, main
from tanbench import store


def test_holm_matches_definition():
    """Holm adjustment: sorted p times (m - rank), cumulative max, capped at 1."""
    p = np.array([0.01, 0.04, 0.03, 0.5])
    np.testing.assert_allclose(holm(p), [0.04, 0.09, 0.09, 0.5])


def test_identical_inputs_nothing_regressed():
    """The baseline against itself: every comparison paired and unchanged (or, for the lost-run
    rows of 80-run cells, underpowered: never regressed)."""
    result = compare(BASELINE, BASELINE)
    assert not result.regressed
    assert set(result.table["verdict"]) <= {"unchanged", "underpowered"}
    assert result.table["paired"].all()
    assert (result.table["change"] == 0).all()
    assert not result.only_new and not result.only_baseline


def test_injected_degradation_flags_exactly_that_cell(copy_of_baseline):
    """Errors x1.5 in one cell: that cell regresses, no other cell does."""
    victim = store.cell_of(store.run_files(copy_of_baseline)[0])

    def degrade(df, cell_id):
        if cell_id == victim:
            for col in ("final_horizontal_error_m", "mean_horizontal_error_m"):
                df[col] *= 1.5
        return df

    rewrite_runs(copy_of_baseline, degrade)
    result = compare(copy_of_baseline, BASELINE)
    flagged = result.table[result.table["verdict"] == "regressed"]
    assert len(flagged) > 0
    assert set(flagged["cell_id"]) == {victim}
    assert result.regressed


def test_improvement_is_not_a_regression(copy_of_baseline):
    """Errors halved everywhere: improvements, and the exit code says nothing regressed."""
    def improve(df, cell_id):
        for col in ("final_horizontal_error_m", "mean_horizontal_error_m"):
            df[col] *= 0.5
        return df

    rewrite_runs(copy_of_baseline, improve)
    result = compare(copy_of_baseline, BASELINE)
    assert not result.regressed
    assert (result.table["verdict"] == "improved").any()


def test_unpaired_when_seeds_differ(copy_of_baseline):
    """Different seeds (other vehicle data): the comparison falls back to the unpaired test."""
    rewrite_runs(copy_of_baseline, lambda df, cell_id: df.assign(seed=df["seed"] + 1))
    result = compare(copy_of_baseline, BASELINE)
    assert not result.table["paired"].any()
    assert not result.regressed


def test_mismatched_cells_are_reported(copy_of_baseline):
    """A cell only in one directory is listed, the others still compared."""
    victim = store.run_files(copy_of_baseline)[0].parent
    shutil.rmtree(victim)
    result = compare(copy_of_baseline, BASELINE)
    cell_id = victim.name.split("=", 1)[1]
    assert len(result.only_baseline) == 1 and cell_id in result.only_baseline[0]
    assert not result.only_new
    assert cell_id not in set(result.table["cell_id"])


def test_margin_options_change_the_verdict(copy_of_baseline):
    """A small uniform degradation passes the default margin but not a zero margin."""
    def nudge(df, cell_id):
        df["final_horizontal_error_m"] += 0.3
        return df

    rewrite_runs(copy_of_baseline, nudge)
    assert not compare(copy_of_baseline, BASELINE).regressed
    strict = compare(copy_of_baseline, BASELINE, CheckOptions(margin_rel=0.0, margin_abs=0.0))
    assert strict.regressed


def test_cli_exit_codes_and_report(copy_of_baseline, tmp_path):
    """Exit 0 when nothing regressed, 1 when something did; --report writes md/json/parquet."""
    runner = CliRunner()
    ok = runner.invoke(app, ["check", str(copy_of_baseline), str(BASELINE), "--report", str(tmp_path / "r.json"),
                             "--allow-underpowered"])
    assert ok.exit_code == 0, ok.output
    assert "0 regressed" in ok.output
    assert (tmp_path / "r.json").exists()

    def degrade(df, cell_id):
        df["final_horizontal_error_m"] *= 3.0
        return df

    rewrite_runs(copy_of_baseline, degrade)
    for name in ("r.md", "r.parquet"):
        bad = runner.invoke(app, ["check", str(copy_of_baseline), str(BASELINE), "--report", str(tmp_path / name)])
        assert bad.exit_code == 1, bad.output
        assert "regressed" in bad.output
    assert pd.read_parquet(tmp_path / "r.parquet")["verdict"].eq("regressed").any()
    # the .md report keeps 4 significant digits (it rounded a lost rate of 0.450 to 0.5)
    table = pd.read_parquet(tmp_path / "r.parquet")
    md = (tmp_path / "r.md").read_text()
    values = [v for v in table["new"].dropna() if f"{v:.4g}" != f"{v:.1f}"][:5]
    assert values and all(f"| {v:.4g} |" in md for v in values)


def test_corrupt_parquet_is_one_clear_error(copy_of_baseline, capsys, monkeypatch):
    """A corrupt run file: one 'error:' line naming the file, exit 2, no traceback."""
    path = store.run_files(copy_of_baseline)[0]
    path.write_bytes(b"PAR1 this is not parquet")
    monkeypatch.setattr("sys.argv", ["tanbench", "check", str(copy_of_baseline), str(BASELINE)])
    with pytest.raises(SystemExit) as exit_info:
        main()
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and path.name in err[0]
    assert "Traceback" not in err[0]


def test_incompatible_schema_is_one_clear_error(copy_of_baseline, capsys, monkeypatch):
    """Results written with another schema version: refused with one line, exit 2."""
    path = store.run_files(copy_of_baseline)[0]
    meta = store.read_meta(path)
    store.write_parquet(pq.read_table(path).to_pandas(), path, {**meta, "schema_version": 999})
    monkeypatch.setattr("sys.argv", ["tanbench", "check", str(copy_of_baseline), str(BASELINE)])
    with pytest.raises(SystemExit) as exit_info:
        main()
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "schema" in err and err.count("\n") == 1


def test_ignore_matches_cells_that_differ_only_there(copy_of_baseline):
    """Cells that differ only in an ignored scenario column are compared (the two random streams of
    ``filter.random_numbers``); without --ignore they are not; an unknown column is one clear error."""
    from tanbench.errors import TanbenchError

    def other_stream(df, cell):
        df["filter.random_numbers"] = "numpy" if (df["filter.random_numbers"] == "fast").all() else "fast"
        return df

    rewrite_runs(copy_of_baseline, other_stream)
    with pytest.raises(TanbenchError, match="no cell in common: their cells differ in filter.random_numbers; to "
                                            "compare across that, give --ignore filter.random_numbers$"):
        compare(copy_of_baseline, BASELINE)  # the column named, and how to compare across it (a user's audit)
    rewrite_runs(copy_of_baseline, lambda df, cell: df.assign(**{"terrain.seed": df["terrain.seed"].astype(float)}))
    with pytest.raises(TanbenchError, match="differ in filter.random_numbers; to compare across that, give "
                                            "--ignore filter.random_numbers$"):
        compare(copy_of_baseline, BASELINE)  # 1.0 is 1 in the cells' match, so not named (found by the review)
    result = compare(copy_of_baseline, BASELINE, CheckOptions(ignore=("filter.random_numbers",)))
    assert not result.missing and not result.regressed
    assert (result.table["verdict"] != "regressed").all() and len(result.table) == 9 * 5
    with pytest.raises(TanbenchError, match="--ignore filter.no_such_option: not a scenario column"):
        compare(copy_of_baseline, BASELINE, CheckOptions(ignore=("filter.no_such_option",)))


def test_the_console_table_keeps_its_columns_for_long_method_names(copy_of_baseline):
    """A plug-in's long name pushed its row's columns out of line with the header (found by a user's audit)."""
    from tanbench.check import render

    rewrite_runs(copy_of_baseline, lambda df, cell: df.assign(method=df["method"].str.replace(
        "loose-dvl", "my_filters.pf:METHOD")))
    result = compare(copy_of_baseline, copy_of_baseline)
    lines = render(result).splitlines()
    rows = [line for line in lines if line.startswith(("unchanged", "regressed", "improved", "underpowered"))]
    assert any("my_filters.pf:METHOD" in line for line in rows)
    metric_at = lines[0].index("metric")
    assert all(line[metric_at - 1] == " " and line[metric_at] != " " for line in rows)
