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
from dataclasses import dataclass, field

import numpy as np

from ..errors import UserError

PREFIX = "railvib_eig_"


class EigenSolveError(UserError):
    """The eigensolver did not deliver the requested modes."""


@dataclass
class ModalResult:
    """Eigenpairs with this rank's rows of the mass-normalised mode matrix."""

    eigenvalues: np.ndarray
    phi: np.ndarray                    # (n_local_dofs, n_modes)
    stats: dict = field(default_factory=dict)
    static: np.ndarray | None = None   # (n_local_dofs, k) K^-1 static_rhs, when asked for
    residuals: np.ndarray | None = None        # (m,) relative residuals (normalise_and_check)
    residual_floors: np.ndarray | None = None  # (m,) their round-off floors (where > tol)
    warnings: list[str] = field(default_factory=list)   # see convergence_verdict

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.sqrt(np.maximum(self.eigenvalues, 0.0)) / (2 * np.pi)


def _configure(K, M, comm, n_modes: int, f_max: float, shift_hz: float, tol: float,
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


def solve_modes(K, M, comm, n_modes: int = 300, f_max: float = 0.0, shift_hz: float = 0.0,
                tol: float = 1e-8, max_it: int = 1000, mpd: int = 0,
                method: str = "block_lanczos", block_size: int = 32, max_basis: int = 0,
                monitor=None, static_rhs: np.ndarray | None = None,
                out_of_core: str = "auto", bands=None, assemble=None) -> ModalResult | None:
    """Extract mass-normalised modes.

    Parameters
    ----------
    K, M
        Assembled PETSc matrices (symmetric, K positive definite after constraints).
    comm
        Communicator of the matrices.
    n_modes
        Number of modes (used when ``f_max`` is 0).
    f_max
        If > 0, all modes with frequency in [shift_hz, f_max] (spectrum slicing).
    shift_hz
        Shift of the spectral transformation, as a frequency.
    tol, max_it
        Relative residual tolerance and maximum restarts.
    mpd
        Maximum projected dimension (bounds memory); 0 lets SLEPc decide.
    method
        ``"block_lanczos"`` (block shift-invert Lanczos, :mod:`.block_lanczos`; with
        ``f_max``: band-sliced, :mod:`.band_solve`) or ``"krylovschur"`` (SLEPc; with
        ``f_max``: SLEPc spectrum slicing).
    block_size, max_basis
        Block Lanczos: right-hand sides per solve and restart size (0: automatic).
    monitor
        Progress callback ``monitor(n_converged, n_wanted, basis_size)`` (band-sliced:
        ``monitor(done, total, basis_size, label=...)`` over all bands).
    static_rhs
        (n_local_dofs, k) right-hand sides solved with the factorization of K
        when the block solver factors K itself (shift 0); the solutions are
        returned in ``ModalResult.static`` (None otherwise: factor K separately).
    out_of_core
        MUMPS out-of-core factorization: ``"auto"`` (block Lanczos: when the in-core
        factor would not fit in memory but the out-of-core one does), ``"always"`` or
        ``"never"``; an explicit ``-railvib_eig_st_mat_mumps_icntl_22`` option wins.
    bands
        :class:`~railvib_hpc.modal.band_solve.BandSettings` of a band-sliced solve
        (``f_max`` with block Lanczos); None: one band plan with the defaults and a
        temporary cache folder.
    assemble
        ``assemble(subcomm) -> (K, M)``: the matrices on a sub-communicator (band groups).

    Raises
    ------
    EigenSolveError
        When fewer than the requested modes converged, or when a mode's true relative
        residual is above ``tol`` (and above its round-off floor, or above ``sqrt(tol)``):
        see :func:`convergence_verdict`. Round-off-limited modes come back with
        ``ModalResult.warnings``.
    """
    from petsc4py import PETSc

    n_global = K.getSize()[0]
    if f_max <= 0 and n_modes >= n_global:
        raise EigenSolveError(f"modal.n_modes = {n_modes}: must be smaller than the number of "
                              f"free DOFs ({n_global})")
    if method == "block_lanczos" and f_max <= 0:
        return _solve_block(K, M, comm, n_modes, shift_hz, tol, max_it, block_size, max_basis,
                            monitor, static_rhs, out_of_core)
    if method == "block_lanczos":
        return _solve_bands(K, M, comm, f_max, tol, max_it, block_size, monitor, static_rhs,
                            out_of_core, bands, assemble)
    ooc_name = f"{PREFIX}st_mat_mumps_icntl_22"
    set_ooc = out_of_core == "always" and not PETSc.Options().hasName(ooc_name)
    if set_ooc:
        PETSc.Options().setValue(ooc_name, 1)
    try:
        return _solve_slepc(K, M, comm, n_modes, f_max, shift_hz, tol, max_it, mpd, monitor)
    finally:
        if set_ooc:
            PETSc.Options().delValue(ooc_name)


def _solve_bands(K, M, comm, f_max: float, tol: float, max_it: int, block_size: int, monitor,
                 static_rhs, out_of_core: str, bands, assemble) -> ModalResult | None:
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
                             out_of_core=out_of_core, cache_dir=Path(tmp), key="temporary")
    try:
        return solve_bands(K, M, comm, bands, assemble=assemble, monitor=monitor,
                           static_rhs=static_rhs)
    finally:
        comm.Barrier()
        if tmp is not None and comm.rank == 0:
            shutil.rmtree(tmp, ignore_errors=True)


