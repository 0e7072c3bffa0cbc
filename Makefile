# rover-sim: `make demo` and `make test` each set up .venv on first use.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
DOCS_STAMP := $(VENV)/.docs-installed
export MUJOCO_GL ?= egl

.PHONY: demo test test-all bench lint docs clean setup

setup: $(STAMP)

$(STAMP): pyproject.toml constraints.txt
	@test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -c constraints.txt -e '.[test,dask]'
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/rover-sim check-gl
	$(BIN)/rover-sim demo --out runs/demo

test: $(STAMP)
	$(BIN)/python -m pytest -q

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m ''

bench: $(STAMP)
	$(BIN)/rover-sim bench slip --json runs/bench/slip.json

# the documentation site: generated pages (scenario catalogue, CLI, benchmark tables) then a strict build
$(DOCS_STAMP): $(STAMP)
	$(BIN)/python -m pip install -q -c constraints.txt -e '.[docs]'
	@touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	$(BIN)/python scripts/gen_docs.py
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict -d runs/site

lint: $(STAMP)
	$(BIN)/ruff check rover_sim nav terrains tests

clean:
	rm -rf $(VENV) runs .pytest_cache build *.egg-info
