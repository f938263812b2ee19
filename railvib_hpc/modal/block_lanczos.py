"""Block shift-invert Lanczos with thick restart (PETSc for the operator, numpy for the rest).

Why: a single-vector Krylov method reads the whole sparse factor once per
triangular solve; MUMPS solving a block of right-hand sides reads it once per
block (measured here: 96 ms for one right-hand side, 17 ms per right-hand side
in a block of 32, 168k DOFs on 2 ranks). This is what ANSYS's Block Lanczos
exploits.

Method: the operator ``A = (K - sigma M)^-1 M`` is self-adjoint in the M inner
product. The basis ``V`` is M-orthonormal (block classical Gram-Schmidt applied
twice, then SVQB normalisation); ``T = V^T M A V`` is accumulated from the
Gram-Schmidt coefficients. Ritz pairs ``(theta, y)`` of ``T`` give eigenvalues
``lambda = sigma + 1/theta``; the residual estimate of a Ritz pair is
``|| B y_last ||`` with ``B`` the coupling to the next block (exact in exact
arithmetic). When the basis is full, the best ``nev + block`` Ritz vectors are
kept (thick restart, Krylov-Schur style arrow matrix) and the expansion goes on
from the next block. A pair is converged when its residual estimate is below
``tol * theta``; the final true residuals ``||K x - lambda M x|| / ||K x||`` are
computed and reported by :func:`railvib_hpc.modal.eigen.normalise_and_check`.

The starting block depends only on global DOF numbers, so the result does not
depend on the number of ranks (beyond round-off).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import eigh

from ..constants import BYTES_PER_DOUBLE, BYTES_PER_GB

if TYPE_CHECKING:
    from mpi4py import MPI


#: Progress callback of the long phases: ``progress(phase, done, total)`` (units of work
#: done of ``total``; rank 0 prints it, throttled, with the phase's percent and ETA).
Progress = Callable[[str, int, int], None]


def no_progress(phase: str, done: int, total: int) -> None:
    """The default :data:`Progress`: nothing."""


def dense_block(arr: np.ndarray, n_global: int, comm: MPI.Comm):
    """A PETSc dense matrix holding this rank's rows ``arr`` (n_local, b) of a block."""
    from petsc4py import PETSc

    D = PETSc.Mat().createDense(size=((arr.shape[0], n_global), (None, arr.shape[1])),
                                comm=comm)
    D.setUp()
    D.getDenseArray()[:] = arr
    D.assemble()
    return D


def sparse_times_block(A, X: np.ndarray, comm: MPI.Comm) -> np.ndarray:
    """This rank's rows of ``A X`` for a distributed block X (n_local, b)."""
    D = dense_block(X, A.getSize()[0], comm)
    R = A.matMult(D)
    out = R.getDenseArray().copy()
    D.destroy()
    R.destroy()
    return out


def abs_matrix(A, comm):
    """``|A|`` (entrywise absolute values) with A's parallel layout and pattern."""
    from petsc4py import PETSc

    ip, ix, v = A.getValuesCSR()
    B = PETSc.Mat().createAIJ(size=A.getSizes(), csr=(ip, ix, np.abs(v)), comm=comm)
    B.assemble()
    return B


def longest_row(A, comm) -> int:
    """Largest number of stored entries in a row of A (all ranks)."""
    from mpi4py import MPI

    ip = A.getValuesCSR()[0]
    return comm.allreduce(int(np.diff(ip).max(initial=0)), op=MPI.MAX)


#: Resident memory of one rank before the factorisation where ``/proc`` cannot tell it
#: (the predictor otherwise measures it, :meth:`BlockOperator.memory_parts`): Python,
#: numpy/scipy, PETSc/SLEPc/MUMPS, MPI, h5py, gmsh (0.12 GB after the imports), the mesh and
#: the DOF map; 0.17 GB measured (VmRSS) per rank of the coarse thesis model (25k DOFs,
#: 2 ranks) with K and M, whose own share is 0.013 GB; more as a safety margin.
BASE_GB_PER_RANK = 0.3

#: Bytes per stored matrix entry (double value + 32-bit column index).
BYTES_PER_ENTRY = 12

#: Bytes per entry of the copy of ``K - sigma M`` that PETSc hands to MUMPS for a Cholesky
#: factorization: its upper triangle as coordinate triples (two 32-bit MUMPS indices + the
#: double value; PETSc's ``MatConvertToTriples_mpiaij_mpisbaij``).
MUMPS_TRIPLE_BYTES = 16

#: Work blocks (n x ``block`` doubles each) of the Lanczos phase besides the basis, measured
#: (VmHWM) on the coarse thesis model: one expansion holds the M product, PETSc's dense
#: copies of the block and of the product (``sparse_times_block``), the solution, MUMPS's
#: centralised right-hand side and distributed solution, and the Gram-Schmidt products and
#: corrected block; the thick restart the kept Ritz vectors; glibc keeps the freed blocks'
#: pages in its heap between them.
LANCZOS_WORK_BLOCKS = 12

#: Work blocks of the purification phase besides its n x ``wanted`` arrays (the solves of
#: one block and their K and M products; the checks' chunks of K Phi and M Phi).
PURIFY_WORK_BLOCKS = 12


#: Share of the available memory (``MemAvailable``) a modal solve may plan to use at its peak:
#: the rest absorbs the spread of the predictor and what other processes allocate meanwhile.
MEMORY_HEADROOM = 0.9