def _solve_slepc(K, M, comm, n_modes: int, f_max: float, shift_hz: float, tol: float,
                 max_it: int, mpd: int, monitor) -> ModalResult:
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
    result = ModalResult(lam, phi, stats)
    normalise_and_check(result, K, M, comm, tol=stats["tol"])
    result.warnings = convergence_verdict(result, stats["tol"])
    return result


def _solve_block(K, M, comm, n_modes: int, shift_hz: float, tol: float, max_restarts: int,
                 block_size: int, max_basis: int, monitor,
                 static_rhs: np.ndarray | None = None, out_of_core: str = "auto") -> ModalResult:
    from mpi4py import MPI
    from petsc4py import PETSc

    from .block_lanczos import (
        BlockOperator,
        FactorizationError,
        InsufficientMemory,
        NotConverged,
        block_lanczos,
        default_max_basis,
        dense_gb,
    )

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
        op = BlockOperator(K, M, sigma, comm, PREFIX, extra_gb=extra_gb,
                           out_of_core=out_of_core)
    except (InsufficientMemory, FactorizationError) as exc:
        raise EigenSolveError(str(exc)) from None
    r0 = K.getOwnershipRange()[0]
    try:
        for lanczos_tol in (tol, tol / RETRY_TOL_FACTOR):
            _, X, st = block_lanczos(op, n_modes, r0, block=block_size, tol=lanczos_tol,
                                     max_basis=max_basis, max_restarts=max_restarts,
                                     monitor=monitor, guard=block_size)
            t_p = time.perf_counter()
            result = purified_modes(op, X, st["block_size"], K, M, comm, tol, st)
            st["time_purify_project"] = time.perf_counter() - t_p
            st["lanczos_tol"] = lanczos_tol
            if not hopeless(result, tol).any():
                break
        static = None
        if static_rhs is not None and sigma == 0.0:
            t_s = time.perf_counter()
            static = op.solve(static_rhs)
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
                        time_solve=t1 - t0 - op.time_factorization, time_extract=0.0)
    result.static = static
    result.warnings = convergence_verdict(result, tol)
    return result


#: When the true residuals stay above modal.tol after the purification passes, block
#: Lanczos runs once more (same factor) with its convergence test at tol / this factor: the
#: true relative residual of a purified Ritz pair exceeds the Lanczos estimate by up to
#: about the square root of the condition of the diagonally scaled mass matrix (27 for
#: trilinear hexahedra, sqrt ~ 5; measured 2x on the 80-element column on 2 ranks).
RETRY_TOL_FACTOR = 10.0

