# tanbench: `make run` and `make test` work on a fresh clone with only Python installed.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
TB     := $(BIN)/tanbench
# the paper report shows the literal profile, its other seafloor and the anatomy when their results exist
PAPER_REPORT = $(TB) report results/zhou2017 $(if $(wildcard results/zhou2017-literal/sweep.yaml),--literal results/zhou2017-literal) $(if $(wildcard results/zhou2017-literal-seed2/sweep.yaml),--other-seafloor results/zhou2017-literal-seed2) $(if $(wildcard results/zhou2017-anatomy/sweep.yaml),--anatomy results/zhou2017-anatomy) $(if $(wildcard results/seafloors/*/sweep.yaml),--seafloors results/seafloors) $(foreach d,$(wildcard results/zhou2017-literal-family*/sweep.yaml),--family $(dir $(d))) $(if $(wildcard results/zhou2017-fitted/sweep.yaml),--fitted results/zhou2017-fitted)

.PHONY: run test ci-check bench paper paper-literal anatomy report paper-report baseline predict methods ablations tempering kld monterey realism heldout-relief multibeam criterion seafloors literal-family fitted check-numpy scaling compile-stages clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

# install tanbench editable with the extras $(1): with uv (from PyPI, into the venv; on a fresh 2-core machine
# 26 s against pip's 72 s, the same packages), or with pip if uv cannot be had or fails; both compile the
# packages' bytecode, and compileall tanbench's own, so that no process compiles them again (with
# PYTHONDONTWRITEBYTECODE set, as on our machines, every process would: about 5 s of CPU for the CLI's imports)
RUN_EXTRAS  := plot,maps
TEST_EXTRAS := test,plot,maps,dask
PIP = $(BIN)/python -m pip install --quiet --disable-pip-version-check
install = (($(PIP) uv && $(BIN)/python -m uv pip install --quiet --compile-bytecode --python $(BIN)/python -e ".[$(1)]") \
	|| (echo "uv did not install; installing with pip" && $(PIP) -e ".[$(1)]")) \
	&& $(BIN)/python -m compileall -q tanbench > /dev/null

$(VENV)/.installed-run: pyproject.toml | $(BIN)/python
	$(call install,$(RUN_EXTRAS))
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(call install,$(TEST_EXTRAS))
	touch $@ $(VENV)/.installed-run

## run: the default sweep (configs/quick.yaml) on the built-in synthetic terrain; prints its tables
run: $(VENV)/.installed-run
	$(TB) run configs/quick.yaml
	@echo "tanbench is installed in $(VENV): 'source $(VENV)/bin/activate' puts it on PATH (or type $(TB))"

## test: the test suite (spread over the machine's cores by pytest-xdist), then `make ci-check`
test: $(VENV)/.installed-test
	$(BIN)/python -m pytest -n auto --durations=25
	$(MAKE) --no-print-directory ci-check

## ci-check: only the CI regression sweep (configs/ci.yaml) and its check against the committed results/ci-baseline:
## per method pooled over the cells, lost runs and accuracy (mean, p90) tested separately, failing on a regression
## or on a row that could not have seen its margin (docs/results.md, "Verdicts" and "The CI design")
CI_CHECK_OPTIONS = --pool method --margin-rel 0.10 --margin-abs 0 --lost-detect 0.05
ci-check: $(VENV)/.installed-run
	$(TB) run configs/ci.yaml --out results/ci --force --quiet --series none
	$(TB) check results/ci results/ci-baseline $(CI_CHECK_OPTIONS) --report results/ci/check.md

## baseline: refresh results/ci-baseline after a deliberate change (say why in the commit message)
baseline: $(VENV)/.installed-run
	rm -rf results/ci-baseline
	$(TB) run configs/ci.yaml --out results/ci-baseline --quiet

## paper: reproduce Zhou et al. 2017 into results/zhou2017 (runs, tables, figures, REPORT.md)
paper: $(VENV)/.installed-run
	rm -rf results/zhou2017
	$(TB) run configs/zhou2017.yaml --out results/zhou2017 --quiet
	$(TB) plot results/zhou2017
	$(PAPER_REPORT)

