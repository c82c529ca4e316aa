# Set-up and checks. `make demo` and `make test` are the only two commands a fresh clone needs.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.install-stamp
# robosuite 1.5.2 pins mink==0.0.5 -> numpy<2, which conflicts with lerobot (numpy>=2); mink is an
# optional import, so robosuite goes in with --no-deps and pyproject.toml lists its real needs.
ROBOSUITE := robosuite==1.5.2
PYTEST_ARGS ?=
export MUJOCO_GL ?= egl

.PHONY: install test lint format demo demo-rgbd mutation clean

install: $(STAMP)

$(STAMP): pyproject.toml Makefile
	@if ! [ -x $(PY) ] || ! $(PY) -c 'import sys; sys.exit(sys.version_info < (3, 12))' 2>/dev/null; then \
	  python=$$(scripts/find_python.sh) || exit 1; \
	  echo "creating $(VENV) with $$python"; rm -rf $(VENV); "$$python" -m venv $(VENV) || exit 1; \
	fi
	$(PY) -m pip install -q --disable-pip-version-check --upgrade pip
	$(PY) -m pip install -q --disable-pip-version-check -e '.[dev,distributed]'
	$(PY) -m pip install -q --disable-pip-version-check --no-deps $(ROBOSUITE)
	@touch $(STAMP)

# One pytest-xdist worker per core, at most 4 (each holds torch, LeRobot and a subprocess); PYTEST_ARGS="-n 0"
# runs in one process, e.g. to debug one test.
test: install
	$(PY) -m pytest -n auto --maxprocesses=4 $(PYTEST_ARGS)

lint: install
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

format: install
	$(VENV)/bin/ruff check --fix .
	$(VENV)/bin/ruff format .

demo: install
	$(PY) scripts/demo.py

# From pixels only (64x64 RGB-D images, the policy's default keys and settings with cameras), 10,000 env steps.
demo-rgbd: install
	$(PY) scripts/demo.py --preset=rgbd

# Mutation testing (mutmut, the `mutation` extra) of the learning core, the encode-once path, the replay buffer and the online
# trainer's batch assembly against their fast tests; settings in pyproject.toml [tool.mutmut]. Not part of
# `make test`: it runs every mutant (about 1900; docs/results/mutation.json). mutmut keeps its verdicts in
# mutants/ and reruns the mutants of changed functions only, not those whose tests changed: after a test
# change, `rm -rf mutants` first. Report: docs/results/mutation.json (+ mutation.md, the argued survivors).
MUTATION_JOBS ?= 2
mutation: install
	$(PY) -m pip install -q --disable-pip-version-check -e '.[mutation]'
	OMP_NUM_THREADS=1 $(VENV)/bin/mutmut run --max-children $(MUTATION_JOBS)
	$(PY) -m benchmarks.mutation.run

clean:
	rm -rf $(VENV) outputs mutants .pytest_cache .ruff_cache
