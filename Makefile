# Two entry points for a new user:
#   make run    create .venv, install the package, run the whole pipeline (python -m pipeline run)
#   make test   create .venv, install with dev extras (+ chromium for the viewer test), run pytest
#   make lint   check the package's layers (import-linter contracts in pyproject.toml)
#   make test-slow   the checks behind the `slow` marker (whole-pipeline runs, paper studies; CI runs both);
#                    the paper-scale `study` set is left out: .venv/bin/python -m pytest -m study
#   make typecheck   mypy on the package; fails when a file has more errors than tools/mypy_baseline.json
# Options: make run ARGS="--config configs/quick.yaml --set seed=3"   make test PYTEST_ARGS="tests/test_cli.py -x"
# Installs are redone only when pyproject.toml changes (stamp files in .venv/).

PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
ARGS ?=
PYTEST_ARGS ?=
# pytest workers (pytest-xdist): one per core of the 2-core machines this is measured on; worksteal:
# an idle worker takes queued tests from the busy one, so one long test at the end does not hold the run
PYTEST_WORKERS ?= 2
# one BLAS thread: reproducible numbers (see pipeline/__init__.py)
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
# Python's bytecode cache (__pycache__, git-ignored) is written: with PYTHONDONTWRITEBYTECODE set, as in
# some containers, every test worker and every CLI child compiles the package again and pytest rewrites
# every test module again (collection 12.7 s -> 5.6 s per worker on the 2-core machine)
unexport PYTHONDONTWRITEBYTECODE

.PHONY: run test test-slow lint typecheck

run: $(VENV)/.stamp-run
	$(PY) -m pipeline run $(ARGS)

lint: $(VENV)/.stamp-dev
	$(VENV)/bin/lint-imports

test: $(VENV)/.stamp-dev
	@command -v chromium >/dev/null 2>&1 || [ -x /usr/bin/chromium ] || { \
	  echo "chromium not found: installing it with apt (for the meshcat viewer test)"; \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	      || echo "warning: could not install chromium; the viewer screenshot test will be skipped"; \
	  elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null && command -v apt-get >/dev/null 2>&1; then \
	    (sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null) \
	      || echo "warning: could not install chromium; the viewer screenshot test will be skipped"; \
	  else echo "warning: no chromium and no root/apt; the viewer screenshot test will be skipped"; fi; }
	$(PY) -m pytest -n $(PYTEST_WORKERS) --dist worksteal --durations=15 $(PYTEST_ARGS)

test-slow: $(VENV)/.stamp-dev
	$(PY) -m pytest -n $(PYTEST_WORKERS) --dist worksteal --durations=15 -m 'slow and not study' $(PYTEST_ARGS)

typecheck: $(VENV)/.stamp-dev
	$(PY) tools/mypy_ratchet.py

$(PY):
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' \
	  || { echo "error: Python >= 3.11 needed ($(PYTHON) is $$($(PYTHON) --version))"; exit 1; }
	$(PYTHON) -m venv $(VENV)

# The install: uv (PyPI's `uv`, a resolver and installer written in Rust) installs the same releases
# as pip, downloads included, in about 8 s instead of pip's 68 s on the 2-core machine; where uv
# cannot be had, pip installs. Modules are byte-compiled when first imported (__pycache__ is written,
# see above): about 6 s for what a run imports, where compiling all of the venv's 7,000 modules
# ahead takes 22 s.
PIP := $(PY) -m pip --quiet --disable-pip-version-check
define INSTALL
echo "installing the package ($(1)) and its dependencies into $(VENV)"; \
if $(PIP) install --no-compile uv >/dev/null 2>&1; then \
  $(VENV)/bin/uv pip install --quiet --python $(PY) $(1); \
else echo "uv not available: installing with pip"; $(PIP) install --no-compile $(1); fi
endef

$(VENV)/.stamp-run: pyproject.toml | $(PY)
	@$(call INSTALL,-e .)
	@touch $@

$(VENV)/.stamp-dev: pyproject.toml | $(PY)
	@$(call INSTALL,-e '.[dev]')
	@touch $@ $(VENV)/.stamp-run
