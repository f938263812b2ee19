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

.PHONY: setup setup-test run thesis test test-slow test-kernels test-all test-serial test-mpi lint bench clean docs

setup:
	@bash tools/setup.sh

setup-test:
	@bash tools/setup.sh --test

run: setup
	$(MPIRUN) $(PY) -m railvib_hpc run $(CASE) --out $(OUT)

# The thesis-vs-project table: 300 modes and the 57.87 Hz band, with and without the drop.
thesis: setup
	$(MPIRUN) $(PY) -m railvib_hpc study thesis jobs/thesis_comparison.toml --out results/studies

# Two tiers. `make test` (the README's test command) is the quick tier: every test not marked
# `slow` on one rank each, in NP pytest-xdist worker processes (file by file, so a module's
# fixtures are built once), and then the `-m mpi` ones under mpirun -n 2; under 12 min on an
# idle 2-core machine (measured: 456 s for the one-rank pass with the other core busy; 647 s
# in one process). `make test-slow` runs the long physics and end-to-end checks (`-m slow`): serially
# the ones not marked `mpi`, and the `mpi` ones under mpirun -n 2 only (most compare N ranks
# with one, which a serial run cannot). CI (.ci/run) runs both tiers.
# Hangs are caught per test by pytest-timeout (pyproject.toml: `timeout`, thread method: a
# hung collective dumps every stack and ends the pass), with a limit far above any test's own
# time, not by a pass-wide kill near the total. PYTEST_ARGS adds options (e.g. --durations=20).
PYTEST   = $(PY) -m pytest -q $(PYTEST_ARGS)
# The one-rank passes in NP worker processes (pytest-xdist; each worker is its own MPI world of
# one rank); XDIST= runs them in one process. Files are handed out longest first
# (tests/conftest.py sorts them by tests/data/test_weights.json, tools/test_weights.py),
# not by xdist's count of tests per file.
XDIST   ?= -n $(NP) --dist loadfile --no-loadscope-reorder
# One BLAS/OpenMP thread per worker process and per MPI rank: NP workers or ranks already fill
# NP cores, and OpenBLAS's own threads on top of them oversubscribe the cores (a dense eigh of
# 2,745 took 10.3 s with the default threads against 7.3 s with one, the machine loaded; the
# 2-rank modal track-ends test 55.0 s against 50.1 s, idle). An exported value wins.
OPENBLAS_NUM_THREADS ?= 1
OMP_NUM_THREADS ?= 1
WORKERS  = OPENBLAS_NUM_THREADS=$(OPENBLAS_NUM_THREADS) OMP_NUM_THREADS=$(OMP_NUM_THREADS)
# pytest's exit code 5 ("no test collected") is not a failure of a tier that selects none.
ALLOW_EMPTY = || [ $$? -eq 5 ]

test: setup-test
	$(WORKERS) $(PYTEST) $(XDIST) -m "not slow"
	$(WORKERS) $(MPIRUN) $(PYTEST) -m "mpi and not slow" -p no:cacheprovider

test-slow: setup-test
	$(WORKERS) $(PYTEST) $(XDIST) -m "slow and not mpi" $(ALLOW_EMPTY)
	$(WORKERS) $(MPIRUN) $(PYTEST) -m "mpi and slow" -p no:cacheprovider $(ALLOW_EMPTY)

test-serial: setup-test
	$(WORKERS) $(PYTEST) $(XDIST) -m "not slow"

test-mpi: setup
	$(WORKERS) $(MPIRUN) $(PYTEST) -m "mpi and not slow" -p no:cacheprovider

