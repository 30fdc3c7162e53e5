# clutch-sim developer entry points.  `make test` works from a fresh clone on a machine
# with Python 3.11, gcc and cmake: it creates .venv, installs the pinned requirements,
# installs this project editable and builds the clutch_msgs ROS 2 interfaces into .venv.

SHELL := /bin/bash
.DEFAULT_GOAL := test

PYTHON ?= python3.11
VENV   := $(CURDIR)/.venv
VPY    := $(VENV)/bin/python
PYTEST_ARGS ?=
# pytest-xdist workers for `make test` (auto: one per core; 0 runs in this process)
PYTEST_WORKERS ?= auto
# with a worker per core, the libraries' own threads (numba's batches, OpenBLAS) only compete
# with the other workers for the cores and spin while they wait: one thread each
TEST_THREADS := $(if $(filter 0,$(PYTEST_WORKERS)),,NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1)

export PIP_DISABLE_PIP_VERSION_CHECK := 1

REQ_STAMP      := $(VENV)/.requirements.stamp
EDITABLE_STAMP := $(VENV)/.editable.stamp
# re-run the editable install when a top-level package appears (setuptools maps the
# packages found at install time)
PKG_INITS := $(wildcard clutch_model/__init__.py clutch_sim/__init__.py clutch_sim_ros/__init__.py)

.PHONY: venv test bench run clean distclean

venv: $(EDITABLE_STAMP)
	@bash tools/build_msgs.sh

$(VPY):
	@command -v $(PYTHON) > /dev/null || { echo "need $(PYTHON) (Python 3.11) on PATH" >&2; exit 1; }
	$(PYTHON) -m venv $(VENV)

$(REQ_STAMP): requirements.txt | $(VPY)
	$(VPY) -m pip install -r requirements.txt
	@touch $@

$(EDITABLE_STAMP): pyproject.toml $(PKG_INITS) $(REQ_STAMP)
	$(VPY) -m pip install --no-deps --no-build-isolation -e .
	@touch $@

test: venv
	@rc=0; $(TEST_THREADS) $(VPY) -m pytest -q -p no:cacheprovider -n $(PYTEST_WORKERS) --dist worksteal $(PYTEST_ARGS) || rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "make test: pytest collected no tests"; rc=0; fi; \
	exit $$rc

bench: venv
	@shopt -s nullglob; files=(bench/*.py); \
	if [ $${#files[@]} -eq 0 ]; then echo "make bench: no bench/*.py scripts"; exit 0; fi; \
	for f in "$${files[@]}"; do echo "== $$f"; $(VPY) "$$f" || exit 1; done

run: venv
	$(VPY) -m clutch_sim.demo

clean:
	rm -rf build dist .numba_cache .pytest_cache .hypothesis *.egg-info out
	find . -path ./.venv -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

distclean: clean
	rm -rf $(VENV)
