# fdi-sim: the two commands are `make demo` and `make test`; both create .venv on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-slow bench venv clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)  ## fly the headline scenario, write an MCAP, print a summary
	$(VENV)/bin/fdi-sim run scenarios/f16_cruise_doublets.toml --out runs/demo

test: $(STAMP)  ## the default suite (under 15 min); long studies are marked slow
	$(PY) -m pytest -q tests

test-slow: $(STAMP)  ## only the long studies and reproductions
	$(PY) -m pytest -q -m slow tests

bench: $(STAMP)  ## speed as ratios against bare JSBSim, run on demand
	$(PY) -m pytest -q tests/benchmarks -p no:cacheprovider -o addopts="" --benchmark-disable-gc

clean:
	rm -rf $(VENV) runs .pytest_cache .benchmarks