# The numerically sensitive files (eigensolvers and their verdicts, derived tolerances,
# dispersion relations, stability limits, factorisations, the modal reductions) under the
# BLAS kernels of other CPUs: Debian's OpenBLAS picks its kernel per CPU and
# OPENBLAS_CORETYPE runs another's here (tools/test_kernels.sh: the CPU's own kernel, and
# one it cannot run, are skipped with a line saying so). Their quick tier, in NP workers,
# once per kernel: 341 tests, 56 s of CPU per kernel in one process (measured). CI
# (.ci/run) runs it after the two tiers (docs/verification.md).
KERNELS ?= SkylakeX Haswell Sandybridge
# A BLAS on several threads splits its sums otherwise again: the eigensolvers' verdicts
# once more with two threads, the CPU's own kernel, in one process (a two-band merge's pair
# came out at 1.549e-10 on two threads against tol + floor = 1.41e-10; within it on one).
THREADED_BLAS ?= 2
THREADED_TESTS ?= tests/modal/test_bands.py tests/modal/test_modal_honesty.py \
  tests/modal/test_modal_verification.py tests/reliability/test_redteam_modal.py
KERNEL_TESTS ?= tests/modal/test_bands.py tests/modal/test_modal_energy.py \
  tests/modal/test_modal_honesty.py tests/modal/test_modal_verification.py \
  tests/modal/test_partial_mesh.py tests/test_tolerances.py \
  tests/fem/test_fem_modes.py tests/fem/test_fem_beam_modes.py tests/fem/test_fem_soil_column.py \
  tests/fem/test_fem_hex8.py tests/fem/test_fem_beam_element.py tests/fem/test_dispersion.py \
  tests/fem/test_dispersion_rayleigh.py tests/fem/test_matrix_free.py \
  tests/fem/test_fem_assemble.py tests/fem/test_fem_spring.py tests/fem/test_fem_winkler.py \
  tests/fem/test_fem_track_receptance.py tests/fem/test_halfspace.py tests/fem/test_pml_kernel.py \
  tests/mesh/test_dispersion_check.py tests/mesh/test_mesh_checks.py \
  tests/transient/test_explicit.py tests/transient/test_imex.py \
  tests/transient/test_verification.py tests/transient/test_engine_energy.py \
  tests/transient/test_dispersion_engines.py tests/transient/test_modal_full_damping.py \
  tests/transient/test_damping_operator.py tests/transient/test_static_start.py \
  tests/mbs/test_mbs_static_correction.py tests/mbs/test_mbs_modal_input.py \
  tests/mbs/test_mbs_coupling.py tests/mbs/test_mbs_contact.py tests/mbs/test_mbs_wheelset.py \
  tests/reliability/test_redteam_modal.py tests/uncertainty/test_reduced_model.py \
  tests/reconstruct/test_reconstruct_stress.py tests/studies/test_studies_richardson.py \
  tests/assess/test_assess_metrics.py tests/assess/test_assess_weighting.py \
  tests/assess/test_assess_standards.py

test-kernels: setup-test
	KERNELS="$(KERNELS)" $(WORKERS) bash tools/test_kernels.sh $(PY) -q $(PYTEST_ARGS) $(XDIST) \
	  -- $(KERNEL_TESTS)
	@echo "[test-kernels] the CPU's own kernel on $(THREADED_BLAS) BLAS threads: $(THREADED_TESTS)"
	OPENBLAS_NUM_THREADS=$(THREADED_BLAS) OMP_NUM_THREADS=1 $(PYTEST) -m "not slow and not mpi" \
	  -p no:cacheprovider $(THREADED_TESTS)

test-all: test test-slow test-kernels

# ruff, then the layer order and the ban on import cycles (.importlinter), then no function
# over 150 lines unless listed with its reason (tools/code_rules.py), then no stage module
# that calls the reuse, provenance or lock layer itself (tools/stage_rules.py)
lint: setup
	$(VENV)/bin/ruff check railvib_hpc tests bench examples tools
	$(VENV)/bin/lint-imports --no-cache
	$(PY) tools/code_rules.py
	$(PY) tools/stage_rules.py

docs: setup
	$(PY) -m railvib_hpc.docs

bench: setup
	$(PY) bench/mesh_bench.py

clean:
	rm -rf results .pytest_cache
