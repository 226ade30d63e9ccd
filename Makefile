# fjm: every target creates and uses a local venv (.venv) from pyproject.toml by itself.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
MODELS ?=

.PHONY: help venv derive check-generated test demo bench clean identify-demo

help:
	@echo "make demo             derive if needed, simulate the paper's cases, write figures to out/"
	@echo "make test             run the test suite"
	@echo "make derive           regenerate generated/ (MODELS=\"link1 planar2\" for a subset)"
	@echo "make check-generated  fail if generated/ is stale"
	@echo "make bench            benchmarks -> bench/results.json"
	@echo "make identify-demo    fjm excite -> MuJoCo log -> fjm identify -> controller on the TRUE plant (link1, Panda)"

LOG    := $(VENV)/install.log

# Quiet install: one line on the terminal, pip's output in $(LOG) (its tail is printed on failure).
$(STAMP): pyproject.toml
	@echo "installing fjm into $(VENV) (log: $(LOG))"
	@$(PYTHON) -m venv $(VENV) > /dev/null 2>&1 || { echo "error: '$(PYTHON) -m venv $(VENV)' failed (python3 -m venv missing? on Debian/Ubuntu: apt install python3-venv)"; exit 1; }
	@{ $(PY) -m pip install -q --upgrade pip && $(PY) -m pip install -q -e '.[dev,bench]'; } > $(LOG) 2>&1 \
	  || { echo "error: pip install failed; last lines of $(LOG):"; tail -n 30 $(LOG); exit 1; }
	@touch $(STAMP)

venv: $(STAMP)

derive: $(STAMP)
	$(PY) -m derive $(if $(MODELS),--models $(MODELS))

check-generated: $(STAMP)
	PYTHONHASHSEED=0 $(PY) -m derive --check
	PYTHONHASHSEED=12345 $(PY) -m derive --check

# one file per worker at a time (module fixtures built once), costliest files first (tests/conftest.py)
test: $(STAMP)
	$(PY) -m pytest -q -n auto --dist loadfile --no-loadscope-reorder

demo: $(STAMP)
	$(PY) -m fjm_runtime.cli figures --out out
	@echo
	@echo "outputs: out/ (figures *.png, every number in out/summary.md)"
	@echo "run fjm: $(VENV)/bin/fjm --help   (or: source $(VENV)/bin/activate, then fjm --help)"

# python -m bench rewrites the marked numbers of README.md, docs/ and bench/README.md (bench/report.py).
bench: $(STAMP)
	$(PY) -m bench

# issue 29's round trip (docs/identification.md): link1 in seconds, the Panda in about a minute.
identify-demo: $(STAMP)
	$(PY) examples/identify_roundtrip.py link1 --duration 10
	$(PY) examples/identify_roundtrip.py panda --duration 20

clean:
	rm -rf $(VENV) out build dist *.egg-info