## paper-literal: the whole study as the paper's text describes it (profile zhou2017-literal) into results/zhou2017-literal (runs, tables, REPORT.md;
## `tanbench plot results/zhou2017-literal` draws its figures, not committed to keep results/ small)
## and the literal profile on another seafloor (results/zhou2017-literal-seed2); then refreshes results/zhou2017/REPORT.md if present.
## Resumes: stored runs are reused only where their identity (cell key, seeds, map hash) matches; rm -rf the directories to recompute.
paper-literal: $(VENV)/.installed-run
	$(TB) run configs/zhou2017-literal.yaml --out results/zhou2017-literal --quiet
	$(TB) tables results/zhou2017-literal --compare-paper > results/zhou2017-literal/tables.md
	$(TB) report results/zhou2017-literal --discussion none
	$(TB) run configs/zhou2017-literal-seed2.yaml --out results/zhou2017-literal-seed2 --quiet
	if [ -f results/zhou2017/sweep.yaml ]; then $(MAKE) --no-print-directory paper-report; fi

## criterion: the reproduction criterion's pass probabilities under a faithful copy of the paper, simulated from
## the paper's numbers alone (docs/model.md section 11) into results/criterion/CRITERION.md and faithful.csv
criterion: $(VENV)/.installed-run
	$(TB) criterion --out results/criterion/CRITERION.md

