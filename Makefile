# Two entry points for a fresh machine; each installs what it needs.
#   make demo   small four-rooms reproduction: prints a table, writes plots
#   make test   lint, type-check, the docs site, the install check and the test suite (what CI runs)
#   make install-check   the built wheel in venvs outside the repository (core alone; with extras)
#   make test-fast   the suite without the tests marked slow
#   make docs   the documentation site (strict: any warning fails) into site/
#   make bench-docs   run the benchmarks at a quick scale and regenerate docs/benchmarks.md
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-fast lint docs bench-docs install install-check clean

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
	$(VENV)/bin/torchrl-subgoal reproduce four-rooms

SOURCES := torchrl_subgoal recipes tests benchmarks tools docs/tutorials

lint: $(STAMP)
	$(PY) -m ruff format --check $(SOURCES)
	$(PY) -m ruff check $(SOURCES)
	$(PY) -m mypy

# MkDocs + Material + mkdocstrings (the docs extra, part of dev); --strict turns every
# warning (a broken link, an unparsable docstring) into a failure. Nothing is fetched.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(PY) -m mkdocs build --strict --site-dir site

# The package as a user installs it: the wheel, built from this tree, in two venvs outside the
# repository (kept in $(CHECK_VENVS) and reused; the first run creates them, ~10 min of downloads):
# the core alone imports and runs the README snippet without numba, pandas or matplotlib; with
# the experiments and tensorboard extras, `torchrl-subgoal train` and `report` run and log.
CHECK_VENVS ?= $(or $(TMPDIR),/tmp)/torchrl_subgoal-install-check

install-check: $(STAMP)
	$(PY) tools/check_install.py --venvs $(CHECK_VENVS)

bench-docs: $(STAMP)
	$(PY) benchmarks/docs_page.py docs/benchmarks.md

$(CHROMIUM):
	$(SUDO) apt-get update -qq
	$(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium

# two processes (pytest-xdist); the Ray tests share one (xdist_group) so two Ray
# instances never start at once
PYTEST := $(PY) -m pytest -q -n 2 --dist loadgroup

test: lint docs install-check $(CHROMIUM)
	$(PYTEST)

# skip the longest end-to-end tests (marked slow) while developing; CI runs them all
test-fast: $(STAMP) $(CHROMIUM)
	$(PYTEST) -m "not slow"

clean:
	rm -rf $(VENV) results site .pytest_cache .mypy_cache .ruff_cache