def dense_gb(n_global: int, basis: int, block: int, wanted: int, static_cols: int = 0
             ) -> float:
    """Peak of the dense arrays of a block Lanczos solve [GB, all ranks], 8 bytes each.

    The largest of three phases, in n-vectors:

    * Lanczos: the basis (``basis + block``), :data:`LANCZOS_WORK_BLOCKS` work blocks and
      the Ritz vectors ``wanted`` (guards included) formed from the basis at its end;
    * purification (:func:`purify_and_project`, in place): the Ritz vectors, the K
      products of the first pass rotated with them for the checks to reuse and the
      round-off bound of :func:`~railvib_hpc.modal.ritz.normalise_and_check` (3 x
      ``wanted``; the other K and M products go by blocks) and :data:`PURIFY_WORK_BLOCKS`
      work blocks (at the default basis of 3 x the modes, below the Lanczos phase);
    * static solves: the modes, right-hand sides and solutions of ``static_cols`` loads and
      the solve's work blocks.
    """
    lanczos = basis + (1 + LANCZOS_WORK_BLOCKS) * block + wanted
    purify = 3 * wanted + PURIFY_WORK_BLOCKS * block
    static = wanted + 2 * static_cols + PURIFY_WORK_BLOCKS * block
    return BYTES_PER_DOUBLE * n_global * max(lanczos, purify, static) / BYTES_PER_GB


class InsufficientMemory(RuntimeError):
    """The factorization (plus the Lanczos basis) would not fit in the available memory."""


class FactorizationError(RuntimeError):
    """MUMPS could not factor the shifted stiffness matrix."""


class NotConverged(RuntimeError):
    """Fewer than the wanted eigenpairs converged within the allowed restarts."""


def available_memory_gb(comm: MPI.Comm) -> float:
    """MemAvailable summed over the distinct nodes of ``comm`` (Linux), in GB."""
    from mpi4py import MPI

    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    mine = 0.0
    if node.rank == 0:
        try:
            with open("/proc/meminfo") as f:
                for line in f:
                    if line.startswith("MemAvailable:"):
                        mine = float(line.split()[1]) / 1e6
        except OSError:
            mine = float("inf")
    node.Free()
    return comm.allreduce(mine, op=MPI.SUM)


def destroy_all(*objects) -> None:
    """``destroy()`` every PETSc object given (None skipped), in the order given.

    Explicitly, not by dropping the Python reference: petsc4py 3.18 only stashes a parallel
    object whose last reference is dropped, until a collective ``PETSc.garbage_cleanup``.
    """
    for obj in objects:
        if obj is not None:
            obj.destroy()


