# symoro_gen — one command per job. `make test` / `make demo` create and use a local
# virtual environment (.venv) when none is active.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
ROBOT ?= lwr4

ifdef VIRTUAL_ENV
PY := python
STAMP := .venv-active.stamp
else
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
endif

.PHONY: help install robot robots check-generated test test-slow lint bench demo clean

help:
	@echo "make demo | make test | make test-slow | make lint | make robot ROBOT=<name> (generate + build) | make robots | make check-generated | make bench"

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)

# (re)install when pyproject.toml changes
$(STAMP): pyproject.toml $(if $(VIRTUAL_ENV),,$(VENV)/bin/python)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,plots]"
	@touch $@

install: $(STAMP)

# generate, then compile the C kernels (otherwise compiled on first use)
robot: $(STAMP)
	$(PY) -m symoro_gen generate $(ROBOT)
	$(PY) -m symoro_gen build $(ROBOT)

robots: $(STAMP)
	@set -e; for f in robots/*.toml; do $(PY) -m symoro_gen generate $$(basename $$f .toml); done

# every file of generated/ against a fresh generation, tool versions recorded in manifest.json excepted
check-generated: $(STAMP)
	$(PY) -m symoro_gen.emit.check

# the suite without the tests marked slow (many-seed simulations, the loop on real recordings): under 10 min
test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n auto --maxprocesses 4 -m "not slow"

# the tests marked slow (CI runs them after `make test`)
test-slow: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q -n auto --maxprocesses 4 -m slow

# ruff (style and likely bugs) and mypy (strict on the core packages), configured in pyproject.toml
lint: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy

bench: $(STAMP)
	$(PY) bench/run_all.py

demo: $(STAMP)
	$(PY) -m symoro_gen demo

clean:
	rm -rf $(VENV) .venv-active.stamp .pytest_cache build *.egg-info
