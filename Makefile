# fjm: every target creates and uses a local venv (.venv) from pyproject.toml by itself.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
MODELS ?=

.PHONY: help venv derive check-generated test demo bench clean

help:
	@echo "make demo             derive if needed, simulate the paper's cases, write figures to out/"
	@echo "make test             run the test suite"
	@echo "make derive           regenerate generated/ (MODELS=\"link1 planar2\" for a subset)"
	@echo "make check-generated  fail if generated/ is stale"
	@echo "make bench            benchmarks -> bench/results.json"

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev,bench]'
	@touch $(STAMP)

venv: $(STAMP)

derive: $(STAMP)
	$(PY) -m derive $(if $(MODELS),--models $(MODELS))

check-generated: $(STAMP)
	PYTHONHASHSEED=0 $(PY) -m derive --check
	PYTHONHASHSEED=12345 $(PY) -m derive --check

test: $(STAMP)
	$(PY) -m pytest -q

demo: $(STAMP)
	$(PY) -m fjm_runtime.cli figures --out out

bench: $(STAMP)
	$(PY) -m bench

clean:
	rm -rf $(VENV) out build dist *.egg-info
