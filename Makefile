# Two entry points for a fresh machine; each installs what it needs.
#   make demo   small four-rooms reproduction: prints a table, writes plots
#   make test   lint, type-check and the test suite (what CI runs)
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test lint install clean

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

test: lint $(CHROMIUM)
	$(PY) -m pytest -q

clean:
	rm -rf $(VENV) results .pytest_cache .mypy_cache .ruff_cache
