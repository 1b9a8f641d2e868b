# tanbench: `make run` and `make test` work on a fresh clone with only Python installed.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
TB     := $(BIN)/tanbench

.PHONY: run test bench paper realism baseline clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(VENV)/.installed-run: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e ".[plot,maps]"
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e ".[test,plot,maps,dask]"
	touch $@ $(VENV)/.installed-run

## run: the default sweep (configs/quick.yaml) on the built-in synthetic terrain; prints its tables
run: $(VENV)/.installed-run
	$(TB) run configs/quick.yaml
	@echo "tanbench is installed in $(VENV): 'source $(VENV)/bin/activate' puts it on PATH (or type $(TB))"

## test: the test suite, then the CI regression sweep checked against the committed baseline
test: $(VENV)/.installed-test
	$(BIN)/python -m pytest
	$(TB) run configs/ci.yaml --out results/ci --force --quiet
	$(TB) check results/ci results/ci-baseline --report results/ci/check.md

## baseline: refresh results/ci-baseline after a deliberate change (say why in the commit message)
baseline: $(VENV)/.installed-run
	$(TB) run configs/ci.yaml --out results/ci-baseline --force --quiet

## paper: reproduce Zhou et al. 2017 into results/zhou2017 (runs, tables, figures, REPORT.md)
paper: $(VENV)/.installed-run
	$(TB) run configs/zhou2017.yaml --out results/zhou2017 --force --quiet
	$(TB) plot results/zhou2017
	$(TB) report results/zhou2017

## realism: each everyday fault alone against the fault-free cell into results/realism (tables)
realism: $(VENV)/.installed-run
	$(TB) run configs/realism.yaml --out results/realism --force --quiet

## bench: speed figures of the tight-dvl filter (printed, never asserted)
bench: $(VENV)/.installed-run
	$(TB) bench

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .hypothesis results/quick results/ci
	find . -name __pycache__ -type d -prune -exec rm -rf {} +