#: Extra purification passes (one more application of the shift-invert operator, with one
#: step of iterative refinement of each solve, and a Rayleigh-Ritz step) when a Ritz pair's
#: *true* residual is above the tolerance although the Lanczos estimate converged. Each pass
#: damps the high-frequency error components by lambda_i / lambda_j; the refinement removes
#: the part of the residual left by an inaccurate factorisation (measured: MUMPS on 2 ranks
#: solves the coarse thesis model to a relative residual of 9e-9, on 1 rank to 1e-11).
EXTRA_PURIFICATIONS = 2


def purified_modes(op, X: np.ndarray, block: int, K, M, comm, tol: float,
                   stats: dict | None = None,
                   window: tuple[float, float] | None = None) -> ModalResult:
    """Purify and project Ritz vectors, normalise, and purify again (at most
    :data:`EXTRA_PURIFICATIONS` times, with iterative refinement) while some true residual
    is above ``tol`` and above its round-off floor. Needs the factor of ``op``; returns the
    checked modes, whose ``residual_floors`` also cover the solves' residuals.

    ``X`` holds ``stats["n_wanted"]`` wanted Ritz vectors followed by ``stats["n_guard"]``
    guard vectors (the next Ritz vectors): the first pass projects on the wanted ones only;
    the extra passes include the guards, so that the components of the next modes, which
    purification damps only by lambda_i / lambda_j ~ 1 near the top of the set, are removed
    by the Rayleigh-Ritz step instead; the ``n_wanted`` nearest to the shift are kept.
    ``window``: only the eigenvalues in ``[lo, hi]`` must converge (a band; the pairs beyond
    its edges belong to the neighbouring bands).
    """
    from mpi4py import MPI

    from .block_lanczos import purify_and_project

    stats = {} if stats is None else stats
    n_wanted = int(stats.get("n_wanted", X.shape[1]))
    guards = X[:, n_wanted:]
    X = X[:, :n_wanted]
    for attempt in range(EXTRA_PURIFICATIONS + 1):
        basis = X if attempt == 0 or guards.shape[1] == 0 else np.hstack([X, guards])
        lam, Xp, KX, MX, solve_res = purify_and_project(op, basis, block, refine=attempt > 0)
        # the n_wanted nearest to the shift (all of them on the first pass), ascending
        near = np.sort(np.argsort(np.abs(lam - op.sigma), kind="stable")[:n_wanted])
        order = near[np.argsort(lam[near], kind="stable")]
        result = ModalResult(lam[order], np.ascontiguousarray(Xp[:, order]), {})
        normalise_and_check(result, K, M, comm, KX[:, order], MX[:, order], tol=tol)
        stats["extra_purifications"] = attempt
        if not (unconverged(result, tol) & in_window(result, window)).any():
            break
        if guards.shape[1]:
            rest = np.setdiff1d(np.arange(len(lam)), order)
            guards = np.ascontiguousarray(Xp[:, rest])
        X = result.phi
    # the solves' own residuals are a floor too (relative to ||K phi||; scale-free)
    knorm = np.sqrt(comm.allreduce(np.sum(KX[:, order] ** 2, axis=0), op=MPI.SUM))
    solve_floor = solve_res[order] / knorm
    result.residual_floors = np.maximum(result.residual_floors, solve_floor)
    stats["max_solve_residual"] = float(solve_floor.max())
    return result


def in_window(result: ModalResult, window: tuple[float, float] | None) -> np.ndarray:
    """Modes whose eigenvalue lies in ``window`` (all without one)."""
    lam = result.eigenvalues
    if window is None:
        return np.ones(len(lam), dtype=bool)
    return (lam >= window[0]) & (lam <= window[1])


def unconverged(result: ModalResult, tol: float) -> np.ndarray:
    """Modes whose relative residual exceeds both ``tol`` and its round-off floor."""
    return result.residuals > np.maximum(tol, result.residual_floors)


def hopeless(result: ModalResult, tol: float) -> np.ndarray:
    """Modes :func:`convergence_verdict` rejects: above ``RETRY_TOL_FACTOR * tol`` and above
    their round-off floor, or above ``sqrt(tol)`` and ``tol``."""
    res, floor = result.residuals, result.residual_floors
    return (res > np.maximum(RETRY_TOL_FACTOR * tol, floor)) | \
        ((res > np.sqrt(tol)) & (res > tol))


