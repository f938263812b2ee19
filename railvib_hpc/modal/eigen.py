"""SLEPc eigensolve of K phi = lambda M phi (PETSc/SLEPc code).

Krylov-Schur, generalized Hermitian, shift-and-invert with a parallel sparse
direct Cholesky factorization (MUMPS). The solver object has the options prefix
``railvib_eig_`` and calls ``setFromOptions`` once, so every setting can be
overridden on the command line (``railvib modal CASE -- -railvib_eig_eps_ncv 700``).

``n_modes`` mode: the ``n_modes`` eigenvalues closest to the shift (the lowest,
for the default shift 0 on a positive definite K). ``f_max`` mode: every
eigenvalue in [shift, (2 pi f_max)^2] by spectrum slicing, MUMPS inertia
counts guaranteeing none is missed.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from mpi4py import MPI

from .ritz import (  # noqa: F401  (re-exported: the solver's public names)
    EXTRA_PURIFICATIONS,
    NORMALISE_CHUNK,
    PREFIX,
    RETRY_TOL_FACTOR,
    Eigenpairs,
    EigenSolveError,
    convergence_verdict,
    hopeless,
    in_window,
    normalise_and_check,
    purified_modes,
    unconverged,
)


def _configure(K, M, comm: MPI.Comm, n_modes: int, f_max: float, shift_hz: float, tol: float,
               max_it: int, mpd: int):
    from petsc4py import PETSc
    from slepc4py import SLEPc

    eps = SLEPc.EPS().create(comm)
    if f_max > 0:
        # MUMPS reports the inertia (needed by spectrum slicing) only for SBAIJ matrices;
        # converted copies (petsc4py's convert() without a target converts in place)
        K = K.convert(PETSc.Mat.Type.SBAIJ, PETSc.Mat())
        M = M.convert(PETSc.Mat.Type.SBAIJ, PETSc.Mat())
    eps.setOperators(K, M)
    eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
    eps.setType(SLEPc.EPS.Type.KRYLOVSCHUR)
    sigma = (2 * np.pi * shift_hz) ** 2
    st = eps.getST()
    st.setType(SLEPc.ST.Type.SINVERT)
    ksp = st.getKSP()
    ksp.setType(PETSc.KSP.Type.PREONLY)
    pc = ksp.getPC()
    pc.setType(PETSc.PC.Type.CHOLESKY)
    pc.setFactorSolverType("mumps")
    opts = PETSc.Options()
    if f_max > 0:
        eps.setWhichEigenpairs(SLEPc.EPS.Which.ALL)
        eps.setInterval(sigma, (2 * np.pi * f_max) ** 2)
        # MUMPS must report the inertia (ICNTL(13) = 1) for spectrum slicing in parallel
        if not opts.hasName(f"{PREFIX}st_mat_mumps_icntl_13"):
            opts.setValue(f"{PREFIX}st_mat_mumps_icntl_13", 1)
        eps.setKrylovSchurDimensions(nev=min(n_modes, 200), mpd=mpd)
    else:
        eps.setDimensions(nev=n_modes, mpd=mpd)
        eps.setTarget(sigma)
        eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_MAGNITUDE)
    eps.setTolerances(tol, max_it)
    eps.setOptionsPrefix(PREFIX)
    eps.setFromOptions()
    return eps


@dataclass(frozen=True)
class ModalProblem:
    """The eigenproblem ``K phi = lambda M phi``: what is asked, not how it is solved.

    The problem half of the problem/solver split (:class:`ModalSolver` is the other),
    as Firedrake's ``LinearEigenproblem`` / ``LinearEigensolver``.

    Attributes
    ----------
    K, M
        Assembled PETSc matrices (symmetric, K positive definite after constraints).
    comm
        Communicator of the matrices.
    n_modes
        Number of modes (used when ``f_max`` is 0): the ``n_modes`` closest to the shift.
    f_max
        If > 0, all modes with frequency in [shift_hz, f_max] (spectrum slicing).
    shift_hz
        Shift of the spectral transformation, as a frequency.
    static_rhs
        (n_local_dofs, k) right-hand sides solved with the factorization of K when the
        block solver factors K itself (shift 0); the solutions are returned in
        ``Eigenpairs.static`` (None otherwise: factor K separately).
    assemble
        ``assemble(subcomm) -> (K, M)``: the matrices on a sub-communicator (band groups).

    Examples
    --------
    >>> ModalProblem(K=None, M=None, comm=None, f_max=44.0).sliced
    True
    """

    K: Any
    M: Any
    comm: Any
    n_modes: int = 300
    f_max: float = 0.0
    shift_hz: float = 0.0
    static_rhs: np.ndarray | None = None
    assemble: Callable | None = None

    @property
    def sliced(self) -> bool:
        """Whether every mode below ``f_max`` is asked for (else ``n_modes`` of them)."""
        return self.f_max > 0


@dataclass(frozen=True)
class ModalSolver:
    """How an eigenproblem is solved: the solver half of the problem/solver split.

    Attributes
    ----------
    method
        ``"block_lanczos"`` (block shift-invert Lanczos, :mod:`.block_lanczos`; with
        ``f_max``: band-sliced, :mod:`.band_solve`) or ``"krylovschur"`` (SLEPc; with
        ``f_max``: SLEPc spectrum slicing).
    tol, max_it
        Relative residual tolerance and maximum restarts.
    mpd
        Maximum projected dimension (bounds memory); 0 lets SLEPc decide.
    block_size, max_basis
        Block Lanczos: right-hand sides per solve and restart size (0: automatic).
    out_of_core
        MUMPS out-of-core factorization: ``"auto"`` (block Lanczos: when the in-core
        factor would not fit in memory but the out-of-core one does), ``"always"`` or
        ``"never"``; an explicit ``-railvib_eig_st_mat_mumps_icntl_22`` option wins.
    bands
        :class:`~railvib_hpc.modal.band_solve.BandSettings` of a band-sliced solve
        (``f_max`` with block Lanczos); None: one band plan with the defaults and a
        temporary cache folder.
    monitor
        Progress callback ``monitor(n_converged, n_wanted, basis_size)`` (band-sliced:
        ``monitor(done, total, basis_size, label=...)`` over all bands).
    log
        Band-sliced: ``log(line)`` gets one line per solved band (modes, time, memory).
    progress
        ``progress(phase, done, total)``: the phases after (and between) the Lanczos
        expansions, which ``monitor`` does not cover: thick restarts, Ritz vectors,
        purification, Rayleigh-Ritz, residual checks, round-off floors, the band merge
        (:data:`~railvib_hpc.model.factor.Progress`).

    Examples
    --------
    >>> ModalSolver(method="krylovschur", tol=1e-10).block_size
    32
    """

    method: str = "block_lanczos"
    tol: float = 1e-8
    max_it: int = 1000
    mpd: int = 0
    block_size: int = 32
    max_basis: int = 0
    out_of_core: str = "auto"
    bands: Any = None
    monitor: Callable | None = None
    log: Callable | None = None
    progress: Callable | None = None

    def solve(self, problem: ModalProblem) -> Eigenpairs | None:
        """Extract the mass-normalised modes of ``problem`` (collective on its comm).

        Returns None for a band-only run (``bands.band_only``: one band cached).

        Raises
        ------
        EigenSolveError
            When fewer than the requested modes converged, or when a mode's true relative
            residual is above ``tol`` (by more than its round-off floor, or above
            ``sqrt(tol)``): see :func:`convergence_verdict`. Round-off-limited modes come
            back with ``Eigenpairs.warnings``.
        """
        from petsc4py import PETSc

        K, M, comm = problem.K, problem.M, problem.comm
        n_modes, f_max, tol = problem.n_modes, problem.f_max, self.tol
        n_global = K.getSize()[0]
        if f_max <= 0 and n_modes >= n_global:
            raise EigenSolveError(f"modal.n_modes = {n_modes}: must be smaller than the number "
                                  f"of free DOFs ({n_global})")
        if self.method == "block_lanczos" and f_max <= 0:
            from .block_lanczos import effective_block

            b = effective_block(PETSc.Options(PREFIX).getInt("bl_block_size", self.block_size),
                                n_global)
            if n_modes + 3 * b > n_global:      # block Lanczos: nev + 2 b <= basis <= n - b
                raise EigenSolveError(
                    f"modal.n_modes = {n_modes}: block Lanczos with blocks of {b} finds at most "
                    f"{max(n_global - 3 * b, 0)} modes of {n_global} free DOFs (n_modes + 3 x "
                    "block size <= DOFs); use fewer modes or modal.method = 'krylovschur'")
            return _solve_block(K, M, comm, n_modes, problem.shift_hz, tol, self.max_it,
                                self.block_size, self.max_basis, self.monitor,
                                problem.static_rhs, self.out_of_core, self.progress)
        if self.method == "block_lanczos":
            return _solve_bands(K, M, comm, f_max, tol, self.max_it, self.block_size,
                                self.monitor, problem.static_rhs, self.out_of_core, self.bands,
                                problem.assemble, self.log, self.progress)
        ooc_name = f"{PREFIX}st_mat_mumps_icntl_22"
        set_ooc = self.out_of_core == "always" and not PETSc.Options().hasName(ooc_name)
        if set_ooc:
            PETSc.Options().setValue(ooc_name, 1)
        try:
            return _solve_slepc(K, M, comm, n_modes, f_max, problem.shift_hz, tol, self.max_it,
                                self.mpd, self.monitor, self.progress)
        finally:
            if set_ooc:
                PETSc.Options().delValue(ooc_name)


#: The keywords of :func:`solve_modes` that belong to the problem (the rest: the solver).
_PROBLEM_KEYS = ("n_modes", "f_max", "shift_hz", "static_rhs", "assemble")


def solve_modes(K, M, comm: MPI.Comm, **options) -> Eigenpairs | None:
    """Extract mass-normalised modes: ``ModalSolver(...).solve(ModalProblem(K, M, comm,
    ...))`` in one call, the keywords of each going to it (see :class:`ModalProblem` and
    :class:`ModalSolver` for them).

    Raises
    ------
    TypeError
        For a keyword neither takes.
    EigenSolveError
        As :meth:`ModalSolver.solve`.
    """
    problem = {k: options.pop(k) for k in _PROBLEM_KEYS if k in options}
    return ModalSolver(**options).solve(ModalProblem(K, M, comm, **problem))


def _solve_bands(K, M, comm: MPI.Comm, f_max: float, tol: float, max_it: int, block_size: int,
                 monitor, static_rhs, out_of_core: str, bands, assemble,
                 log=None, progress=None) -> Eigenpairs | None:
    """Band-sliced block Lanczos (:mod:`.band_solve`); a temporary cache without settings."""
    import shutil
    import tempfile
    from pathlib import Path

    from petsc4py import PETSc

    from .band_solve import BandSettings, solve_bands

    opts = PETSc.Options(PREFIX)
    tol = opts.getReal("eps_tol", tol)
    block_size = opts.getInt("bl_block_size", block_size)
    tmp = None
    if bands is None:
        tmp = comm.bcast(tempfile.mkdtemp(prefix="railvib-bands-") if comm.rank == 0 else None)
        bands = BandSettings(f_max=f_max, edges=[], band_modes=250, groups=1, band_only=0,
                             tol=tol, block_size=block_size, max_restarts=max_it,
                             out_of_core=out_of_core, cache_dir=Path(tmp))
    try:
        return solve_bands(K, M, comm, bands, assemble=assemble, monitor=monitor,
                           static_rhs=static_rhs, log=log, progress=progress)
    finally:
        comm.Barrier()
        if tmp is not None and comm.rank == 0:
            shutil.rmtree(tmp, ignore_errors=True)


def _solve_slepc(K, M, comm: MPI.Comm, n_modes: int, f_max: float, shift_hz: float, tol: float,
                 max_it: int, mpd: int, monitor, progress=None) -> Eigenpairs:
    """SLEPc Krylov-Schur (or spectrum slicing when ``f_max > 0``)."""
    from petsc4py import PETSc

    eps = _configure(K, M, comm, n_modes, f_max, shift_hz, tol, max_it,
                     mpd if mpd > 0 else PETSc.DECIDE)
    if monitor is not None:
        eps.setMonitor(lambda e, its, nconv, *a: monitor(min(nconv, n_modes), n_modes,
                                                         e.getDimensions()[1]))
    PETSc.Log.begin()                      # event counts (cheap); also enables -log_view
    solves = PETSc.Log.Event("MatSolve")
    solves0 = solves.getPerfInfo()["count"]
    t0 = time.perf_counter()
    eps.setUp()                            # symbolic + numeric factorization of K - sigma M
    t1 = time.perf_counter()
    eps.solve()
    t2 = time.perf_counter()
    nconv = eps.getConverged()
    reason = eps.getConvergedReason()
    wanted = n_modes if f_max <= 0 else nconv
    if reason < 0 or nconv < wanted:
        raise EigenSolveError(
            f"eigensolver converged {nconv} of {wanted} requested modes (reason {reason}, "
            f"{eps.getIterationNumber()} restarts); try a larger -{PREFIX}eps_max_it or "
            f"-{PREFIX}eps_ncv, or fewer modes (modal.n_modes)")
    if f_max > 0 and nconv == 0:
        raise EigenSolveError(f"modal.f_max = {f_max}: no mode below this frequency")
    vr, _ = K.createVecs()
    n_local = vr.getLocalSize()
    lam = np.empty(wanted)
    phi = np.empty((n_local, wanted))
    for i in range(wanted):
        lam[i] = eps.getEigenpair(i, vr).real
        phi[:, i] = vr.getArray()
    order = np.argsort(lam, kind="stable")
    lam, phi = lam[order], np.ascontiguousarray(phi[:, order])
    t3 = time.perf_counter()
    ksp = eps.getST().getKSP()
    stats = {
        "nconv": int(nconv), "restarts": int(eps.getIterationNumber()),
        "linear_solves": int(solves.getPerfInfo()["count"] - solves0),
        "eps_type": eps.getType(), "st_type": eps.getST().getType(),
        "factor_solver": ksp.getPC().getFactorSolverType(),
        "ncv": int(eps.getDimensions()[1]), "mpd": int(eps.getDimensions()[2]),
        "tol": float(eps.getTolerances()[0]),
        "time_factorization": t1 - t0, "time_solve": t2 - t1, "time_extract": t3 - t2,
    }
    for A in eps.getOperators():
        if A is not None and A.getType() == "sbaij":      # the copies made for slicing
            A.destroy()
    eps.destroy()
    result = Eigenpairs(lam, phi, stats)
    normalise_and_check(result, K, M, comm, tol=stats["tol"], progress=progress)
    result.warnings = convergence_verdict(result, stats["tol"])
    return result


def _solve_block(K, M, comm: MPI.Comm, n_modes: int, shift_hz: float, tol: float, max_restarts: int,
                 block_size: int, max_basis: int, monitor,
                 static_rhs: np.ndarray | None = None, out_of_core: str = "auto",
                 progress=None) -> Eigenpairs:
    from mpi4py import MPI
    from petsc4py import PETSc

    from ..model.factor import FactorizationError, InsufficientMemory, ShiftInvertFactor
    from .block_lanczos import NotConverged, block_lanczos, default_max_basis, dense_gb

    opts = PETSc.Options(PREFIX)
    block_size = opts.getInt("bl_block_size", block_size)
    max_basis = opts.getInt("bl_max_basis", max_basis)
    tol = opts.getReal("eps_tol", tol)
    sigma = (2 * np.pi * shift_hz) ** 2
    t0 = time.perf_counter()
    n_global = K.getSize()[0]
    basis = max_basis if max_basis > 0 else default_max_basis(n_modes, block_size)
    extra_gb = dense_gb(n_global, basis, block_size, n_modes + block_size,
                        0 if static_rhs is None else comm.allreduce(
                            static_rhs.shape[1], op=MPI.MAX))
    try:
        op = ShiftInvertFactor(K, M, sigma, comm, PREFIX, extra_gb=extra_gb,
                               out_of_core=out_of_core)
    except (InsufficientMemory, FactorizationError) as exc:
        raise EigenSolveError(str(exc)) from None
    r0 = K.getOwnershipRange()[0]
    try:
        for lanczos_tol in (tol, tol / RETRY_TOL_FACTOR):
            result = X = None              # a retry's Lanczos run reuses their memory
            _, X, st = block_lanczos(op, n_modes, r0, block=block_size, tol=lanczos_tol,
                                     max_basis=max_basis, max_restarts=max_restarts,
                                     monitor=monitor, guard=block_size, progress=progress)
            t_p = time.perf_counter()
            result = purified_modes(op, X, st["block_size"], K, M, comm, tol, st,
                                    progress=progress)
            st["time_purify_project"] = time.perf_counter() - t_p
            st["lanczos_tol"] = lanczos_tol
            if not hopeless(result, tol).any():
                break
        static = None
        if static_rhs is not None and sigma == 0.0:
            t_s = time.perf_counter()
            static = op.solve(static_rhs, progress=progress, phase="static solves")
            st["time_static_solves"] = time.perf_counter() - t_s
    except NotConverged as exc:
        raise EigenSolveError(f"{exc}; try a larger -{PREFIX}bl_max_basis or fewer modes "
                              "(modal.n_modes)") from None
    finally:
        op.destroy()
    t1 = time.perf_counter()
    result.stats.update(st, nconv=int(n_modes), eps_type="block_lanczos", st_type="sinvert",
                        factor_solver="mumps", tol=tol,
                        time_factorization=op.time_factorization,
                        factor_memory_gb=op.factor_memory_gb, out_of_core=op.out_of_core,
                        factor_memory_in_core_gb=op.in_core_memory_gb,
                        predicted_peak_gb=op.predicted_peak_gb,
                        predicted_parts_gb=dict(op.memory_parts),
                        time_solve=t1 - t0 - op.time_factorization, time_extract=0.0)
    result.static = static
    result.warnings = convergence_verdict(result, tol)
    return result
