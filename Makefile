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

.PHONY: help install robot robots check-generated test bench demo clean

help:
	@echo "make demo | make test | make robot ROBOT=<name> | make robots | make check-generated | make bench"

$(VENV)/bin/python:
	$(PYTHON) -m venv $(VENV)

# (re)install when pyproject.toml changes
$(STAMP): pyproject.toml $(if $(VIRTUAL_ENV),,$(VENV)/bin/python)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[test,plots]"
	@touch $@

install: $(STAMP)

robot: $(STAMP)
	$(PY) -m symoro_gen generate $(ROBOT)

robots: $(STAMP)
	@set -e; for f in robots/*.toml; do $(PY) -m symoro_gen generate $$(basename $$f .toml); done

check-generated: $(STAMP)
	@set -e; tmp=$$(mktemp -d); \
	for f in robots/*.toml; do $(PY) -m symoro_gen --quiet generate $$(basename $$f .toml) --out $$tmp; done; \
	if diff -r --exclude=__pycache__ --exclude=_build generated $$tmp; then echo "generated/ matches the generator"; rm -rf $$tmp; \
	else echo "generated/ differs from the generator: run 'make robots' and commit"; rm -rf $$tmp; exit 1; fi

test: $(STAMP)
	OPENBLAS_NUM_THREADS=1 $(PY) -m pytest -q

bench: $(STAMP)
	$(PY) bench/run_all.py

demo: $(STAMP)
	$(PY) -m symoro_gen demo

clean:
	rm -rf $(VENV) .venv-active.stamp .pytest_cache build *.egg-info
