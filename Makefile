# Two set-up-free entry points: `make demo` (the main job) and `make test`.
# Each creates a local virtual environment in .venv and installs the package into it.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[dev,notebooks,dask]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/flexctrl study studies/quickstart.toml --out out/quickstart

# Every shipped description is validated (flexctrl check) before the tests run.
SHIPPED := $(sort $(wildcard models/*.toml controllers/*.toml studies/*.toml studies/*/*.toml studies/*/*/*.toml))

test: $(STAMP)
	$(BIN)/flexctrl check $(SHIPPED)
	$(BIN)/python -m pytest

clean:
	rm -rf $(VENV) out .flexctrl-cache