class BlockOperator:
    """Dense-block products with M, K and the shift-invert operator (MUMPS Cholesky)."""

    def __init__(self, K, M, sigma: float, comm: MPI.Comm, prefix: str, extra_gb: float = 0.0,
                 out_of_core: str = "auto", inertia: bool = False):
        """Factor ``K - sigma M`` with MUMPS after checking that it fits in memory.

        The memory predictor (:attr:`predicted_peak_gb`: the peak resident memory of the
        ranks together while this operator lives, comparable with their ``VmHWM``) is the
        sum of :attr:`memory_parts` [GB]:

        * ``resident``: what the processes hold when the operator is created (``VmRSS``
          summed over the ranks: Python and the libraries, the mesh, the DOF map, K and M,
          whatever the caller keeps), measured, not modelled; where ``/proc`` is missing,
          :data:`BASE_GB_PER_RANK` per rank plus K and M;
        * ``shifted_matrix``: ``K - sigma M`` (sigma != 0; nonzeros x
          :data:`BYTES_PER_ENTRY` and the row pointers);
        * ``mumps_input``: PETSc's copy of its upper triangle handed to MUMPS
          (:data:`MUMPS_TRIPLE_BYTES` per entry);
        * ``factor``: MUMPS's own estimate of everything it allocates for the factorization,
          from the analysis (INFOG(17) in core, INFOG(27) out of core);
        * ``dense``: the caller's dense arrays ``extra_gb`` (:func:`dense_gb`: the Lanczos
          basis, work blocks, Ritz vectors and the purification's arrays).

        Measured on the coarse thesis model (25k DOFs, 2 ranks; block 8, 16 and 32; bands of
        8-76 modes) the prediction was within 4 % of every band's own peak. The memory check:
        what the operator adds (all parts but ``resident``, which the processes already
        hold and ``MemAvailable`` does not count) must stay below
        :data:`MEMORY_HEADROOM` of the available memory.

        ``out_of_core``: ``"auto"`` switches MUMPS to out-of-core (factor on disk,
        ICNTL(22) = 1) when the in-core estimate does not fit but the out-of-core one does;
        ``"always"`` / ``"never"`` force it on / off. An explicit PETSc option
        ``-<prefix>st_mat_mumps_icntl_22`` always wins. The option is removed again by
        :meth:`destroy` when this operator set it.

        ``inertia``: also count the eigenvalues below ``sigma`` (Sylvester: the negative
        pivots of the LDL^T factor, MUMPS INFOG(12), exact with ICNTL(13) = 1 so that the
        root front is not factored by ScaLAPACK) into :attr:`n_below`.

        Call :meth:`destroy` when done: it frees the factor at once (collective).
        """
        self.K, self.M, self.comm, self.sigma = K, M, comm, sigma
        self.ksp = self.factor = None
        self._set_ooc = False
        self._inertia = inertia
        self.n_below: int | None = None
        self.n_global = K.getSize()[0]
        self.n_local = K.getLocalSize()[0]
        self.A = K
        try:
            self._setup(prefix, extra_gb, out_of_core)
        except BaseException:
            self.destroy()          # nothing of a failed operator outlives it
            raise

    def _setup(self, prefix: str, extra_gb: float, out_of_core: str) -> None:
        """Memory check and factorization (see :meth:`__init__`)."""
        from petsc4py import PETSc

        from ..resources import current_memory_gb

        K, M, comm, sigma = self.K, self.M, self.comm, self.sigma
        resident = comm.allreduce(current_memory_gb())       # before K - sigma M is formed
        if sigma != 0.0:
            self.A = K.duplicate(copy=True)
            self.A.axpy(-sigma, M, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        t0 = time.perf_counter()
        self._ooc_option = f"{prefix}st_mat_mumps_icntl_22"
        opts = PETSc.Options()
        user_set = opts.hasName(self._ooc_option)
        if out_of_core == "always" and not user_set:
            self._use_out_of_core(True)
        avail_gb = available_memory_gb(comm)
        self.factor_memory_gb = self._estimate_factor_memory(prefix)
        self.in_core_memory_gb = self.factor_memory_gb

        fixed = self._fixed_memory_gb(resident)

        def peak(factor_gb: float) -> float:
            return sum(fixed.values()) + factor_gb + extra_gb

        def fit(factor_gb: float) -> bool:     # what the processes hold is not available
            return peak(factor_gb) - fixed["resident"] <= MEMORY_HEADROOM * avail_gb

        fits = fit(self.factor_memory_gb)
        self.available_gb = avail_gb
        ooc_note = ""
        if not fits and out_of_core == "auto" and not user_set:
            self._use_out_of_core(True)
            ooc_gb = self._estimate_factor_memory(prefix)
            if fit(ooc_gb):
                self.factor_memory_gb, fits = ooc_gb, True
            else:
                self._use_out_of_core(False)
                ooc_note = (f"; out of core: ~{ooc_gb:.1f} GB factor, "
                            f"~{peak(ooc_gb) - fixed['resident']:.1f} GB more, does not fit "
                            "either")
        if not fits:                       # (the option set here goes with destroy)
            advice = ("a coarser mesh (mesh.refinement), more nodes or a smaller "
                      "modal.max_basis / modal.n_modes")
            if out_of_core == "never":
                advice += ", or MUMPS out of core (modal.out_of_core = 'auto' or 'always')"
            more = peak(self.factor_memory_gb) - fixed["resident"]
            raise InsufficientMemory(
                f"the model has {self.n_global:,} DOFs: MUMPS estimates "
                f"~{self.factor_memory_gb:.1f} GB for the Cholesky factor "
                f"{'out of core' if out_of_core == 'always' else 'in core'}; with the copies "
                f"of K - sigma M (~{fixed['shifted_matrix'] + fixed['mumps_input']:.1f} GB) "
                f"and the Lanczos basis and blocks (~{extra_gb:.1f} GB) the solve needs "
                f"~{more:.1f} GB more than the ~{fixed['resident']:.1f} GB its processes hold "
                f"now{ooc_note}, but {avail_gb:.1f} GB are available on {comm.size} rank(s) "
                f"(modal.out_of_core = '{out_of_core}'); use {advice}")
        self.out_of_core = opts.getInt(self._ooc_option, 0) == 1
        #: the memory predictor's parts (see :meth:`__init__`), all ranks [GB]
        self.memory_parts = dict(fixed, factor=self.factor_memory_gb, dense=extra_gb)
        #: the memory predictor: the peak resident memory of the ranks [GB]
        self.predicted_peak_gb = peak(self.factor_memory_gb)
        self.ksp, self.factor = ksp, F = self._factor_solver(prefix)
        try:
            ksp.setUp()
            failed = F.getMumpsInfog(1) < 0    # PETSc flags a failed factorization silently
        except PETSc.Error:
            failed = True
        if failed:                         # (destroyed by __init__)
            raise FactorizationError(f"MUMPS Cholesky factorization of K - sigma M failed "
                                     f"(INFOG(1) = {F.getMumpsInfog(1)}, INFOG(2) = "
                                     f"{F.getMumpsInfog(2)}); is the model free to move "
                                     "(missing supports)? A small positive modal.shift_hz "
                                     "helps then")
        self.time_factorization = time.perf_counter() - t0
        if self._inertia:
            self.n_below = int(F.getMumpsInfog(12))
        self.n_solves = 0
        self.time_solves = 0.0

    def _fixed_memory_gb(self, resident: float) -> dict[str, float]:
        """The predictor's parts besides the factor and the dense arrays [GB, all ranks]:
        ``resident`` (what the processes held before this operator: ``VmRSS`` summed over
        the ranks; where it is NaN, :data:`BASE_GB_PER_RANK` per rank and K and M),
        ``shifted_matrix`` (``K - sigma M``, when sigma != 0) and ``mumps_input`` (PETSc's
        triples of its upper triangle for MUMPS)."""
        import math

        from petsc4py import PETSc

        def nnz(A) -> int:
            return int(A.getInfo(PETSc.Mat.InfoType.GLOBAL_SUM)["nz_used"])

        if math.isnan(resident):
            resident = BASE_GB_PER_RANK * self.comm.size + \
                BYTES_PER_ENTRY * (nnz(self.K) + nnz(self.M)) / BYTES_PER_GB
        n_a = nnz(self.A)
        shifted = 0.0 if self.A is self.K else \
            (BYTES_PER_ENTRY * n_a + 8 * (self.n_global + self.comm.size)) / BYTES_PER_GB
        return {"resident": resident, "shifted_matrix": shifted,
                "mumps_input": MUMPS_TRIPLE_BYTES * (n_a + self.n_global) / 2 / BYTES_PER_GB}

    def _use_out_of_core(self, on: bool) -> None:
        """Set (or remove again) the MUMPS out-of-core option of this operator's factor."""
        from petsc4py import PETSc

        if on:
            PETSc.Options().setValue(self._ooc_option, 1)
        else:
            PETSc.Options().delValue(self._ooc_option)
        self._set_ooc = on

    def _factor_solver(self, prefix: str):
        from petsc4py import PETSc

        ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(self.A)
        ksp.setType(PETSc.KSP.Type.PREONLY)
        pc = ksp.getPC()
        pc.setType(PETSc.PC.Type.CHOLESKY)
        pc.setFactorSolverType("mumps")
        ksp.setOptionsPrefix(prefix + "st_")
        ksp.setFromOptions()
        pc.setFactorSetUpSolverType()
        F = pc.getFactorMatrix()
        if self._inertia and F.getType() == "mumps":
            F.setMumpsIcntl(13, 1)          # exact inertia: no ScaLAPACK root
        return ksp, F

    def _estimate_factor_memory(self, prefix: str) -> float:
        """MUMPS's own estimate (GB, all ranks) of the in-core factorization, after analysis only.

        The analysis runs with a 1 MB working-memory cap (ICNTL(23)), so MUMPS stops with
        INFOG(1) = -19 before allocating anything and reports INFOG(17).
        """
        from petsc4py import PETSc

        ksp, F = self._factor_solver(prefix)
        try:
            if F.getType() != "mumps":
                return 0.0
            F.setMumpsIcntl(23, 1)
            with contextlib.suppress(PETSc.Error):
                ksp.setUp()
            out_of_core = PETSc.Options().getInt(f"{prefix}st_mat_mumps_icntl_22", 0) == 1
            return F.getMumpsInfog(27 if out_of_core else 17) / 1e3
        finally:
            destroy_all(F, ksp)         # the analysis's symbolic data (~10 % of the factor)

    def _dense(self, arr: np.ndarray):
        return dense_block(arr, self.n_global, self.comm)

    def _product(self, A, X: np.ndarray) -> np.ndarray:
        return sparse_times_block(A, X, self.comm)

    def mass(self, X: np.ndarray) -> np.ndarray:
        """``M X`` for a block X (n_local, b)."""
        return self._product(self.M, X)

    def stiffness(self, X: np.ndarray) -> np.ndarray:
        """``K X`` for a block X (n_local, b)."""
        return self._product(self.K, X)

    def apply(self, X: np.ndarray) -> np.ndarray:
        """``(K - sigma M)^-1 M X`` for a block X (n_local, b)."""
        return self.solve(self.mass(X), chunk=max(X.shape[1], 1))

    def solve(self, B: np.ndarray, chunk: int = 64, progress: Progress | None = None,
              phase: str = "solves") -> np.ndarray:
        """``(K - sigma M)^-1 B`` for right-hand sides B (n_local, b), ``chunk`` at a time
        (``progress``: :data:`Progress` after each chunk)."""
        from petsc4py import PETSc

        out = np.empty(B.shape)
        for c0 in range(0, B.shape[1], chunk):
            Bc = np.ascontiguousarray(B[:, c0:c0 + chunk])
            Bd = self._dense(Bc)
            Y = PETSc.Mat().createDense(size=((self.n_local, self.n_global),
                                              (None, Bc.shape[1])), comm=self.comm)
            Y.setUp()
            Y.assemble()
            t0 = time.perf_counter()
            self.factor.matSolve(Bd, Y)
            self.time_solves += time.perf_counter() - t0
            self.n_solves += Bc.shape[1]
            out[:, c0:c0 + chunk] = Y.getDenseArray()
            Bd.destroy()
            Y.destroy()
            if progress is not None:
                progress(phase, min(c0 + chunk, B.shape[1]), B.shape[1])
        return out

    def destroy(self) -> None:
        """Free the factor, its solver and ``K - sigma M`` now (collective; idempotent).

        The factor must be destroyed explicitly: petsc4py 3.18 does not destroy a parallel
        PETSc object whose last Python reference goes away but stashes it for
        ``PETSc.garbage_cleanup`` (``PetscObjectDelayedDestroy``), and the Python handle of
        ``pc.getFactorMatrix()`` is the last reference once the KSP is destroyed: measured,
        every band kept its whole MUMPS factor resident (+1.1 GB per band at thesis size).
        """
        destroy_all(self.factor, self.ksp)
        self.factor = self.ksp = None
        if self.A is not None and self.A is not self.K:
            self.A.destroy()
        self.A = None
        if self._set_ooc:
            self._use_out_of_core(False)


def effective_block(block: int, n_global: int) -> int:
    """The block size :func:`block_lanczos` uses: ``block``, at most a quarter of the
    ``n_global`` DOFs (1 below 8 DOFs).

    Examples
    --------
    >>> effective_block(32, 100_000), effective_block(32, 40), effective_block(32, 5)
    (32, 10, 1)
    """
    return max(1, min(block, n_global // 4 if n_global >= 8 else 1))


def default_max_basis(nev: int, block: int) -> int:
    """Basis size at which block Lanczos restarts when the caller gives none."""
    return max(2 * nev, nev + 8 * block)


def start_block(n_global: int, r0: int, r1: int, b: int, seed: int = 20261123) -> np.ndarray:
    """Rows r0:r1 of a reproducible random (n_global, b) block, whatever the partition."""
    chunk = 65536
    out = np.empty((r1 - r0, b))
    for c in range(r0 // chunk, (r1 - 1) // chunk + 1 if r1 > r0 else 0):
        lo, hi = c * chunk, min((c + 1) * chunk, n_global)
        block = np.random.default_rng([seed, c]).standard_normal((hi - lo, b))
        a, z = max(lo, r0), min(hi, r1)
        out[a - r0:z - r0] = block[a - lo:z - lo]
    return out


#: Block Lanczos's Rayleigh-Ritz step (the eigendecomposition of the m x m projected matrix,
#: on every rank: 0.05-0.5 s at m = 400-900 whatever the DOFs, 30-40 times a solve) only
#: tests convergence until the last one. When the residual estimates of the wanted pairs,
#: extrapolated geometrically from the last two tests, need ``k`` more expansions, the next
#: test comes after ``k // 2`` of them, at most :data:`RR_MAX_GAP` (the forecast is
#: pessimistic: Lanczos converges superlinearly). A test always precedes a restart, and a
#: late test costs at most a few extra expansions, never an unconverged pair.
RR_MAX_GAP = 4


def ritz_step(T: np.ndarray, m: int, keep: int, b: int, two_sided: bool
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``keep`` Ritz pairs of largest ``|theta|`` of ``T[:m, :m]`` (upper triangle) and
    their residual estimates ``|| T[m:m+b, :m] y ||``."""
    S = np.triu(T[:m, :m]) + np.triu(T[:m, :m], 1).T
    # the full decomposition by divide and conquer (LAPACK syevd) is faster than the
    # subset of the ``keep`` largest by MRRR (syevr): measured 25 vs 53 ms at m = 450 and
    # 60 vs 93 ms at m = 675 (keep = 257); the pairs are the same to rounding
    theta, Y = eigh(S, driver="evd")
    if two_sided:
        order = np.argsort(-np.abs(theta), kind="stable")[:min(m, keep)]
    else:
        order = np.arange(m - 1, m - 1 - min(m, keep), -1)
    theta, Y = theta[order], np.asfortranarray(Y[:, order])
    # the coupling to the next block touches the last block of columns only
    lo = max(0, m - b)
    res = np.linalg.norm(T[m:m + b, lo:m] @ Y[lo:m], axis=0)
    return theta, Y, res


def rr_gap(history: list[tuple[int, float]]) -> int:
    """Expansions until the next convergence test (:data:`RR_MAX_GAP`), from the last two
    ``(expansion, q)`` of the worst wanted ratio ``q = residual / (tol |theta|)``."""
    if len(history) < 2:
        return 1
    (e0, q0), (e1, q1) = history[-2:]
    if not (q1 > 1.0 and q0 > q1 and e1 > e0):
        return 1
    rate = np.log(q0 / q1) / (e1 - e0)            # natural decades per expansion
    return int(max(1, min(RR_MAX_GAP, np.log(q1) / rate // 2)))


def rows_product(A: np.ndarray, Z: np.ndarray, out: np.ndarray, progress: Progress,
                 phase: str) -> None:
    """``out[:] = A @ Z`` by slices of :data:`ROTATE_ROWS` rows; ``out`` may be A's own
    leading columns (each slice is read before it is written), with progress."""
    n = A.shape[0]
    for r in range(0, n, ROTATE_ROWS):
        out[r:r + ROTATE_ROWS] = A[r:r + ROTATE_ROWS] @ Z
        progress(phase, min(r + ROTATE_ROWS, n), n)


def _allsum(comm, a: np.ndarray) -> np.ndarray:
    """``a`` summed over the ranks (in place, contiguous)."""
    from mpi4py import MPI

    a = np.ascontiguousarray(a)
    comm.Allreduce(MPI.IN_PLACE, a, op=MPI.SUM)
    return a


def m_orthonormalize_block(op: BlockOperator, V: np.ndarray, W: np.ndarray, m: int, r0: int,
                           local_from: int | None = None
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gram-Schmidt against V[:, :m], then SVQB; returns Q, coefficients C (m, b), R (b, b).

    With ``local_from`` the first pass only covers V[:, local_from:m] (the blocks the
    Lanczos recurrence couples to) and the second pass is a full reorthogonalization;
    otherwise two full passes (CGS2). ``r0``: this rank's first global row (the random
    replacements of directions lost to a (nearly) invariant subspace).
    """
    comm, n = op.comm, op.n_global
    C = np.zeros((m, W.shape[1]))
    passes = ((0, m), (0, m)) if local_from is None else ((local_from, m), (0, m))
    for lo, hi in passes:
        if hi > lo:
            h = _allsum(comm, V[:, lo:hi].T @ op.mass(W))
            W = W - V[:, lo:hi] @ h
            C[lo:hi] += h
    G = _allsum(comm, W.T @ op.mass(W))
    s, U = np.linalg.eigh(0.5 * (G + G.T))
    good = s > 1e-13 * max(s.max(), 1e-300)
    Q = W @ (U / np.sqrt(np.where(good, s, 1.0)))
    R = U.T * np.sqrt(np.where(good, s, 0.0))[:, None]     # W = Q R
    if not good.all():
        # (nearly) invariant subspace: replace the lost directions by random vectors
        nbad = int((~good).sum())
        rnd = start_block(n, r0, r0 + op.n_local, nbad, seed=int(m) + 7)
        basis = np.hstack([V[:, :m], Q[:, good]])
        for _ in range(2):
            rnd = rnd - basis @ _allsum(comm, basis.T @ op.mass(rnd))
        s2, U2 = np.linalg.eigh(_allsum(comm, rnd.T @ op.mass(rnd)))
        Q[:, ~good] = rnd @ (U2 / np.sqrt(s2))
    return Q, C, R


def block_lanczos(op: BlockOperator, nev: int, r0: int, block: int = 32, tol: float = 1e-8,
                  max_basis: int = 0, max_restarts: int = 50,
                  monitor: Callable[[int, int, int], None] | None = None,
                  theta_cut: float | None = None, margin: int = 1, guard: int = 0,
                  progress: Progress | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Largest ``nev`` eigenvalues ``theta`` (in modulus) of the M-self-adjoint ``op.apply``.

    With a shift inside the spectrum (``op.sigma > 0``) ``theta = 1 / (lambda - sigma)``
    has both signs: the eigenvalues nearest to the shift, on both sides, come first. With
    ``theta_cut`` the solve goes on past ``nev`` until every Ritz value with ``|theta| >=
    theta_cut`` (every eigenvalue within ``1 / theta_cut`` of the shift: a band) has
    converged, followed by ``margin`` converged ones beyond it — Krylov methods converge the
    extreme ``|theta|`` first, so the band is then complete (the caller checks it with
    inertia counts). Raises :class:`NotConverged` when the band does not fit ``max_basis``.
    ``guard``: up to this many further (unconverged) Ritz vectors are appended to ``X``
    (``stats["n_guard"]``), for a later Rayleigh-Ritz step that needs them. The convergence
    test (a Rayleigh-Ritz step, :func:`ritz_step`) is skipped while its forecast says that
    it cannot pass yet (:data:`RR_MAX_GAP`).

    Parameters
    ----------
    op
        The operator (shift-invert of K, M).
    nev
        Number of wanted eigenpairs.
    r0
        First global row of this rank (for the reproducible starting block).
    block
        Block size (right-hand sides per solve).
    tol
        Convergence: residual estimate <= tol * theta.
    max_basis
        Basis size at which to restart (0: max(2 nev, nev + 8 block), at most n).
    max_restarts
        Give up after this many restarts.
    monitor
        Called as ``monitor(n_converged, nev, basis_size)`` after each expansion (the
        count of the last convergence test).
    progress
        :data:`Progress` of the long dense products (thick restarts, the Ritz vectors).

    Returns
    -------
    theta : (nev,) descending in modulus (with ``theta_cut``: all converged ones)
    X : (n_local, nev) M-orthonormal Ritz vectors
    stats : dict
    """
    progress = progress or no_progress
    n = op.n_global
    b = effective_block(block, n)
    if max_basis <= 0:
        max_basis = default_max_basis(nev, b)
    max_basis = min(max_basis, n - b)
    if nev + 2 * b > max_basis:
        raise ValueError(f"too many modes ({nev}) for {n} DOFs with block size {b}")
    keep = min(nev + b, max_basis - 2 * b)
    two_sided = op.sigma != 0.0          # theta of both signs: order by modulus
    V = np.zeros((op.n_local, max_basis + b), order="F")   # column slices stay contiguous
    T = np.zeros((max_basis + b, max_basis + b))
    t_orth = t_ritz = 0.0

    def m_orthonormalize(W: np.ndarray, m: int, local_from: int | None = None):
        return m_orthonormalize_block(op, V, W, m, r0, local_from)

    t0 = time.perf_counter()
    Q, _, _ = m_orthonormalize(start_block(n, r0, r0 + op.n_local, b), 0)
    t_orth += time.perf_counter() - t0
    V[:, :b] = Q
    m = 0                                   # vectors whose A-image is in T
    restarts, expansions, tests = 0, 0, 0
    theta = Y = res = None
    fresh = -1                              # the basis size of the last Ritz step
    nconv, next_test, history = 0, 0, []
    just_restarted = False
    while True:
        # expand the block V[:, m:m+b]
        W = op.apply(V[:, m:m + b])
        t0 = time.perf_counter()
        Q, C, R = m_orthonormalize(W, m + b, None if just_restarted else max(0, m - b))
        just_restarted = False
        t_orth += time.perf_counter() - t0
        T[: m + b, m:m + b] += C
        T[m + b:m + 2 * b, m:m + b] = R
        V[:, m + b:m + 2 * b] = Q
        m += b
        expansions += 1
        restart_due = m + 2 * b > max_basis
        # Rayleigh-Ritz on the m vectors whose images are known: the convergence test
        if m >= nev + b and (expansions >= next_test or restart_due):
            t0 = time.perf_counter()
            theta, Y, res = ritz_step(T, m, keep, b, two_sided)
            fresh, tests = m, tests + 1
            ok = res <= tol * np.abs(theta)
            nconv = int(np.argmin(ok)) if not ok.all() else len(ok)
            if theta_cut is not None:
                # the band: every Ritz value above the cut, then `margin` converged below it
                inside = int(np.sum(np.abs(theta) >= theta_cut))
                want = max(nev, inside + margin)
                if want + 2 * b > max_basis:
                    raise NotConverged(f"block Lanczos: the band holds at least {inside} "
                                       f"modes, more than a basis of {max_basis} can take")
                if want > nev:
                    nev = want
                    keep = min(nev + b, max_basis - 2 * b)
            if nev <= len(theta):
                history.append((expansions, float(np.max(
                    res[:nev] / (tol * np.abs(theta[:nev]))))))
            next_test = expansions + rr_gap(history)
            t_ritz += time.perf_counter() - t0
            if monitor:
                monitor(min(nconv, nev), nev, m)
            if nconv >= nev:
                break
        elif monitor:
            monitor(min(nconv, nev), nev, m)
        if restart_due:
            if restarts >= max_restarts:
                raise NotConverged(f"block Lanczos: {nconv} of {nev} modes converged after "
                                   f"{restarts} restarts")
            if fresh != m or len(theta) < min(keep, m):
                # the band grew at the last test (more vectors to keep than it computed)
                t0 = time.perf_counter()
                theta, Y, res = ritz_step(T, m, keep, b, two_sided)
                fresh = m
                t_ritz += time.perf_counter() - t0
            # thick restart: keep the best `keep` Ritz vectors, then the next block
            p = min(keep, len(theta))
            t0 = time.perf_counter()
            coupling = T[m:m + b, :m] @ Y[:, :p]
            nxt = V[:, m:m + b].copy()
            rows_product(V[:, :m], Y[:, :p], V[:, :p], progress, "thick restart")
            V[:, p:p + b] = nxt
            T[:] = 0.0
            T[np.arange(p), np.arange(p)] = theta[:p]
            T[p:p + b, :p] = coupling       # its transpose comes from the next expansion
            t_orth += time.perf_counter() - t0
            m = p
            restarts += 1
            just_restarted = True
    if theta_cut is not None:          # return every converged pair (band + margin)
        nev = nconv
    n_guard = max(0, min(guard, Y.shape[1] - nev))
    t0 = time.perf_counter()
    X = np.empty((op.n_local, nev + n_guard))
    rows_product(V[:, :m], Y[:, :nev + n_guard], X, progress, "Ritz vectors")
    t_orth += time.perf_counter() - t0
    stats = {"block_size": b, "max_basis": max_basis, "restarts": restarts,
             "expansions": expansions, "basis_size": m, "linear_solves": op.n_solves,
             "time_block_solves": op.time_solves, "time_orthogonalization": t_orth,
             "time_lanczos_ritz": t_ritz, "lanczos_ritz_steps": tests,
             "max_residual_estimate": float((res[:nev] / np.abs(theta[:nev])).max()),
             "n_wanted": int(nev), "n_guard": int(n_guard)}
    return theta[:nev], X, stats


#: Rows per slice when a block of vectors is rotated in place (:func:`rotate_in_place`):
#: the temporary is ``ROTATE_ROWS x k`` doubles, not another ``n x k`` block.
ROTATE_ROWS = 4096


def rotate_in_place(A: np.ndarray, Z: np.ndarray, progress: Progress | None = None,
                    phase: str = "rotation") -> None:
    """``A[:] = A @ Z`` for a square Z, by slices of :data:`ROTATE_ROWS` rows (no n x k copy)."""
    rows_product(A, Z, A, progress or no_progress, phase)


def rotate_narrowing(A: np.ndarray, Z: np.ndarray, progress: Progress | None = None,
                     phase: str = "rotation") -> np.ndarray:
    """``A @ Z`` for a C-contiguous A (n, k) and Z (k, p), p <= k, in A's own memory.

    Returns a C-contiguous (n, p) array on A's buffer (A is overwritten). Row slice
    ``r:r+R`` of the result occupies the first ``(r + R) p <= (r + R) k`` values of the
    buffer, so it only overwrites rows of A that have already been multiplied. ``progress``:
    :data:`Progress` by row slices.

    >>> import numpy as np
    >>> A = np.arange(12.0).reshape(4, 3)
    >>> Z = np.array([[1.0], [0.0], [1.0]])
    >>> expected = A @ Z
    >>> out = rotate_narrowing(A, Z)
    >>> bool(np.array_equal(out, expected)), out.shape, np.shares_memory(out, A)
    (True, (4, 1), True)
    """
    n, k = A.shape
    p = Z.shape[1]
    if p > k or not A.flags.c_contiguous:
        raise ValueError(f"rotate_narrowing: needs a C-contiguous (n, k) A and p <= k columns, "
                         f"got {A.shape} and {Z.shape}")
    progress = progress or no_progress
    out = A.reshape(-1)[:n * p].reshape(n, p)
    for r in range(0, n, ROTATE_ROWS):
        out[r:r + ROTATE_ROWS] = A[r:r + ROTATE_ROWS] @ Z    # (the product is computed first)
        progress(phase, min(r + ROTATE_ROWS, n), n)
    return out


def narrow_columns(A: np.ndarray, p: int) -> np.ndarray:
    """``A[:, :p]`` as a C-contiguous (n, p) array in A's own memory (A is overwritten),
    by slices of :data:`ROTATE_ROWS` rows, as :func:`rotate_narrowing`.

    >>> import numpy as np
    >>> narrow_columns(np.arange(12.0).reshape(4, 3), 2).tolist()
    [[0.0, 1.0], [3.0, 4.0], [6.0, 7.0], [9.0, 10.0]]
    """
    n, k = A.shape
    if p > k or not A.flags.c_contiguous:
        raise ValueError(f"narrow_columns: needs a C-contiguous (n, k) A and p <= k, got "
                         f"{A.shape} and {p}")
    out = A.reshape(-1)[:n * p].reshape(n, p)
    for r in range(0, n, ROTATE_ROWS):
        out[r:r + ROTATE_ROWS] = A[r:r + ROTATE_ROWS, :p].copy()   # (read before written)
    return out


def symmetric_from_upper(A: np.ndarray) -> np.ndarray:
    """The symmetric matrix whose upper triangle (diagonal included) is A's."""
    return np.triu(A) + np.triu(A, 1).T


def permute_columns(A: np.ndarray, order: np.ndarray) -> None:
    """``A[:] = A[:, order]`` by slices of :data:`ROTATE_ROWS` rows (no n x k copy)."""
    for r in range(0, A.shape[0], ROTATE_ROWS):
        A[r:r + ROTATE_ROWS] = A[r:r + ROTATE_ROWS][:, order]


def purify_and_project(op: BlockOperator, X: np.ndarray, block: int, refine: bool = False,
                       select: Callable[[np.ndarray], np.ndarray] | None = None,
                       progress: Progress | None = None, timings: dict | None = None,
                       fixed: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                       kx: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One more operator application (purification), then Rayleigh-Ritz with K and M.

    Applying ``(K - sigma M)^-1 M`` once more damps the high-frequency error left in the
    Ritz vectors (what SLEPc calls purification); the final Rayleigh-Ritz step makes the
    modes exactly M-orthonormal and K-orthogonal. Returns eigenvalues, modes ``Phi`` and
    for every mode an upper bound of the norm of its solve residual ``M X - (K - sigma M)
    X_p`` (the accuracy of the factorisation: a floor for the eigen-residual, since ``K phi
    - lambda M phi`` contains it). ``refine``: one step of iterative refinement per solve
    (``X_p += (K - sigma M)^-1 s``), which brings an inaccurate factor's solves to working
    accuracy.

    ``fixed = (KC, MC, bounds)``: the first ``c = len(bounds)`` columns of X are modes kept
    as they are (converged ones of an earlier pass, with their projections ``KC = X_c^T K
    X_c``, ``MC = X_c^T M X_c`` and solve-residual bounds): only the others are purified,
    and the Rayleigh-Ritz step works in the span of both.

    The projected matrices ``X_p^T K X_p`` and ``X_p^T M X_p`` are accumulated block by
    block while the K and M products of the block are at hand, their upper triangles only
    (block ``j`` against the blocks up to ``j``: half the products of the full matrices);
    the products are not kept: the checks form ``K Phi`` and ``M Phi`` of the final modes
    afresh (:func:`~railvib_hpc.modal.ritz.normalise_and_check`).

    Memory: ``X`` is overwritten: it becomes ``Phi`` (the purified vectors are written over
    the block just solved with, then rotated in place, :func:`rotate_in_place`), so the
    phase holds ``X`` and a few solve blocks. ``select(lam)``: the order of the returned
    pairs, a permutation of ``range(k)`` (default: ascending eigenvalues). ``progress``:
    :data:`Progress` (phases "purification" and "Rayleigh-Ritz"); ``timings``: seconds
    added under ``"solves"``, ``"products"`` (the K and M products and solve residuals) and
    ``"rayleigh_ritz"`` (projection, dense eigenproblem, rotation).

    ``kx`` (C-contiguous, X's shape; not with ``fixed``): filled with ``K Phi``, the K
    products of the purified vectors rotated by the same Rayleigh-Ritz rotation as the
    vectors themselves (exact in exact arithmetic; the rounding of the rotation, ~1e-16
    ``||K Phi||``, is far below any residual tolerance), for the checks to reuse
    instead of a second sparse product with K (one more n x k array while it lives).
    """
    from mpi4py import MPI

    if kx is not None and (fixed is not None or kx.shape != X.shape):
        raise ValueError("purify_and_project: kx needs X's shape and no fixed columns")
    progress = progress or no_progress
    timings = {} if timings is None else timings
    clock = dict.fromkeys(("solves", "products", "rayleigh_ritz"), 0.0)
    k = X.shape[1]
    kp = np.zeros((k, k))
    mp = np.zeros((k, k))
    sres = np.zeros(k)
    n_fixed = 0 if fixed is None else len(fixed[2])
    for j in range(n_fixed, k, block):
        c = slice(j, min(j + block, k))
        t0, s0 = time.perf_counter(), op.time_solves
        B = op.mass(X[:, c])
        Y = op.solve(B, chunk=max(B.shape[1], 1))
        KY, MY = op.stiffness(Y), op.mass(Y)
        if refine:
            Y += op.solve(B - (KY - op.sigma * MY), chunk=max(B.shape[1], 1))
            KY, MY = op.stiffness(Y), op.mass(Y)
        S = B - (KY - op.sigma * MY)
        sres[c] = np.sum(S**2, axis=0)
        X[:, c] = Y
        if kx is not None:
            kx[:, c] = KY
        t1 = time.perf_counter()
        clock["solves"] += op.time_solves - s0
        clock["products"] += t1 - t0 - (op.time_solves - s0)
        kp[:c.stop, c] = X[:, :c.stop].T @ KY
        mp[:c.stop, c] = X[:, :c.stop].T @ MY
        clock["rayleigh_ritz"] += time.perf_counter() - t1
        progress("purification", c.stop - n_fixed, k - n_fixed)
    t0 = time.perf_counter()
    for a in (sres, kp, mp):
        op.comm.Allreduce(MPI.IN_PLACE, a, op=MPI.SUM)
    if n_fixed:
        kp[:n_fixed, :n_fixed], mp[:n_fixed, :n_fixed] = fixed[0], fixed[1]
        sres[:n_fixed] = fixed[2] ** 2
    lam, Z = eigh(symmetric_from_upper(kp), symmetric_from_upper(mp))
    if select is not None:
        perm = np.asarray(select(lam))
        lam, Z = lam[perm], Z[:, perm]
    rotate_in_place(X, Z, progress, "Rayleigh-Ritz")
    if kx is not None:
        rotate_in_place(kx, Z, progress, "Rayleigh-Ritz (K Phi)")
    clock["rayleigh_ritz"] += time.perf_counter() - t0
    for key, value in clock.items():
        timings[key] = timings.get(key, 0.0) + value
    # ||S z_i|| <= sum_j |z_ji| ||s_j|| (triangle inequality; S itself is not kept)
    return lam, X, np.abs(Z).T @ np.sqrt(sres)