def convergence_verdict(result: ModalResult, tol: float) -> list[str]:
    """Judge the final residuals: raise, warn, or accept (the documented rule).

    With ``rho`` the relative residual ``||K phi - lambda M phi|| / ||K phi||`` of a mode
    and ``floor`` its round-off floor (:func:`normalise_and_check`):

    * ``rho <= tol``: converged.
    * ``tol < rho <= floor`` and ``rho <= sqrt(tol)``: limited by round-off (an
      ill-conditioned model: tiny or extremely flat elements, huge stiffness contrasts).
      Accepted with a warning: the eigenvalue error is ``~ rho^2 / relgap`` (Kato-Temple),
      no worse than what ``tol`` buys for eigenvalues, but the shapes are only accurate to
      ``~ rho / relgap``.
    * ``tol < rho <= RETRY_TOL_FACTOR * tol`` (after the extra purifications and a Lanczos
      run at ``tol / RETRY_TOL_FACTOR``): accepted with a warning. The solver's own test
      (on the shift-inverted operator) is met; the true residual exceeds it by the
      scaling of the mass matrix (see :data:`RETRY_TOL_FACTOR`).
    * otherwise (:func:`hopeless`): :class:`EigenSolveError` naming the count, the worst
      residual, its mode and the floor.

    Returns the warnings (empty when every mode converged).
    """
    res, floor = result.residuals, result.residual_floors
    f = result.frequencies_hz
    bad = hopeless(result, tol)
    if bad.any():
        worst = int(np.argmax(np.where(bad, res, -1.0)))
        n_bad, m = int(bad.sum()), len(res)
        cause = ("round-off: the model is too ill-conditioned for double precision "
                 "(see the mesh check: aspect ratios, tiny elements, stiffness contrasts)"
                 if floor[worst] >= res[worst] else
                 f"the eigensolver stopped early; try a larger -{PREFIX}bl_max_basis / "
                 f"modal.max_basis, more modal.max_restarts, or a looser modal.tol")
        raise EigenSolveError(
            f"{n_bad} of {m} modes did not converge: worst relative residual "
            f"{res[worst]:.2e} (mode {worst + 1}, {f[worst]:.3f} Hz) > modal.tol = {tol:.1e} "
            f"(round-off floor {floor[worst]:.1e}); cause: {cause}")
    out = []
    limited = (res > tol) & (res <= floor)
    near = (res > tol) & ~limited
    if limited.any():
        worst = int(np.argmax(np.where(limited, res, -1.0)))
        out.append(f"{int(limited.sum())} of {len(res)} modes are limited by round-off: "
                   f"relative residual up to {res[worst]:.2e} (mode {worst + 1}, "
                   f"{f[worst]:.3f} Hz) > modal.tol = {tol:.1e}, at the round-off floor "
                   f"{floor[worst]:.1e} of this ill-conditioned model; their frequencies are "
                   "accurate to ~residual^2, their shapes only to ~residual / relative gap "
                   "(check the mesh: aspect ratios, tiny elements)")
    if near.any():
        worst = int(np.argmax(np.where(near, res, -1.0)))
        out.append(f"{int(near.sum())} of {len(res)} modes end with a relative residual "
                   f"above modal.tol = {tol:.1e}, up to {res[worst]:.2e} (mode {worst + 1}, "
                   f"{f[worst]:.3f} Hz; <= {RETRY_TOL_FACTOR:g} x tol: the solver's own test "
                   "is met, the mass matrix's scaling makes the true residual larger); "
                   "frequencies accurate to ~residual^2")
    return out


#: Columns per chunk when normalise_and_check forms K Phi and M Phi itself.
NORMALISE_CHUNK = 64


def normalise_and_check(result: ModalResult, K, M, comm, KPhi: np.ndarray | None = None,
                        MPhi: np.ndarray | None = None, tol: float = 0.0) -> None:
    """Scale modes to unit modal mass and record max |Phi^T M Phi - I| and residuals.

    ``KPhi``/``MPhi`` may be given when already computed (they are scaled along).

    Records the relative residuals ``rho_i = ||K phi_i - lambda_i M phi_i|| / ||K phi_i||``
    (``result.residuals``) and, for the modes with ``rho_i > tol``, their round-off floor
    ``gamma_k || |K| |phi_i| + |lambda_i| |M| |phi_i| || / ||K phi_i||`` (k = longest row
    + 1, :func:`railvib_hpc.tolerances.gamma`; ``result.residual_floors``, 0 elsewhere):
    the error of evaluating the residual in double precision, below which no solver can
    verify an eigenpair. (Computing it needs |K| and |M|, so it is only done when needed.)
    """
    from mpi4py import MPI

    from .. import tolerances

    t0 = time.perf_counter()
    from .block_lanczos import abs_matrix, longest_row, sparse_times_block

    phi = result.phi
    lam = result.eigenvalues
    if KPhi is None and MPhi is None:
        # column chunks: no (n, m) copies of K Phi and M Phi (many modes of a big model)
        chunk = NORMALISE_CHUNK
        cols = [slice(j, j + chunk) for j in range(0, phi.shape[1], chunk)]
        modal_mass = np.concatenate([np.einsum("ij,ij->j", phi[:, c], sparse_times_block(
            M, phi[:, c], comm)) for c in cols]) if cols else np.zeros(0)
        phi *= 1.0 / np.sqrt(comm.allreduce(modal_mass, op=MPI.SUM))
        gram = np.empty((len(lam), len(lam)))
        stiff = np.empty_like(gram)
        res = np.empty(len(lam))
        knorm = np.empty(len(lam))
        for c in cols:
            MP, KP = sparse_times_block(M, phi[:, c], comm), sparse_times_block(K, phi[:, c], comm)
            gram[:, c], stiff[:, c] = phi.T @ MP, phi.T @ KP
            res[c] = np.sum((KP - MP * lam[c]) ** 2, axis=0)
            knorm[c] = np.sum(KP**2, axis=0)
        for a in (gram, stiff, res, knorm):
            comm.Allreduce(MPI.IN_PLACE, a, op=MPI.SUM)
    else:
        if MPhi is None:
            MPhi = sparse_times_block(M, phi, comm)
        modal_mass = comm.allreduce(np.einsum("ij,ij->j", phi, MPhi), op=MPI.SUM)
        scale = 1.0 / np.sqrt(modal_mass)
        phi *= scale
        MPhi = MPhi * scale
        KPhi = sparse_times_block(K, phi, comm) if KPhi is None else KPhi * scale
        gram = comm.allreduce(phi.T @ MPhi, op=MPI.SUM)
        stiff = comm.allreduce(phi.T @ KPhi, op=MPI.SUM)
        res = comm.allreduce(np.sum((KPhi - MPhi * lam) ** 2, axis=0), op=MPI.SUM)
        knorm = comm.allreduce(np.sum(KPhi**2, axis=0), op=MPI.SUM)
    result.residuals = np.sqrt(res / knorm)
    floor = np.zeros(len(lam))
    need = np.flatnonzero(result.residuals > tol)
    if need.size:
        k = max(longest_row(K, comm), longest_row(M, comm)) + 1
        absphi = np.abs(phi[:, need])
        bound = np.zeros_like(absphi)
        for A, w in ((K, 1.0), (M, np.abs(lam[need]))):
            Aabs = abs_matrix(A, comm)
            bound += sparse_times_block(Aabs, absphi, comm) * w
            Aabs.destroy()
        floor[need] = tolerances.gamma(k) * np.sqrt(
            comm.allreduce(np.sum(bound**2, axis=0), op=MPI.SUM) / knorm[need])
    result.residual_floors = floor
    result.stats.update({
        "max_orthonormality_error": float(np.abs(gram - np.eye(len(lam))).max()),
        "max_stiffness_diag_error": float(np.abs(stiff - np.diag(lam)).max() / lam.max()),
        "max_relative_residual": float(result.residuals.max()),
        "max_residual_floor": float(floor.max()),
        "time_checks": time.perf_counter() - t0,
    })
