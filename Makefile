# Two commands do everything on a fresh machine:
#   make run    install, prepare the config's models, start the stack (Ctrl-C stops it)
#   make test   install, prepare the default model, lint, type-check and run every test
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
DEV_STAMP := $(VENV)/.installed-dev
CONFIG_ARG := $(if $(CONFIG),--config $(CONFIG))

.PHONY: setup model run credentials test lint unit integration benchmark clean

# What the stack needs to run: no test tools, no torch.
$(STAMP): pyproject.toml
	@echo "installing the runtime into $(VENV)" >&2
	@$(PYTHON) -m venv $(VENV)
	@$(PY) -m pip install --quiet --upgrade pip >&2
	@$(PY) -m pip install --quiet -e . >&2
	@touch $(STAMP)

# What the tests need on top.
# TrackEval (the tracking metrics of tools/tracking) without its requirements: they name
# opencv-python, whose cv2 would clash with opencv-python-headless's; its metrics need only
# numpy and scipy (docs/library-decisions.md).
$(DEV_STAMP): $(STAMP)
	$(PY) -m pip install --quiet -e '.[dev]'
	$(PY) -m pip install --quiet --no-deps 'trackeval==1.3.0'
	touch $(DEV_STAMP)

setup: $(STAMP) model

# Every model file the config needs (fetched, rebuilt at its input size, INT8, the fast
# profile's choice): the detector only loads them. The model's path goes to stderr: with
# `make run ARGS="--duration S"` stdout carries the run's JSON summary and nothing else.
model: $(STAMP)
	@$(PY) -m tools.detector prepare --config $(or $(CONFIG),deploy/stack.toml) >&2

run: setup
	@$(PY) -m deploy.supervisor $(CONFIG_ARG) $(ARGS)

credentials: $(STAMP)
	$(PY) -m deploy.credentials $(ARGS)

lint: $(DEV_STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy

# Two pytest workers (pytest-xdist): most integration tests wait on a real-time stack, so two
# at once fill a 2-core machine; TEST_WORKERS=0 runs one test at a time.
TEST_WORKERS ?= 2

test: $(DEV_STAMP) lint
	$(PY) -m tools.detector prepare
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist worksteal --durations=25

unit: $(DEV_STAMP)
	$(PY) -m pytest -q tests/unit

integration: $(DEV_STAMP)
	$(PY) -m tools.detector prepare
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist worksteal -m integration

benchmark: setup
	$(PY) -m tools.detector benchmark --runs 50

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache
