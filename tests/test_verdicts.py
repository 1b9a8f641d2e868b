"""The verdicts' statistics (tanbench.inference) and the two-part regression check (issue 22).

Fixed seeds throughout; the false-alarm rates are measured on simulated nulls (heavy-tailed,
like the errors of a terrain-navigation filter) with enough datasets for the bound asserted.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from check_support import BASELINE, copy_of_baseline, rewrite_runs  # noqa: F401 (a fixture)
from tanbench import inference, store
from tanbench.check import CheckOptions, compare, looks, spend
from tanbench.cli import app
from tanbench.errors import TanbenchError

# ---- inference ------------------------------------------------------------------------------

def test_exact_intervals_and_tests_match_their_definitions():
    lo, hi = inference.clopper_pearson(0, 30)
    assert lo == 0.0 and hi == pytest.approx(1 - 0.025 ** (1 / 30))
    lo, hi = inference.clopper_pearson(3, 10)
    assert (lo, hi) == pytest.approx((0.0667, 0.6525), abs=1e-4)
    new = np.array([1, 1, 1, 1, 1, 0, 0, 0], bool)  # five runs lost only in NEW: McNemar p = 1/32
    base = np.zeros(8, bool)
    assert inference.lost_tests(new, base, paired=True) == pytest.approx((1 / 32, 1.0))
    p_worse, _ = inference.lost_tests(new, base, paired=False)
    assert p_worse == pytest.approx(0.0128, abs=1e-4)  # Fisher's exact, one-sided: C(5,5)C(11,3)/C(16,8)


def _null_rejections(paired: bool, statistic: str, shift: float, datasets: int = 300, n: int = 30) -> float:
    """Share of simulated nulls rejected at 5 %: lognormal errors, NEW = a reseed of BASELINE
    plus exactly ``shift`` (H0 "change <= shift" holds at its boundary)."""
    rng = np.random.default_rng(22)
    rejected = 0
    for k in range(datasets):
        y = rng.lognormal(1.0, 1.0, n)
        x = rng.lognormal(1.0, 1.0, n) + shift
        rejected += inference.permutation_p(x, y, shift, paired, statistic, n=400, seed=k) < 0.05
    return rejected / datasets


@pytest.mark.parametrize("paired", [True, False])
@pytest.mark.parametrize("statistic", ["mean", "p90"])
def test_false_alarm_rate_at_most_alpha_on_simulated_nulls(paired, statistic):
    """Reseeded heavy-tailed nulls at the margin's boundary: rejected in at most 5 % + 2.5
    binomial standard errors (300 datasets: 8.2 %) of cases."""
    assert _null_rejections(paired, statistic, shift=1.0) <= 0.05 + 2.5 * np.sqrt(0.05 * 0.95 / 300)


def test_permutation_test_sees_a_shift_beyond_the_margin():
    rng = np.random.default_rng(5)
    y = rng.lognormal(1.0, 0.5, 60)
    x = y * 1.3 + rng.normal(0, 0.05, 60)
    assert inference.permutation_p(x, y, 0.1 * y.mean(), True) < 0.001
    assert inference.permutation_p(y, x, 0.1 * y.mean(), True) > 0.5


def test_minimal_detectable_effects():
    """Identical pairs (no reshuffled lost runs): McNemar needs k one-way pairs with 2^-k <= level,
    so the MDE is the Poisson mean reaching k with 80 % power, over n."""
    level = 0.05 / 15
    k = int(np.ceil(np.log2(1 / level)))
    from scipy import special

    assert inference.mde_lost_paired(240, 0, level) == pytest.approx(special.gammaincinv(k, 0.8) / 240)
    assert inference.mde_lost_paired(240, 0, level) < 0.05 < inference.mde_lost_paired(200, 0, level)
    assert inference.mde_lost_paired(240, 3, level) > inference.mde_lost_paired(240, 0, level)
    assert inference.mde_lost(0.0, 30, 30, level) > inference.mde_lost(0.0, 300, 300, level)
    assert inference.mde_shift(1.0, 0.0, level) == 1.0


def test_looks_and_alpha_spending():
    assert looks(30, 30, 100) == [30, 60, 90, 100]
    assert spend(0.05, 4) == pytest.approx(0.0125)
    with pytest.raises(TanbenchError):
        looks(50, 10, 20)


# ---- the check --------------------------------------------------------------------------------

def test_two_part_rows_for_every_cell_and_method():
    result = compare(BASELINE, BASELINE)
    t = result.table
    assert set(t["metric"]) == {"lost", "final", "final p90", "time-avg", "time-avg p90"}
    assert len(t) == 9 * 5 and (t["role"] == "decisive").all()
    assert not result.regressed and (t["change"] == 0).all()


def test_verdict_never_disagrees_in_sign_with_its_effect(copy_of_baseline):
    """Random per-cell, per-method scalings and lost flags flipped: every regressed row printed a
    change above its margin, every improved row one below minus its margin."""
    rng = np.random.default_rng(7)
    factors = {}

    def perturb(df, cell):
        for m in df["method"].unique():
            f = factors.setdefault((cell, m), float(rng.choice([0.5, 0.8, 1.0, 1.25, 2.0])))
            sel = df["method"] == m
            for col in ("final_horizontal_error_m", "mean_horizontal_error_m"):
                df.loc[sel, col] = df.loc[sel, col] * f * rng.lognormal(0, 0.1, sel.sum())
        flip = rng.random(len(df)) < 0.1
        df.loc[flip, "diverged"] = ~df.loc[flip, "diverged"].astype(bool)
        return df

    rewrite_runs(copy_of_baseline, perturb)
    for pool in ("none", "method"):
        t = compare(copy_of_baseline, BASELINE, CheckOptions(margin_abs=0.0, pool=pool)).table
        assert (t.loc[t["verdict"] == "regressed", "change"] > t.loc[t["verdict"] == "regressed", "margin"]).all()
        assert (t.loc[t["verdict"] == "improved", "change"] < -t.loc[t["verdict"] == "improved", "margin"]).all()
        assert (t["verdict"] == "regressed").any() and (t["verdict"] == "improved").any()


def test_lost_runs_are_their_own_outcome(copy_of_baseline):
    """Twelve more tight-dvl runs lost in one cell, their errors unchanged: the lost row regresses
    (McNemar), the accuracy rows (over runs lost in neither) do not move."""
    victim = store.cell_of(store.run_files(copy_of_baseline)[0])

    def lose(df, cell):
        if cell == victim:
            sel = (df["method"] == "tight-dvl") & (df["run"] < 12)
            df.loc[sel, "diverged"] = True
        return df

    rewrite_runs(copy_of_baseline, lose)
    t = compare(copy_of_baseline, BASELINE, CheckOptions(min_runs=5)).table
    row = t[(t["cell_id"] == victim) & (t["method"] == "tight-dvl")].set_index("metric")
    assert row.loc["lost", "verdict"] == "regressed"
    assert row.loc["lost", "change"] == pytest.approx(12 / row.loc["lost", "n_new"])
    assert (t.drop(t[(t["metric"] == "lost")].index)["verdict"] != "regressed").all()


def test_three_runs_of_a_method_made_700_times_worse_do_not_pass(copy_of_baseline, tmp_path):
    """Three runs per cell: the check cannot see anything and says so (too few runs), exit 1."""
    base3 = tmp_path / "base3"
    shutil.copytree(BASELINE, base3, ignore=shutil.ignore_patterns(".work"))

    def first3(df, cell):
        return df[df["run"] < 3]

    def worse(df, cell):
        df = df[df["run"] < 3].copy()
        sel = df["method"] == "tight-dvl"
        for col in ("final_horizontal_error_m", "mean_horizontal_error_m"):
            df.loc[sel, col] *= 700.0
        return df

    rewrite_runs(base3, first3)
    rewrite_runs(copy_of_baseline, worse)
    out = CliRunner().invoke(app, ["check", str(copy_of_baseline), str(base3)])
    assert out.exit_code == 1
    assert "unchanged" not in [line.split()[0] for line in out.output.splitlines() if "tight-dvl" in line]
    assert "too few runs" in out.output


def test_underpowered_rows_fail_unless_allowed(copy_of_baseline):
    runner = CliRunner()
    bad = runner.invoke(app, ["check", str(copy_of_baseline), str(BASELINE)])
    assert bad.exit_code == 1 and "underpowered" in bad.output  # 80 runs cannot see 5 more lost in 100
    ok = runner.invoke(app, ["check", str(copy_of_baseline), str(BASELINE), "--allow-underpowered"])
    assert ok.exit_code == 0, ok.output


def test_pooling_per_method_is_declared_and_decides(copy_of_baseline):
    """--pool method: one decisive row set per method over its cells; a 30 % worse tight-sbe in
    every cell regresses its pooled time-averaged row, the cell rows are information only."""
    def worse(df, cell):
        sel = df["method"] == "tight-sbe"
        df.loc[sel, "mean_horizontal_error_m"] *= 1.3
        return df

    rewrite_runs(copy_of_baseline, worse)
    result = compare(copy_of_baseline, BASELINE, CheckOptions(pool="method", margin_abs=0.0))
    d = result.decisive
    assert set(d["scope"]) == {"pooled"} and len(d) == 3 * 5
    row = d[(d["method"] == "tight-sbe") & (d["metric"] == "time-avg")].iloc[0]
    assert row["verdict"] == "regressed" and row["change"] > 0
    assert set(result.table.loc[result.table["scope"] == "cell", "role"]) == {"info"}
    assert not (d[d["method"] != "tight-sbe"]["verdict"] == "regressed").any()


def test_ignore_never_averages_two_cells_into_one_row(copy_of_baseline):
    """Ignoring a column that tells two cells apart would merge them: refused with one line."""
    with pytest.raises(TanbenchError, match="one cell; check compares cell with cell"):
        compare(copy_of_baseline, BASELINE, CheckOptions(ignore=("sampling_time_s",)))


# ---- --until-decisive ---------------------------------------------------------------------------

SMALL = """
name: sequential
seed: 5
runs: 4
methods: [tight-dvl]
scenario: {particles: 60, duration_s: 60%s}
"""


def _decisive_run(tmp_path, tag):
    from tanbench.runner.engine import run_sweep
    from tanbench.runner.sequential import until_decisive
    from tanbench.sweep import parse_sweep

    dirs = []
    for name, extra in (("new", ", faults: {map_offset_east_m: 40.0}"), ("base", "")):
        d = tmp_path / f"{tag}-{name}"
        text = SMALL % extra
        run_sweep(parse_sweep(text, "s.yaml"), d, workers=1, series="none", progress=False,
                  echo=lambda *_: None, note=lambda *_: None)
        dirs.append(d)
    lines = []
    result = until_decisive(dirs[0], dirs[1], CheckOptions(ignore=("faults.map_offset_east_m",), min_runs=2),
                            batch=4, cap=8, echo=lines.append)
    return result, lines


def test_until_decisive_is_deterministic_and_spends_alpha_over_its_looks(tmp_path):
    """Two fresh starts of the same comparison stop at the same look with the same table; the
    looks are 4 and 8 runs, each at alpha / 2."""
    first, lines = _decisive_run(tmp_path, "a")
    again, lines2 = _decisive_run(tmp_path, "b")
    assert lines == lines2 and lines[0].startswith("look 1/2: 4 runs per cell, level 0.025")
    cols = ["metric", "n_new", "change", "p_worse", "verdict"]
    assert first.table[cols].equals(again.table[cols])


PLUG = """import numpy as np
OFFSET = {offset}


