# Two commands: `make run` (the thesis baseline on 2 MPI ranks) and `make test`.
# Both set everything up on a fresh Debian 12 machine (idempotent, seconds when done);
# with PETSC_DIR/SLEPC_DIR set (or without dpkg) they use your own stack (docs/install.md).
# `make test` also needs ParaView's pvbatch (Debian: python3-paraview, installed by
# setup-test); RAILVIB_SKIP_PARAVIEW=1 skips the ParaView checks (CI never sets it).
VENV    ?= .venv
PY      := $(VENV)/bin/python
NP      ?= 2
CASE    ?= jobs/thesis_baseline.toml
OUT     ?= results/thesis_baseline
# Open MPI refuses to run as root unless told; harmless otherwise.
export OMPI_ALLOW_RUN_AS_ROOT := 1
export OMPI_ALLOW_RUN_AS_ROOT_CONFIRM := 1
# Oversubscription keeps `-n 2` working on 1-core CI machines.
MPIRUN  ?= mpirun --oversubscribe -n $(NP)

.PHONY: setup setup-test run thesis test test-serial test-mpi lint bench clean docs

setup:
	@bash tools/setup.sh

setup-test:
	@bash tools/setup.sh --test

run: setup
	$(MPIRUN) $(PY) -m railvib_hpc run $(CASE) --out $(OUT)

# The thesis-vs-project table: 300 modes and the 57.87 Hz band, with and without the drop.
thesis: setup
	$(MPIRUN) $(PY) -m railvib_hpc study thesis jobs/thesis_comparison.toml --out results/studies

# A hung collective must fail the run, not eat the CI budget: each pass has a time limit.
TIMEOUT ?= timeout --signal=KILL 1500

test: setup-test
	$(TIMEOUT) $(PY) -m pytest -q
	$(TIMEOUT) $(MPIRUN) $(PY) -m pytest -q -m mpi -p no:cacheprovider

test-serial: setup-test
	$(TIMEOUT) $(PY) -m pytest -q

test-mpi: setup
	$(TIMEOUT) $(MPIRUN) $(PY) -m pytest -q -m mpi -p no:cacheprovider

# ruff, then the layer order and the ban on import cycles (.importlinter)
lint: setup
	$(VENV)/bin/ruff check railvib_hpc tests bench examples tools
	$(VENV)/bin/lint-imports --no-cache

docs: setup
	$(PY) -m railvib_hpc.docs

bench: setup
	$(PY) bench/mesh_bench.py

clean:
	rm -rf results .pytest_cache
