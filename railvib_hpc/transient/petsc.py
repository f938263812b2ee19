"""The full-order system on PETSc: effective matrix, one MUMPS factor, right-hand sides.

:class:`TransientSystem` holds the distributed K, M, C of the model, builds the effective
matrix ``K_eff = c_m M + c_c C + c_k K`` of :class:`~.scheme.GeneralizedAlpha` (the same
sparsity pattern as K), factors it once with MUMPS Cholesky (through
:class:`~railvib_hpc.model.factor.ShiftInvertFactor` at sigma = 0: memory check, automatic
out of core, options prefix ``railvib_tr_st_``) and reuses the factor at every step. The history
part of the right-hand side is precombined into at most three matrices
``H_u = m_u M + c_u C - alpha_f K``, ``H_v = m_v M + c_v C``, ``H_a = m_a M + c_a C``
(``H_a`` vanishes for the trapezoidal rule), so a step costs one solve and two or three
sparse products.

State vectors are numpy arrays of this rank's rows (global DOF numbers of
:class:`~railvib_hpc.model.dofmap.DofMap`, independent of the number of ranks) wrapped as
PETSc vectors without copies.
"""

from __future__ import annotations

import time

import numpy as np

from .scheme import GeneralizedAlpha

#: Options prefix of the effective-matrix factorization (``-railvib_tr_st_mat_mumps_...``).
PREFIX = "railvib_tr_"