def run(ctx):
    k = ctx.updates.imu
    return {{"east": ctx.nav.pos[k, 0] + OFFSET, "north": ctx.nav.pos[k, 1]}}
"""


def test_until_decisive_refuses_a_baseline_its_code_would_recompute(tmp_path):
    """A plug-in edited after the baseline was stored: extending the baseline would recompute its runs with the
    new code, and the check would compare the new code with itself (found by a user's audit: a bug that lost 45 %
    of runs passed). Refused, one line, and the baseline's runs are left as they were."""
    from sweep_support import cli, error_lines, sweep_dict, write_sweep

    (tmp_path / "plugx").mkdir()
    (tmp_path / "plugx" / "__init__.py").write_text("")
    (tmp_path / "plugx" / "m.py").write_text(PLUG.format(offset=0.0))
    sweep = write_sweep(tmp_path / "s.yaml", sweep_dict(name="plug", runs=2, methods=["plugx.m:run"], tables={},
                                                       scenario={"duration_s": 60, "particles": 60}))
    for name in ("base", "new"):
        proc = cli("run", sweep, "--out", tmp_path / name, "--workers", 1, "-q", extra_path=tmp_path)
        assert proc.returncode == 0, proc.stderr
    (tmp_path / "plugx" / "m.py").write_text(PLUG.format(offset=5.0))
    before = sorted((p, p.stat().st_mtime_ns) for p in (tmp_path / "base" / "runs").rglob("*.parquet"))
    proc = cli("check", tmp_path / "new", tmp_path / "base", "--until-decisive", extra_path=tmp_path)
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    lines = error_lines(proc.stderr)
    assert len(lines) == 1 and "would be recomputed by the code here" in lines[0] and "plugx.m:run (code)" in lines[0]
    assert sorted((p, p.stat().st_mtime_ns) for p in (tmp_path / "base" / "runs").rglob("*.parquet")) == before


