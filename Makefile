# Two entry points for a fresh machine; each installs what it needs.
#   make demo   small four-rooms reproduction: prints a table, writes plots
#   make test   lint, type-check and the test suite (what CI runs)
#   make test-fast   the suite without the tests marked slow
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-fast lint install clean

# The studio's browser tests drive Debian's Chromium through Playwright (a dev
# dependency); nothing downloads a browser build. Installed once, with apt.
CHROMIUM := /usr/bin/chromium
SUDO     := $(if $(filter 0,$(shell id -u)),,sudo)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	# torch first, the CPU build: later requirements are ranges it satisfies
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(PY) recipes/four_rooms.py

lint: $(STAMP)
	$(PY) -m ruff check torchrl_subgoal recipes tests benchmarks
	$(PY) -m mypy

$(CHROMIUM):
	$(SUDO) apt-get update -qq
	$(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium

# two processes (pytest-xdist); the Ray tests share one (xdist_group) so two Ray
# instances never start at once
PYTEST := $(PY) -m pytest -q -n 2 --dist loadgroup

test: lint $(CHROMIUM)
	$(PYTEST)

# skip the longest end-to-end tests (marked slow) while developing; CI runs them all
test-fast: $(STAMP) $(CHROMIUM)
	$(PYTEST) -m "not slow"

clean:
	rm -rf $(VENV) results .pytest_cache .mypy_cache .ruff_cache