class TransientSystem:
    """``K_eff`` factored once; products with K, M, C; energies.

    Parameters
    ----------
    K, M, C
        Distributed AIJ matrices with one pattern (C may be None: undamped).
    scheme
        The time-integration scheme (step and parameters).
    comm
        MPI communicator.
    extra_gb
        Memory the caller will need besides the factor (e.g. the rail columns), for the
        memory check.
    pml
        The perfectly matched layers (:class:`~.pml.PmlLayer`, or None; the system owns
        it), implicit: their ``M_e1`` joins C, the part of their force that ``u_{n+1}``
        makes (:meth:`~.pml.PmlLayer.instant_matrix`, ``A``) joins K_eff as
        ``(1 - alpha_f) A``, and the history's part is in the right-hand side
        (:meth:`history_rhs`, :meth:`end_step`). ``A`` is symmetric (to round-off; the
        identity in :meth:`~railvib_hpc.fem.pml.PmlElements.instant_matrices`), so K_eff
        keeps its Cholesky factor.
    """

    #: The loads' work in this scheme's energy balance is ``f^T (u_{n+1} - u_n)``
    #: (:mod:`.guard`)
    LOAD_WORK = "displacement"
    #: How the static start was solved (its own factor of K: nothing to say)
    static_method: str | None = None

    def __init__(self, K, M, C, scheme: GeneralizedAlpha, comm, extra_gb: float = 0.0,
                 pml=None):
        from petsc4py import PETSc

        from ..model.factor import ShiftInvertFactor

        self.n_global = K.getSize()[0]
        self.r0, self.r1 = K.getOwnershipRange()
        self.n_local = self.r1 - self.r0
        self.pml = pml
        self.time_pml = 0.0
        self._owned_c = None
        if pml is not None:
            C = self._owned_c = _with_diagonal_damping(K, C, pml.damping_diagonal, comm)
            self.pml_force = np.zeros(self.n_local)
        self.K, self.M, self.C, self.scheme, self.comm = K, M, C, scheme, comm
        same = PETSc.Mat.Structure.SAME_NONZERO_PATTERN
        t0 = time.perf_counter()
        k_eff = K.duplicate(copy=True)
        k_eff.scale(scheme.c_stiffness)
        k_eff.axpy(scheme.c_mass, M, structure=same)
        if C is not None:
            k_eff.axpy(scheme.c_damping, C, structure=same)
        if pml is not None:
            instant = csr_matrix(comm, pml.instant_matrix(scheme.dt))
            k_eff.axpy(scheme.c_stiffness, instant,
                       structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            instant.destroy()
        k_eff.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        k_eff.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
        self.k_eff = k_eff
        self.history_matrices = self._history(PETSc)
        self.time_setup = time.perf_counter() - t0
        self.op = ShiftInvertFactor(k_eff, M, 0.0, comm, PREFIX, extra_gb=extra_gb)
        self.time_factorization = self.op.time_factorization
        self.factor_memory_gb = self.op.factor_memory_gb
        self.out_of_core = self.op.out_of_core
        self._work = [self.vector() for _ in range(2)]
        self.n_solves = 0
        self.time_solves = 0.0
        self.time_products = 0.0

    def _history(self, PETSc) -> list:
        """``[(matrix, which state)]`` of the right-hand side's history part."""
        h = self.scheme.history()
        same = PETSc.Mat.Structure.SAME_NONZERO_PATTERN
        out = []
        for slot in range(3):
            cm, cc = h["M"][slot], h["C"][slot] if self.C is not None else 0.0
            ck = h["K"][slot]
            if cm == 0.0 and cc == 0.0 and ck == 0.0:
                continue
            A = self.M.duplicate(copy=True)
            A.scale(cm)
            if cc != 0.0:
                A.axpy(cc, self.C, structure=same)
            if ck != 0.0:
                A.axpy(ck, self.K, structure=same)
            out.append((A, slot))
        return out

    # ---------------------------------------------------------------- vectors
    def vector(self, array: np.ndarray | None = None):
        """A distributed PETSc vector on ``array`` (this rank's rows; zeros if None)."""
        from petsc4py import PETSc

        if array is None:
            array = np.zeros(self.n_local)
        return PETSc.Vec().createWithArray(array, size=(self.n_local, self.n_global),
                                           comm=self.comm)

    def local(self, vec) -> np.ndarray:
        """The numpy view of a vector created by :meth:`vector`."""
        return vec.getArray(readonly=False)

    # ---------------------------------------------------------------- one step
    def history_rhs(self, u, v, a, out) -> None:
        """``out = H_u u + H_v v + H_a a`` (PETSc vectors)."""
        t0 = time.perf_counter()
        out.zeroEntries()
        state = (u, v, a)
        tmp = self._work[0]
        for A, slot in self.history_matrices:
            A.mult(state[slot], tmp)
            out.axpy(1.0, tmp)
        self.time_products += time.perf_counter() - t0
        if self.pml is not None:
            self.history_rhs_layers(u, out)

    def history_rhs_layers(self, u, out) -> None:
        """With perfectly matched layers: ``out -= (1 - alpha_f) f_pml(0) + alpha_f
        f_pml,n``, the history's part of their force at ``t_{n+1-alpha_f}`` (the rest,
        ``(1 - alpha_f) A u_{n+1}``, is in K_eff). The memory starts at rest with the
        first step when nothing started it before (a static start does,
        :meth:`~.pml.PmlLayer.start`)."""
        t0 = time.perf_counter()
        layer, af = self.pml, self.scheme.alpha_f
        if not layer.started:
            self.pml_force = layer.start(self.local(u))
        res = self.local(out)
        res -= (1.0 - af) * layer.peek(np.zeros(self.n_local), self.scheme.dt)
        if af != 0.0:
            res -= af * self.pml_force
        self.time_pml += time.perf_counter() - t0

    def end_step(self, u_new: np.ndarray) -> None:
        """Advance the layers' memory to the step's final displacements ``u_new`` (this
        rank's rows; collective; nothing without layers)."""
        if self.pml is None:
            return
        t0 = time.perf_counter()
        self.pml_force = self.pml.force(u_new, self.scheme.dt)
        self.time_pml += time.perf_counter() - t0

    def solve(self, rhs, out) -> None:
        """``out = K_eff^-1 rhs`` with the stored factor."""
        t0 = time.perf_counter()
        self.op.solve_vector(rhs, out)
        self.time_solves += time.perf_counter() - t0
        self.n_solves += 1

    def solve_block(self, B: np.ndarray) -> np.ndarray:
        """``K_eff^-1 B`` for this rank's rows of a block of right-hand sides (n_local, k)."""
        t0 = time.perf_counter()
        out = self.op.solve(B)
        self.time_solves += time.perf_counter() - t0
        self.n_solves += B.shape[1]
        return out

    # ---------------------------------------------------------------- energies
    def quadratic(self, A, x) -> float:
        """``x^T A x`` (collective)."""
        if A is None:
            return 0.0
        tmp = self._work[1]
        A.mult(x, tmp)
        return tmp.dot(x)

    def energy(self, u, v) -> float:
        """Kinetic plus strain energy ``1/2 v^T M v + 1/2 u^T K u`` (collective)."""
        return 0.5 * self.quadratic(self.M, v) + 0.5 * self.quadratic(self.K, u)

    # ---------------------------------------------------------------- other solves
    def solve_matrix(self, A, B: np.ndarray) -> np.ndarray:
        """``A^-1 B`` for a block B with a separate MUMPS Cholesky factor of A (e.g. K for a
        static start, M for a consistent initial acceleration); the factor is freed."""
        return factor_solve(A, self.M, B, self.comm, PREFIX + "aux_")

    def destroy(self) -> None:
        self.op.destroy()
        self.k_eff.destroy()
        if self._owned_c is not None:
            self._owned_c.destroy()
        if self.pml is not None:
            self.pml.destroy()
        for A, _ in self.history_matrices:
            A.destroy()
        for w in self._work:
            w.destroy()


def factor_solve(A, M, B: np.ndarray, comm, prefix: str) -> np.ndarray:
    """``A^-1 B`` for a block B of this rank's rows with one MUMPS Cholesky factor of A
    (:class:`~railvib_hpc.model.factor.ShiftInvertFactor` at sigma = 0, its memory check
    included: :class:`~railvib_hpc.model.factor.InsufficientMemory` when it does not fit),
    freed before returning (collective)."""
    from ..model.factor import ShiftInvertFactor

    op = ShiftInvertFactor(A, M, 0.0, comm, prefix, extra_gb=16.0 * B.size / 1e9)
    try:
        return op.solve(np.ascontiguousarray(B, dtype=float))
    finally:
        op.destroy()


class GhostGather:
    """Values of a distributed vector at given global DOFs, on this rank (a PETSc
    scatter from the global vector into a sequential one; collective construction and
    call). The perfectly matched layers' elements need their nodes' displacements from
    the ranks that own them (:class:`~.pml.PmlLayer`).

    Parameters
    ----------
    comm
        MPI communicator of the rows.
    rows
        ``(r0, r1)``: this rank's rows.
    n_global
        Global size.
    dofs
        Global DOFs whose values this rank needs (sorted, unique; may be empty).
    """

    def __init__(self, comm, rows: tuple[int, int], n_global: int, dofs: np.ndarray):
        from petsc4py import PETSc

        r0, r1 = rows
        self._vec = PETSc.Vec().createMPI((r1 - r0, n_global), comm=comm)
        self._seq = PETSc.Vec().createSeq(len(dofs), comm=PETSc.COMM_SELF)
        index = PETSc.IS().createGeneral(np.asarray(dofs, dtype=PETSc.IntType),
                                         comm=PETSc.COMM_SELF)
        self._scatter = PETSc.Scatter().create(self._vec, index, self._seq, None)
        index.destroy()
        self.time = 0.0

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """The values at the DOFs from this rank's rows ``u`` (a new array)."""
        from petsc4py import PETSc

        t0 = time.perf_counter()
        self._vec.getArray()[:] = u
        self._scatter.scatter(self._vec, self._seq, PETSc.InsertMode.INSERT_VALUES,
                              PETSc.ScatterMode.FORWARD)
        out = self._seq.getArray().copy()
        self.time += time.perf_counter() - t0
        return out

    def destroy(self) -> None:
        for obj in (self._scatter, self._vec, self._seq):
            obj.destroy()


def csr_matrix(comm, local):
    """A distributed AIJ matrix from this rank's rows, a scipy CSR matrix (n_local,
    n_global) with global columns."""
    from petsc4py import PETSc

    local = local.tocsr()
    local.sort_indices()
    n, n_global = local.shape
    A = PETSc.Mat().createAIJ(size=((n, n_global), (n, n_global)),
                              csr=(local.indptr.astype(PETSc.IntType),
                                   local.indices.astype(PETSc.IntType),
                                   local.data.astype(float)), comm=comm)
    A.assemble()
    return A


def _with_diagonal_damping(K, C, diagonal: np.ndarray, comm):
    """``C + diag(diagonal)`` in K's pattern (a new matrix; C may be None)."""
    from petsc4py import PETSc

    out = K.duplicate(copy=False)
    out.zeroEntries()
    if C is not None:
        out.axpy(1.0, C, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
    d = out.createVecLeft()
    d.getArray()[:] = diagonal
    out.setDiagonal(d, addv=PETSc.InsertMode.ADD_VALUES)
    d.destroy()
    return out