## seafloors: the literal and recommended profiles on 5 more synthetic seafloors (configs/seafloors/, docs/model.md
## section 11.1; 20 runs per cell, no series) into results/seafloors/<name>. Resumes like paper-literal.
SEAFLOORS := $(sort $(wildcard configs/seafloors/*.yaml))
seafloors: $(VENV)/.installed-run
	for f in $(SEAFLOORS); do $(TB) run $$f --out results/seafloors/$$(basename $$f .yaml) --series none --quiet || exit 1; done
	if [ -f results/zhou2017/sweep.yaml ]; then $(MAKE) --no-print-directory paper-report; fi

## literal-family: the literal profile with one other reading of the text at a time (docs/model.md section 11.2)
## into results/zhou2017-literal-family and results/zhou2017-literal-family-loose (20 runs, no series). Resumes.
literal-family: $(VENV)/.installed-run
	$(TB) run configs/zhou2017-literal-family-loose.yaml --out results/zhou2017-literal-family-loose --series none --quiet
	$(TB) run configs/zhou2017-literal-family.yaml --out results/zhou2017-literal-family --series none --quiet
	if [ -f results/zhou2017/sweep.yaml ]; then $(MAKE) --no-print-directory paper-report; fi

## fitted: the openly fitted profile (docs/model.md section 11.3): the grid of configs/zhou2017-fitted-fit.yaml over the
## Table 3-4 cells (15 runs, no series) into results/zhou2017-fitted-fit, scored by `tanbench fit-profile` (FIT.md, scores.csv;
## it stops if tanbench/profiles.py does not hold the selection), then the whole study under profile zhou2017-fitted
## (50 runs, no series) into results/zhou2017-fitted, judged on the held-out tables in REPORT.md. Resumes.
fitted: $(VENV)/.installed-run
	$(TB) run configs/zhou2017-fitted-fit.yaml --out results/zhou2017-fitted-fit --series none --quiet --workers 2
	$(TB) fit-profile results/zhou2017-fitted-fit
	$(TB) run configs/zhou2017-fitted.yaml --out results/zhou2017-fitted --series none --quiet --workers 2
	$(TB) tables results/zhou2017-fitted --compare-paper > results/zhou2017-fitted/tables.md
	if [ -f results/zhou2017/sweep.yaml ]; then $(MAKE) --no-print-directory paper-report; fi

## anatomy: the literal profile with one mechanism switched at a time (configs/zhou2017-anatomy.yaml) into results/zhou2017-anatomy
## (final errors only, no series), its table in results/zhou2017-anatomy/ANATOMY.md. Resumes like paper-literal.
anatomy: $(VENV)/.installed-run
	$(TB) run configs/zhou2017-anatomy.yaml --out results/zhou2017-anatomy --series none --quiet
	$(TB) anatomy results/zhou2017-anatomy > results/zhou2017-anatomy/ANATOMY.md
	if [ -f results/zhou2017/sweep.yaml ]; then $(MAKE) --no-print-directory paper-report; fi

## predict: terrain suitability maps (results/suitability) and prediction vs outcome over the committed
## sweeps (results/prediction: Spearman correlations of suitability and PCRB with the errors, scatter figure)
predict: $(VENV)/.installed-run
	$(TB) terrain suitability configs/zhou2017.yaml --out results/suitability --track
	$(TB) terrain suitability configs/monterey.yaml --out results/suitability --track
	$(TB) predict results/zhou2017 results/monterey --out results/prediction

## methods: every estimator (PFs, PMF, MPF, IEKF, TERCOM) over areas A, B and Monterey at three budgets
## into results/methods (tables with error statistics, divergence rate and filter wall time; the
## accuracy-cost figure results/methods/figures/accuracy_cost.png). RUNS=n overrides the sweep's 20.
methods: $(VENV)/.installed-run
	rm -rf results/methods
	$(TB) run configs/methods.yaml --out results/methods --quiet --workers 2 --series none $(if $(RUNS),--runs $(RUNS))
	$(TB) plot results/methods --frontier

## report: redraw results/zhou2017's figures and rewrite its REPORT.md from the stored runs
report: $(VENV)/.installed-run
	$(TB) plot results/zhou2017
	$(PAPER_REPORT)

## paper-report: rewrite results/zhou2017/REPORT.md only (with the literal profile and anatomy if present)
paper-report: $(VENV)/.installed-run
	$(PAPER_REPORT)

## ablations: area A defaults with one of tanbench's modelling or filter choices switched at a time
ablations: $(VENV)/.installed-run
	rm -rf results/zhou2017-ablations
	$(TB) run configs/zhou2017-ablations.yaml --out results/zhou2017-ablations --quiet --series none

# an ablation sweep whose tables are <cell>__<switch>: configs/$(1).yaml into results/$(1) afresh (no series), then
# its paired differences against the <cell>__$(2) tables (tanbench anatomy) in results/$(1)/ABLATION.md, titled $(3)
define ablation
	rm -rf results/$(1)
	$(TB) run configs/$(1).yaml --out results/$(1) --quiet --series none
	(echo "# $(3)"; echo; \
	 echo "## Final horizontal error (the counted statistic)"; echo; \
	 $(TB) anatomy results/$(1) --baseline $(2) --digits 2; \
	 echo "## Time-averaged horizontal error (reported, not counted)"; echo; \
	 $(TB) anatomy results/$(1) --baseline $(2) --column mean_horizontal_error_m --digits 2; \
	 echo "## Filter wall time, s (reported, not counted)"; echo; \
	 $(TB) anatomy results/$(1) --baseline $(2) --column filter_wall_s --digits 3) \
	 > results/$(1)/ABLATION.md
endef

## tempering: tight-dvl and tight-sbe with and without progressive correction (configs/tempering.yaml,
## docs/filters.md section 22) into results/tempering (no series); the paired differences in results/tempering/ABLATION.md
tempering: $(VENV)/.installed-run
	$(call ablation,tempering,off,Progressive correction against none (docs/filters.md section 22))

## kld: tight-dvl and tight-sbe with a fixed and an adaptive (KLD sampling) particle count (configs/kld.yaml,
## docs/filters.md section 23) into results/kld (no series); the paired differences in results/kld/ABLATION.md
kld: $(VENV)/.installed-run
	$(call ablation,kld,fixed,KLD sampling against a fixed particle count (docs/filters.md section 23))

## monterey: the methods over the real Monterey Canyon tiles in ../shared/data/monterey (read in place)
monterey: $(VENV)/.installed-run
	rm -rf results/monterey
	$(TB) run configs/monterey.yaml --out results/monterey --quiet

## realism: each everyday fault alone against the fault-free cell into results/realism (tables; no series: nothing plots them)
realism: $(VENV)/.installed-run
	rm -rf results/realism
	$(TB) run configs/realism.yaml --out results/realism --quiet --series none

## heldout-relief: issue 24's real-relief targets on held-out relief (docs/filters.md section 8): 24 windows of
## matplotlib's Jacksboro sample DEM (built under .cache/heldout-relief, never committed), tight-dvl, tight-sbe and
## loose-dvl at the recommended defaults, 10 runs each, into results/heldout-relief with SUMMARY.md
heldout-relief: $(VENV)/.installed-run
	rm -rf results/heldout-relief .cache/heldout-relief
	$(BIN)/python examples/prototypes/heldout_relief.py .cache/heldout-relief --all
	for f in .cache/heldout-relief/J*.yaml; do \
		$(TB) run $$f --out results/heldout-relief/$$(basename $$f .yaml) --quiet --series none --workers 2 || exit 1; \
	done
	$(BIN)/python examples/prototypes/heldout_relief.py --summary results/heldout-relief > results/heldout-relief/SUMMARY.md

## multibeam: accuracy and cost against the multibeam's beam count and swath angle (tight-mbe, pmf-mbe, tight-dvl) on
## areas A, B and Monterey into results/multibeam (summary series): tables, the accuracy-cost figure and the
## pre-registered comparisons (COMPARISONS.md; docs/multibeam.md section 5). RUNS=n overrides the sweep's 10.
multibeam: $(VENV)/.installed-run
	rm -rf results/multibeam
	$(TB) run configs/multibeam.yaml --out results/multibeam --quiet --workers 2 --series summary $(if $(RUNS),--runs $(RUNS))
	$(TB) plot results/multibeam --frontier
	$(BIN)/python examples/multibeam_comparisons.py results/multibeam > results/multibeam/COMPARISONS.md

## bench: speed of every method, numpy vs fast random numbers, kernels (printed, never asserted)
bench: $(VENV)/.installed-run
	$(TB) bench

## check-numpy: the CI sweep with filter.random_numbers: numpy (the run's numpy Generator instead of the default
## fast lanes), checked against results/ci-baseline: the generator leaves the statistics within Monte Carlo noise
check-numpy: $(VENV)/.installed-run
	$(TB) run configs/ci-numpy.yaml --out results/ci-numpy --force --quiet
	$(TB) check results/ci-numpy results/ci-baseline --ignore filter.random_numbers $(CI_CHECK_OPTIONS) --allow-underpowered --report results/ci-numpy/check.md

## scaling: wall time of configs/quick.yaml on 1 and 2 workers (run on an otherwise idle machine)
scaling: $(VENV)/.installed-run
	$(TB) run configs/quick.yaml --out results/scaling-1 --force --quiet --workers 1
	$(TB) run configs/quick.yaml --out results/scaling-2 --force --quiet --workers 2
	@$(BIN)/python -c "import json; w = [json.loads(open(f'results/scaling-{n}/sessions.jsonl').readlines()[-1])['wall_s'] for n in (1, 2)]; print(f'1 worker {w[0]:.1f} s, 2 workers {w[1]:.1f} s: {w[0] / w[1]:.2f}x')"

## compile-stages: record which kernels the tight and loose families both compile, and split them between the two
## side-by-side compile processes of a cold first run (tanbench/runner/compile_stages.json; docs/speed.md). Rerun
## after a change to the kernels' arguments: tests/test_first_run.py fails on a stale table.
compile-stages: $(VENV)/.installed-run
	$(BIN)/python -m tanbench.runner.compile_stages

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis results/quick results/ci results/ci-numpy results/scaling-1 results/scaling-2
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
