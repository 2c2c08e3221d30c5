# Two set-up-free entry points: `make demo` (the main job) and `make test`.
# Each creates a local virtual environment in .venv and installs the package into it.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test lint format docs figures clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev,notebooks,dask,docs]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/flexctrl study studies/quickstart.toml --out out/quickstart

# Every shipped description is validated (flexctrl check) before the tests run.  The suite
# runs on TEST_WORKERS processes (pytest-xdist), each test file whole on one of them so that
# a file's module fixtures are built once: on this 2-core machine 9.1 min against 16 min in
# one process.  `make test TEST_WORKERS=0` runs it in one process.  Each test process holds
# its BLAS libraries to one thread: NumPy and SciPy each start a pool per core, and two test
# processes on two cores spinning four pools slow each other (docs/explanation/studies.md, "Backends";
# warm compile cache, one after the other: 8:02 min, 788 s of CPU, against 8:45 min, 875 s).
TEST_WORKERS ?= 2
ONE_BLAS_THREAD := OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
DATA := src/flexctrl/data
SHIPPED := $(sort $(wildcard $(DATA)/models/*.toml $(DATA)/controllers/*.toml $(DATA)/studies/*.toml $(DATA)/studies/*/*.toml $(DATA)/studies/*/*/*.toml))

test: $(STAMP)
	$(BIN)/flexctrl check $(SHIPPED)
	$(ONE_BLAS_THREAD) $(BIN)/python -m pytest -n $(TEST_WORKERS) --dist loadfile

# ruff (lint and format check) and mypy, configured in pyproject.toml.
lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

# Rewrites the sources in the project's format (ruff format) and applies ruff's safe fixes.
format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# The documentation site, into docs/_build/html: warnings are errors, the notebooks executed
# (DOCS_QUICK=1 runs them on their reduced grids, as the tests do).
DOCS_QUICK ?= 0
docs: $(STAMP)
	cd docs && FLEXCTRL_NOTEBOOK_QUICK=$(DOCS_QUICK) FLEXCTRL_DOCS_EXECUTE=force \
		../$(BIN)/python -m sphinx -b html -W --keep-going -n -q . _build/html

# Redraw docs/figures/*.png from reduced studies (results kept in out/figures and resumed:
# about 15 minutes the first time on 2 busy cores, under a minute after; tools/make_figures.py
# lists what it runs).
figures: $(STAMP)
	$(BIN)/python tools/make_figures.py

clean:
	rm -rf $(VENV) out docs/_build docs/jupyter_execute
