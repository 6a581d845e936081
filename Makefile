# Two commands do everything on a fresh machine:
#   make run    install, fetch the default model, start the stack (Ctrl-C stops it)
#   make test   install, fetch the default model, lint, type-check and run every test
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup model run credentials test lint unit integration benchmark clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

setup: $(STAMP) model

model: $(STAMP)
	$(PY) -m services.detector fetch-model

run: setup
	$(PY) -m deploy.supervisor $(if $(CONFIG),--config $(CONFIG)) $(ARGS)

credentials: $(STAMP)
	$(PY) -m deploy.credentials $(ARGS)

lint: $(STAMP)
	$(PY) -m ruff check .
	$(PY) -m mypy

test: setup lint
	$(PY) -m pytest -q

unit: $(STAMP)
	$(PY) -m pytest -q tests/unit

integration: setup
	$(PY) -m pytest -q -m integration

benchmark: setup
	$(PY) -m services.detector benchmark --runs 50

clean:
	rm -rf $(VENV) .mypy_cache .ruff_cache .pytest_cache
