# fdi-sim: the two commands are `make demo` and `make test`; both create .venv on first use.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-slow bench venv clean node-tools browser

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)  ## fly the headline scenario, write an MCAP, print a summary; then a fault with the FDI bank in the loop, and its review (HTML report)
	$(VENV)/bin/fdi-sim run scenarios/f16_cruise_doublets.toml --out runs/demo
	$(VENV)/bin/fdi-sim run scenarios/f16_pitch_gyro_bias.toml --log runs/demo/f16_pitch_gyro_bias.mcap --force
	$(VENV)/bin/fdi-sim detect runs/demo/f16_pitch_gyro_bias.mcap --bank scenario
	$(VENV)/bin/fdi-sim review runs/demo/f16_pitch_gyro_bias.mcap  # writes runs/demo/f16_pitch_gyro_bias.review.html

# node modules for tests/flightlog/test_foxglove.py (Foxglove's decoders), from the lock file
NODE_TOOLS := tools/foxglove/node_modules/.package-lock.json
$(NODE_TOOLS): tools/foxglove/package-lock.json
	@command -v npm >/dev/null || { echo "npm not found: tests/flightlog/test_foxglove.py will skip"; exit 0; }; \
	npm ci --prefix tools/foxglove --no-audit --no-fund && touch $@

node-tools: $(NODE_TOOLS)

# Debian's chromium for tests/review/test_browser.py (the report rendered in a real browser; playwright
# drives it, `playwright install` is never used). Installed with apt-get when root; otherwise the
# command is printed and the browser tests skip, saying why.
CHROMIUM := /usr/bin/chromium
browser:
	@if [ -x $(CHROMIUM) ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  echo "installing Debian's chromium for the browser tests (apt-get)"; \
	  DEBIAN_FRONTEND=noninteractive apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium; \
	else \
	  echo "$(CHROMIUM) not found: tests/review/test_browser.py will skip;" \
	       "install it with: sudo apt-get install -y chromium"; \
	fi

test: $(STAMP) node-tools browser  ## the default suite (under 15 min); long studies are marked slow
	$(PY) -m pytest -q -n 2 --dist loadfile --durations=15 tests  # two workers (CI has 2 cores); a file stays on one worker (module fixtures)

test-slow: $(STAMP)  ## only the long studies and reproductions
	$(PY) -m pytest -q -m slow tests

bench: $(STAMP)  ## speed as ratios against bare JSBSim, run on demand
	$(PY) -m pytest -q tests/benchmarks -p no:cacheprovider -o addopts="" --benchmark-disable-gc

clean:
	rm -rf $(VENV) runs .pytest_cache .benchmarks