def test_until_decisive_refuses_a_baseline_another_revision_made(tmp_path):
    """Built-ins have no code identity of their own: a baseline made by another revision of the code would be
    extended with this code's runs (a reviewer reproduced it with a bug put into tight-dvl). Refused, naming
    the revisions; the directory is left as it was."""
    import pyarrow.parquet as pq

    from tanbench.runner.engine import run_sweep
    from tanbench.runner.sequential import until_decisive
    from tanbench.sweep import parse_sweep

    if not store.git_revision():
        pytest.skip("not a git checkout: the revision is unknown")
    dirs = []
    for name in ("new", "base"):
        d = tmp_path / name
        run_sweep(parse_sweep(SMALL % "", "s.yaml"), d, workers=1, series="none", progress=False,
                  echo=lambda *_: None, note=lambda *_: None)
        dirs.append(d)
    for path in store.run_files(dirs[1]):
        meta = store.read_meta(path)
        store.write_parquet(pq.read_table(path).to_pandas(), path, {**meta, "git_revision": "abc1234"})
    before = sorted((p, p.stat().st_mtime_ns) for p in (dirs[1] / "runs").rglob("*.parquet"))
    with pytest.raises(TanbenchError, match=f"made by code revision abc1234, and this is {store.git_revision()}"):
        until_decisive(dirs[0], dirs[1], CheckOptions(min_runs=2), batch=4, cap=8, echo=lambda *_: None)
    assert sorted((p, p.stat().st_mtime_ns) for p in (dirs[1] / "runs").rglob("*.parquet")) == before
