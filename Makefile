# One command each on a fresh machine with Python 3.11: `make demo` and `make test`.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export HOME ?= /tmp
export MPLBACKEND ?= Agg

.PHONY: setup demo test test-noble bench lint clean

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

# The library (everything but the ROS shell) on the versions Jazzy users have from Ubuntu
# 24.04: python3-numpy 1.26.4, python3-opencv 4.6.0, python3-matplotlib 3.6.3, python3-yaml
# 6.0.1. No ROS here: the tests marked `ros` are left out, and so are the linters (the ament
# linter test modules import the linters when they are collected).
NOBLE_VENV ?= .venv-noble
NOBLE_PY := $(NOBLE_VENV)/bin/python
NOBLE_STAMP := $(NOBLE_VENV)/.installed
NOBLE_PINS := numpy==1.26.4 opencv-python-headless==4.6.0.66 matplotlib==3.6.3 pyyaml==6.0.1

$(NOBLE_STAMP): Makefile
	$(PYTHON) -m venv $(NOBLE_VENV)
	$(NOBLE_PY) -m pip install --quiet --upgrade pip
	$(NOBLE_PY) -m pip install --quiet $(NOBLE_PINS) pytest pytest-timeout hypothesis
	touch $(NOBLE_STAMP)

test-noble: $(NOBLE_STAMP)
	PYTHONPATH=$(CURDIR) $(NOBLE_PY) -m pytest -q -m 'not ros and not linter' \
		--ignore=test/test_flake8.py --ignore=test/test_pep257.py test

bench: $(STAMP)
	$(PY) -m mlofc_tools.bench all

lint: $(STAMP)
	$(PY) -m pytest -q -m linter test

clean:
	rm -rf $(VENV) $(NOBLE_VENV) build *.egg-info .pytest_cache
