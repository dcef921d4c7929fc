# One command each on a fresh machine with Python 3.11: `make demo` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export HOME ?= /tmp
export MPLBACKEND ?= Agg

.PHONY: setup demo test bench lint clean

$(STAMP): requirements-ros.txt requirements-dev.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -r requirements-ros.txt -r requirements-dev.txt
	$(PY) -m pip install --quiet --no-deps -e .
	touch $(STAMP)

setup: $(STAMP)

demo: $(STAMP)
	$(PY) -m mlofc_tools.demo

test: $(STAMP)
	$(PY) -m pytest -q test

bench: $(STAMP)
	$(PY) -m mlofc_tools.bench all

lint: $(STAMP)
	$(PY) -m pytest -q -m linter test

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache
