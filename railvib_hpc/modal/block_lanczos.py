"""Block shift-invert Lanczos with thick restart (numpy; the operator is a MUMPS factor).

Why: a single-vector Krylov method reads the whole sparse factor once per
triangular solve; MUMPS solving a block of right-hand sides reads it once per
block (measured here: 96 ms for one right-hand side, 17 ms per right-hand side
in a block of 32, 168k DOFs on 2 ranks). This is what ANSYS's Block Lanczos
exploits.

Method: the operator ``A = (K - sigma M)^-1 M``
(:meth:`~railvib_hpc.model.factor.ShiftInvertFactor.apply`) is self-adjoint in the M inner
product. The basis ``V`` is M-orthonormal (block classical Gram-Schmidt applied
twice, then SVQB normalisation); ``T = V^T M A V`` is accumulated from the
Gram-Schmidt coefficients. Ritz pairs ``(theta, y)`` of ``T`` give eigenvalues
``lambda = sigma + 1/theta``; the residual estimate of a Ritz pair is
``|| B y_last ||`` with ``B`` the coupling to the next block (exact in exact
arithmetic). When the basis is full, the best ``nev + block`` Ritz vectors are
kept (thick restart, Krylov-Schur style arrow matrix) and the expansion goes on
from the next block. A pair is converged when its residual estimate is below
``tol * theta``; the final true residuals ``||K x - lambda M x|| / ||K x||`` are
computed and reported by :func:`railvib_hpc.modal.ritz.normalise_and_check`.

The starting block depends only on global DOF numbers, so the result does not
depend on the number of ranks (beyond round-off).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import eigh

from ..constants import BYTES_PER_DOUBLE, BYTES_PER_GB
from ..model.factor import Progress  # the progress callback of the long phases

if TYPE_CHECKING:
    from ..model.factor import ShiftInvertFactor


def no_progress(phase: str, done: int, total: int) -> None:
    """The default :data:`Progress`: nothing."""


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


def dense_gb(n_global: int, basis: int, block: int, wanted: int, static_cols: int = 0
             ) -> float:
    """Peak of the dense arrays of a block Lanczos solve [GB, all ranks], 8 bytes each.

    The largest of three phases, in n-vectors:

    * Lanczos: the basis (``basis + block``), :data:`LANCZOS_WORK_BLOCKS` work blocks and
      the Ritz vectors ``wanted`` (guards included) formed from the basis at its end;
    * purification (:func:`~railvib_hpc.modal.ritz.purified_modes`, in place): the Ritz
      vectors and the round-off bound of :func:`~railvib_hpc.modal.ritz.normalise_and_check`
      (counted as 3 x ``wanted``, a margin over the two; the K and M products go by blocks)
      and :data:`PURIFY_WORK_BLOCKS` work blocks (at the default basis of 3 x the modes,
      below the Lanczos phase);
    * static solves: the modes, right-hand sides and solutions of ``static_cols`` loads and
      the solve's work blocks.
    """
    lanczos = basis + (1 + LANCZOS_WORK_BLOCKS) * block + wanted
    purify = 3 * wanted + PURIFY_WORK_BLOCKS * block
    static = wanted + 2 * static_cols + PURIFY_WORK_BLOCKS * block
    return BYTES_PER_DOUBLE * n_global * max(lanczos, purify, static) / BYTES_PER_GB


class NotConverged(RuntimeError):
    """Fewer than the wanted eigenpairs converged within the allowed restarts."""


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


def m_orthonormalize_block(op: ShiftInvertFactor, V: np.ndarray, W: np.ndarray, m: int, r0: int,
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


class _LanczosRun:
    """One :func:`block_lanczos` solve between its phases: the M-orthonormal basis ``V``
    (its first ``m`` vectors have their images in ``T``), the projected matrix ``T``, the
    wanted count ``nev`` and the ``keep`` Ritz vectors of a thick restart (both grow with a
    band, ``theta_cut``), the last Ritz pairs ``theta, Y, res``, the counters and the
    timings."""

    def __init__(self, op: ShiftInvertFactor, nev: int, r0: int, b: int, keep: int,
                 max_basis: int, tol: float, theta_cut: float | None, margin: int):
        self.op, self.r0, self.b, self.tol = op, r0, b, tol
        self.nev, self.keep, self.max_basis = nev, keep, max_basis
        self.theta_cut, self.margin = theta_cut, margin
        self.two_sided = op.sigma != 0.0          # theta of both signs: order by modulus
        self.V = np.zeros((op.n_local, max_basis + b), order="F")  # column slices contiguous
        self.T = np.zeros((max_basis + b, max_basis + b))
        self.t_orth = self.t_ritz = 0.0
        self.m = 0                                # vectors whose A-image is in T
        self.restarts = self.expansions = self.tests = 0
        self.theta = self.Y = self.res = None
        self.fresh = -1                           # the basis size of the last Ritz step
        self.nconv, self.next_test, self.history = 0, 0, []
        self.just_restarted = False

    def _orthonormalize(self, W: np.ndarray, m: int, local_from: int | None = None):
        return m_orthonormalize_block(self.op, self.V, W, m, self.r0, local_from)

    def start(self) -> None:
        """The first block of the basis: the reproducible random :func:`start_block`."""
        t0 = time.perf_counter()
        Q, _, _ = self._orthonormalize(start_block(self.op.n_global, self.r0,
                                                   self.r0 + self.op.n_local, self.b), 0)
        self.t_orth += time.perf_counter() - t0
        self.V[:, :self.b] = Q

    def expand(self) -> bool:
        """Expand the block ``V[:, m:m+b]``: its image, orthonormalized, becomes the next
        block and its coefficients a block column of ``T``. Returns whether the basis is
        full (a thick restart is due)."""
        V, T, b, m = self.V, self.T, self.b, self.m
        W = self.op.apply(V[:, m:m + b])
        t0 = time.perf_counter()
        Q, C, R = self._orthonormalize(W, m + b, None if self.just_restarted else max(0, m - b))
        self.just_restarted = False
        self.t_orth += time.perf_counter() - t0
        T[: m + b, m:m + b] += C
        T[m + b:m + 2 * b, m:m + b] = R
        V[:, m + b:m + 2 * b] = Q
        self.m = m + b
        self.expansions += 1
        return self.m + 2 * b > self.max_basis

    def test_due(self, restart_due: bool) -> bool:
        """Whether a convergence test comes now: enough vectors, and its forecast
        (:func:`rr_gap`) says it may pass or a restart is due."""
        return self.m >= self.nev + self.b and (self.expansions >= self.next_test
                                                or restart_due)

    def convergence_test(self, monitor: Callable[[int, int, int], None] | None) -> bool:
        """Rayleigh-Ritz on the ``m`` vectors whose images are known (:func:`ritz_step`);
        with ``theta_cut`` the wanted count grows to the band. Returns whether the wanted
        pairs have converged."""
        m = self.m
        t0 = time.perf_counter()
        self.theta, self.Y, self.res = ritz_step(self.T, m, self.keep, self.b, self.two_sided)
        theta, res = self.theta, self.res
        self.fresh, self.tests = m, self.tests + 1
        ok = res <= self.tol * np.abs(theta)
        self.nconv = int(np.argmin(ok)) if not ok.all() else len(ok)
        if self.theta_cut is not None:
            self._grow_to_band(theta)
        nev = self.nev
        if nev <= len(theta):
            self.history.append((self.expansions, float(np.max(
                res[:nev] / (self.tol * np.abs(theta[:nev]))))))
        self.next_test = self.expansions + rr_gap(self.history)
        self.t_ritz += time.perf_counter() - t0
        if monitor:
            monitor(min(self.nconv, nev), nev, m)
        return self.nconv >= nev

    def _grow_to_band(self, theta: np.ndarray) -> None:
        """The band: every Ritz value above the cut, then ``margin`` converged below it."""
        inside = int(np.sum(np.abs(theta) >= self.theta_cut))
        want = max(self.nev, inside + self.margin)
        if want + 2 * self.b > self.max_basis:
            raise NotConverged(f"block Lanczos: the band holds at least {inside} "
                               f"modes, more than a basis of {self.max_basis} can take")
        if want > self.nev:
            self.nev = want
            self.keep = min(self.nev + self.b, self.max_basis - 2 * self.b)

    def thick_restart(self, max_restarts: int, progress: Progress) -> None:
        """Keep the best ``keep`` Ritz vectors (an arrow matrix ``T``), then the next block;
        :class:`NotConverged` after ``max_restarts``."""
        V, T, b, m = self.V, self.T, self.b, self.m
        if self.restarts >= max_restarts:
            raise NotConverged(f"block Lanczos: {self.nconv} of {self.nev} modes converged "
                               f"after {self.restarts} restarts")
        if self.fresh != m or len(self.theta) < min(self.keep, m):
            # the band grew at the last test (more vectors to keep than it computed)
            t0 = time.perf_counter()
            self.theta, self.Y, self.res = ritz_step(T, m, self.keep, b, self.two_sided)
            self.fresh = m
            self.t_ritz += time.perf_counter() - t0
        p = min(self.keep, len(self.theta))
        t0 = time.perf_counter()
        coupling = T[m:m + b, :m] @ self.Y[:, :p]
        nxt = V[:, m:m + b].copy()
        rows_product(V[:, :m], self.Y[:, :p], V[:, :p], progress, "thick restart")
        V[:, p:p + b] = nxt
        T[:] = 0.0
        T[np.arange(p), np.arange(p)] = self.theta[:p]
        T[p:p + b, :p] = coupling       # its transpose comes from the next expansion
        self.t_orth += time.perf_counter() - t0
        self.m = p
        self.restarts += 1
        self.just_restarted = True

    def ritz_vectors(self, guard: int, progress: Progress
                     ) -> tuple[np.ndarray, np.ndarray, dict]:
        """The converged pairs (with ``theta_cut``: every converged one), ``guard`` more
        Ritz vectors at most, and the statistics."""
        if self.theta_cut is not None:          # return every converged pair (band + margin)
            self.nev = self.nconv
        nev, op = self.nev, self.op
        n_guard = max(0, min(guard, self.Y.shape[1] - nev))
        t0 = time.perf_counter()
        X = np.empty((op.n_local, nev + n_guard))
        rows_product(self.V[:, :self.m], self.Y[:, :nev + n_guard], X, progress, "Ritz vectors")
        self.t_orth += time.perf_counter() - t0
        stats = {"block_size": self.b, "max_basis": self.max_basis, "restarts": self.restarts,
                 "expansions": self.expansions, "basis_size": self.m,
                 "linear_solves": op.n_solves, "time_block_solves": op.time_solves,
                 "time_orthogonalization": self.t_orth, "time_lanczos_ritz": self.t_ritz,
                 "lanczos_ritz_steps": self.tests,
                 "max_residual_estimate": float((self.res[:nev]
                                                 / np.abs(self.theta[:nev])).max()),
                 "n_wanted": int(nev), "n_guard": int(n_guard)}
        return self.theta[:nev], X, stats


def block_lanczos(op: ShiftInvertFactor, nev: int, r0: int, block: int = 32, tol: float = 1e-8,
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
        The shift-invert factor of K - sigma M (its ``apply``, ``mass`` and statistics).
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
    run = _LanczosRun(op, nev, r0, b, keep, max_basis, tol, theta_cut, margin)
    run.start()
    while True:
        restart_due = run.expand()
        if run.test_due(restart_due):
            if run.convergence_test(monitor):
                break
        elif monitor:
            monitor(min(run.nconv, run.nev), run.nev, run.m)
        if restart_due:
            run.thick_restart(max_restarts, progress)
    return run.ritz_vectors(guard, progress)


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
