"""Ritz pairs of the shift-invert solvers: results, purification, normalisation, checks.

The eigenpairs (:class:`Eigenpairs`), the purification and Rayleigh-Ritz step applied to
block Lanczos's Ritz vectors (:func:`purified_modes`), the unit-modal-mass normalisation with
the true residuals and their round-off floors (:func:`normalise_and_check`) and the
convergence verdicts. Used by the single-shift solve (:mod:`.eigen`) and the band-sliced
solve (:mod:`.band_solve`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from ..errors import UserError

if TYPE_CHECKING:
    from mpi4py import MPI

PREFIX = "railvib_eig_"


class EigenSolveError(UserError):
    """The eigensolver did not deliver the requested modes."""


@dataclass
class Eigenpairs:
    """Eigenpairs with this rank's rows of the mass-normalised mode matrix."""

    eigenvalues: np.ndarray
    phi: np.ndarray                    # (n_local_dofs, n_modes)
    stats: dict = field(default_factory=dict)
    static: np.ndarray | None = None   # (n_local_dofs, k) K^-1 static_rhs, when asked for
    residuals: np.ndarray | None = None        # (m,) relative residuals (normalise_and_check)
    residual_floors: np.ndarray | None = None  # (m,) their round-off floors (where > tol)
    #: (m,) the round-off floors alone, where purified_modes added the solves' floors to
    #: residual_floors (a one-band merge judges by these, as its own checks would)
    roundoff_floors: np.ndarray | None = None
    warnings: list[str] = field(default_factory=list)   # see convergence_verdict
    #: (m, m) Phi^T M Phi and Phi^T K Phi as the last checks measured them (purified_modes)
    gram: np.ndarray | None = None
    stiff: np.ndarray | None = None

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.sqrt(np.maximum(self.eigenvalues, 0.0)) / (2 * np.pi)


#: When the true residuals stay above modal.tol after the purification passes, block
#: Lanczos runs once more (same factor) with its convergence test at tol / this factor: the
#: true relative residual of a purified Ritz pair exceeds the Lanczos estimate by up to
#: about the square root of the condition of the diagonally scaled mass matrix (27 for
#: trilinear hexahedra, sqrt ~ 5; measured 2x on the 80-element column on 2 ranks).
RETRY_TOL_FACTOR = 10.0

#: Purification passes of the pairs whose true residual fails after the first Rayleigh-Ritz
#: step on the Ritz vectors as block Lanczos returns them (:func:`purified_modes`). Most
#: pass already: measured at the issue-26 case (296 modes, 138k DOFs, 2 ranks, tol 1e-8)
#: 265 of 296 (median relative residual 1.5e-10; the ones that fail are the first and the
#: last, nearest to the basis's edge), so purifying only the others saves ~240 of the 364
#: solves the purification of every Ritz vector and its extra pass took.
PURIFICATIONS = 1

#: Extra purification passes (one more application of the shift-invert operator, with one
#: step of iterative refinement of each solve, and a Rayleigh-Ritz step) when a Ritz pair's
#: *true* residual is above the tolerance although the Lanczos estimate converged. Each pass
#: damps the high-frequency error components by lambda_i / lambda_j; the refinement removes
#: the part of the residual left by an inaccurate factorisation (measured: MUMPS on 2 ranks
#: solves the coarse thesis model to a relative residual of 9e-9, on 1 rank to 1e-11).
EXTRA_PURIFICATIONS = 2


#: The first this many purification passes purify the failing pairs only; the guards enter
#: their Rayleigh-Ritz step as block Lanczos returned them (their K and M products, no
#: solves). The passes after them purify the guards too. Measured at the issue-26 case (2
#: bands, 296 modes, 2 ranks, tol 1e-8): the same pairs pass after the first pass either
#: way, and the solves of the 2 x 29 guards (2 per guard: solve and refinement), 2.4 s of the
#: 12.8 s after Lanczos, are saved. On the 60-element column at tol 1e-10 the top pair of a
#: band stalled at 6e-9 without purified guards (its neighbour beyond the band, coupled to
#: it at eigenvalue ratio ~1, needs its guard purified too): the next pass purifies them.
GUARDS_AS_THEY_ARE = 1


def purified_modes(op, X: np.ndarray, block: int, K, M, comm: MPI.Comm, tol: float,
                   stats: dict | None = None, window: tuple[float, float] | None = None,
                   progress=None) -> Eigenpairs:
    """Check Ritz vectors as they are and purify the pairs that fail (at most
    :data:`PURIFICATIONS` + :data:`EXTRA_PURIFICATIONS` passes, with iterative refinement)
    while some true residual is above ``tol`` by more than its round-off floor
    (:func:`unconverged`). Needs the
    factor of ``op``; returns the checked modes (ascending eigenvalues), whose
    ``residual_floors`` also cover the solves' residuals.

    ``X`` holds ``stats["n_wanted"]`` wanted Ritz vectors followed by ``stats["n_guard"]``
    guard vectors (the next Ritz vectors). The first pass checks the wanted ones as block
    Lanczos returns them (:func:`_checked_ritz_vectors`: K and M products formed afresh,
    one each per vector, the Gram matrices, the Rayleigh quotients as eigenvalues and the
    true residuals with them), with no Rayleigh-Ritz step with K and M before it unless
    those measurements ask for one (before, that step always came first: its projection,
    rotation of the vectors and of their K products, and the checks' fresh M products
    again).

    The pairs within ``tol`` need no purification
    (a pair is accepted by its measured residual, whatever it went through); the others
    (those at their round-off floor included: purification still improves them) go to a
    purification pass that **locks** the converged modes (those within ``tol``, or
    outside ``window``): it purifies only the others, takes the guards into its
    Rayleigh-Ritz step (whose components of the next modes, damped by purification only by
    lambda_i / lambda_j ~ 1 near the top of the set, that step removes; the first
    :data:`GUARDS_AS_THEY_ARE` passes take them as they are, the later ones purify them
    too), M-orthogonalises them against the locked
    modes and projects in that complement (:func:`purify_locked`); the ``n_wanted`` pairs
    nearest to the shift are kept, and only the new ones are checked, against every mode
    (:func:`normalise_and_check`'s ``known``). Before, every Ritz vector was purified
    first: measured at the issue-26 case (296 modes, 138k DOFs, 2 ranks) the phase took
    10.0 s of a 51 s eigensolve, 364 solves of it; ``stats["purified_modes"]``: how many
    modes the first purification pass redid, ``stats["extra_purifications"]`` and
    ``stats["repurified_modes"]``: the passes after it and the modes they redid.
    ``window``: only the eigenvalues in ``[lo, hi]`` must converge (a band; the pairs
    beyond its edges belong to the neighbouring bands). ``progress``:
    :data:`~railvib_hpc.model.factor.Progress` of the phases (purification,
    Rayleigh-Ritz, residual checks, round-off floors).

    Statistics (added to ``stats``, seconds summed over the passes):
    ``time_purify_solves``, ``time_purify_products`` (K and M products, solve residuals),
    ``time_rayleigh_ritz`` (projection, dense eigenproblem, rotation) and ``time_checks``
    (:func:`normalise_and_check`, the first pass's included).

    Memory: every pass works in ``X`` itself (it is overwritten; afterwards its first
    columns are the modes, the rest the rotated guards); the K and M products go by blocks.
    """
    from .block_lanczos import permute_columns

    stats = {} if stats is None else stats
    n_wanted = int(stats.get("n_wanted", X.shape[1]))
    timings: dict[str, float] = {}
    t_checks = 0.0

    def nearest_first(lam: np.ndarray) -> np.ndarray:
        """The n_wanted nearest to the shift, ascending, then the others (the next pass's
        guards)."""
        near = np.sort(np.argsort(np.abs(lam - op.sigma), kind="stable")[:n_wanted])
        order = near[np.argsort(lam[near], kind="stable")]
        return np.concatenate([order, np.setdiff1d(np.arange(len(lam)), order)])

    # the first pass: the wanted Ritz vectors as block Lanczos returns them, checked as
    # they are; a Rayleigh-Ritz step with K and M only where the checks say it is needed.
    # Only the pairs whose true residual fails are purified (locked passes).
    t0 = time.perf_counter()
    result, checks = _checked_ritz_vectors(X, n_wanted, K, M, comm, tol, window, progress,
                                           stats, timings)
    t_checks += time.perf_counter() - t0 - timings.get("rayleigh_ritz", 0.0)
    bounds = np.zeros(n_wanted)                            # (no solve yet)
    stats["extra_purifications"] = stats["purified_modes"] = 0
    for attempt in range(PURIFICATIONS + EXTRA_PURIFICATIONS):
        # the first purification takes every pair above tol, even one at its round-off
        # floor (as when every pair was purified); the extra passes only those above both
        above = result.residuals > tol if attempt < PURIFICATIONS else unconverged(result, tol)
        redo = above & in_window(result, window)
        if not redo.any():
            break
        if attempt < PURIFICATIONS:
            stats["purified_modes"] += int(redo.sum())
        else:
            stats["extra_purifications"] = attempt + 1 - PURIFICATIONS
            stats["repurified_modes"] = stats.get("repurified_modes", 0) + int(redo.sum())
        # X = [locked modes | modes to redo | guards]
        kept = np.flatnonzero(~redo)
        c = kept.size
        permute_columns(X, np.concatenate([kept, np.flatnonzero(redo),
                                           np.arange(n_wanted, X.shape[1])]))
        locked = (checks.stiff[np.ix_(kept, kept)], checks.gram[np.ix_(kept, kept)])
        # the first pass purifies the failing pairs only (the guards enter as they are),
        # the extra passes the guards too (GUARDS_AS_THEY_ARE)
        lam_new, bounds_new = purify_locked(
            op, X, c, block, locked, progress, timings,
            n_purify=int(redo.sum()) if attempt < GUARDS_AS_THEY_ARE else None)
        lam_all = np.concatenate([result.eigenvalues[kept], lam_new])
        # the locked modes the n_wanted nearest to the shift still include come first (as
        # they are), then the new ones among them, then the rest (the next guards)
        order = nearest_first(lam_all)
        chosen = order[:n_wanted]
        first = np.concatenate([np.sort(chosen[chosen < c]), chosen[chosen >= c]])
        permute_columns(X, np.concatenate([first, order[n_wanted:]]))
        n_known = int((chosen < c).sum())
        known_idx = kept[first[:n_known]]
        known = _known_checks(result, checks, known_idx)
        result = Eigenpairs(lam_all[first], X[:, :n_wanted], {})
        t0 = time.perf_counter()
        checks = normalise_and_check(result, K, M, comm, tol=tol, progress=progress,
                                     known=known)
        t_checks += time.perf_counter() - t0
        bounds = np.concatenate([bounds[known_idx], bounds_new[first[n_known:] - c]
                                 * checks.scale[n_known:]])
        # ascending eigenvalues again
        asc = np.argsort(result.eigenvalues, kind="stable")
        if np.any(asc != np.arange(n_wanted)):
            permute_columns(X, np.concatenate([asc, np.arange(n_wanted, X.shape[1])]))
            result, checks = _permuted(result, checks, asc, X[:, :n_wanted])
            bounds = bounds[asc]
    result.gram, result.stiff = checks.gram, checks.stiff
    # the solves' own residuals are a floor too (relative to ||K phi||; scale-free)
    solve_floor = bounds / checks.knorm
    result.roundoff_floors = result.residual_floors
    result.residual_floors = np.maximum(result.residual_floors, solve_floor)
    stats["max_solve_residual"] = float(solve_floor.max(initial=0.0))
    stats.update(time_purify_solves=timings.get("solves", 0.0),
                 time_purify_products=timings.get("products", 0.0),
                 time_rayleigh_ritz=timings.get("rayleigh_ritz", 0.0), time_checks=t_checks)
    # the modes without the guards behind them (a view would keep them alive)
    result.phi = np.ascontiguousarray(result.phi)
    return result


#: The first pass of :func:`purified_modes` keeps block Lanczos's Ritz vectors as they are
#: (no Rayleigh-Ritz step with K and M) when the checks measure ``max |Phi^T M Phi - I|``
#: among the pairs that are not purified next at most this (what the step itself leaves
#: is rounding, ~1e-15; the tests ask for 1e-12; measured at the issue-26 case: 3.6e-15) ...
RAW_RITZ_GRAM = 1e-13

#: ... their K-coupling ``max |Phi^T K Phi - Lambda| / lambda_max`` at most this fraction
#: of ``modal.tol`` (a coupling ``phi_j^T K phi_i = lambda_i phi_j^T M phi_i + phi_j^T
#: r_i`` of the order of the residuals that ``tol`` accepts is no error beyond what ``tol``
#: allows; measured at the issue-26 case: up to 1.2e-10 in the bands, 7.7e-11 in the old
#: code's single-shift result, whose Rayleigh-Ritz step did not remove it) ...
RAW_RITZ_STIFF = 0.1

#: ... and, when some pairs are to be purified, the M-overlap ``|(Phi^T M Phi)_ij|`` of a
#: pair i that is not with one j that is, times ``max(1, lambda_i / lambda_j)``, at most
#: this fraction of ``modal.tol``: the locked pass makes the purified vectors M-orthogonal
#: to the locked modes, and a locked mode's overlap ``e`` with another one's direction
#: becomes a residual of up to about ``e lambda_locked / lambda`` in that one (measured on
#: the 60-element column at tol 1e-10, overlaps 4e-10 and eigenvalue ratios up to 2.6e5:
#: the purified pairs stalled at 1e-8; at the issue-26 case, 2 bands: 1e-11 x 15 and
#: 1.5e-10 x 1.7, the overlaps being mostly the failing vectors' own errors).
RAW_RITZ_SPREAD = 0.1


def _checked_ritz_vectors(X: np.ndarray, n_wanted: int, K, M, comm: MPI.Comm, tol: float,
                          window: tuple[float, float] | None, progress, stats: dict,
                          timings: dict) -> tuple[Eigenpairs, Checks]:
    """The first pass of :func:`purified_modes`: the ``n_wanted`` Ritz vectors in ``X``
    checked as block Lanczos returns them (:func:`normalise_and_check` with ``rayleigh``:
    K and M products afresh, one each per vector, the Gram matrices, the Rayleigh quotients
    as eigenvalues and the true residuals with them), in ascending order (``X``'s columns
    permuted).

    The Ritz vectors of one Lanczos run are M-orthonormal by construction (``X = V Y``,
    ``V`` M-orthonormal, ``Y`` orthogonal) and K-orthogonal to second order in their
    residuals (with ``A x_i = theta_i x_i + s_i``, ``s_i`` M-orthogonal to the basis:
    ``x_j^T K x_i - lambda_i x_j^T M x_i = s_j^T (K - sigma M) s_i / (theta_i theta_j)``),
    so a Rayleigh-Ritz step with K and M would rotate them by ``I + O(residual^2)``, and the
    Rayleigh quotients are its eigenvalues to that order; it is skipped when the measured
    Gram matrices say so (:data:`RAW_RITZ_GRAM`, :data:`RAW_RITZ_STIFF`,
    :data:`RAW_RITZ_SPREAD`). Otherwise (a
    basis that lost M-orthogonality to rounding amplified by an ill-conditioned K) the step
    is made from those same measured matrices (the projections ``X^T K X``, ``X^T M X``;
    no product formed twice): the vectors are rotated in place and checked afresh (K and
    M products again), as before. Either way every returned pair's checks are measured of
    the returned vector itself. ``stats["first_rayleigh_ritz"]``: "skipped" or the reason
    it was made; ``stats["raw_ritz_gram_error"]``, ``stats["raw_ritz_stiffness_error"]``:
    the measured M and K errors among the pairs that stay.
    """
    from scipy.linalg import eigh

    from .block_lanczos import permute_columns, rotate_in_place

    # Round-off floors only where one is read: none with purification. The pairs above tol
    # in the window are purified next (their new checks bring their floors); those outside
    # it (a band's margin) are neither returned (the band keeps its window only,
    # band_solve._trim, with the same window) nor judged (the passes, their verdicts and
    # the band's retry take the window only); before, the first pass formed |K|, |M| and
    # the floors of the margin's pairs above tol (a band's 7-21 pairs outside its window).
    def floors_of(r: Eigenpairs) -> np.ndarray:
        return in_window(r, window) & (PURIFICATIONS == 0)

    result = Eigenpairs(np.zeros(n_wanted), X[:, :n_wanted], {})
    checks = normalise_and_check(result, K, M, comm, tol=tol, progress=progress,
                                 rayleigh=True, floors_of=floors_of)
    lam = result.eigenvalues
    # the pairs that stay as they are (the others are purified and replaced): their Gram
    # errors among themselves, and their M-overlaps with every pair (the locked pass)
    keep = ~((result.residuals > tol) & in_window(result, window))
    overlap = np.abs(checks.gram - np.eye(n_wanted))[keep]
    err_m = overlap[:, keep].max(initial=0.0)
    err_k = np.abs(checks.stiff - np.diag(lam))[np.ix_(keep, keep)].max(initial=0.0) / \
        np.abs(lam).max(initial=1.0)
    # a kept pair i's overlap with a purified one j, times lambda_i / lambda_j (>= 1)
    ratio = np.abs(lam)[keep][:, None] / np.maximum(np.abs(lam)[~keep][None, :], 1e-300)
    damage = (overlap[:, ~keep] * np.maximum(ratio, 1.0)).max(initial=0.0)
    stats.update(raw_ritz_gram_error=float(err_m), raw_ritz_stiffness_error=float(err_k))
    if err_m > RAW_RITZ_GRAM:
        why = f"M-Gram error {err_m:.1e} > {RAW_RITZ_GRAM:g}"
    elif err_k > RAW_RITZ_STIFF * tol:
        why = f"K-coupling {err_k:.1e} > {RAW_RITZ_STIFF:g} tol"
    elif damage > RAW_RITZ_SPREAD * tol:
        why = f"M-overlap x eigenvalue ratio {damage:.1e} > {RAW_RITZ_SPREAD:g} tol"
    else:
        stats["first_rayleigh_ritz"] = "skipped"
        asc = np.argsort(lam, kind="stable")
        if np.any(asc != np.arange(n_wanted)):
            permute_columns(X, np.concatenate([asc, np.arange(n_wanted, X.shape[1])]))
            result, checks = _permuted(result, checks, asc, X[:, :n_wanted])
        return result, checks
    stats["first_rayleigh_ritz"] = why
    t0 = time.perf_counter()
    lam, Z = eigh(checks.stiff, checks.gram)                 # ascending
    rotate_in_place(X[:, :n_wanted], Z, progress, "Rayleigh-Ritz")
    timings["rayleigh_ritz"] = timings.get("rayleigh_ritz", 0.0) + time.perf_counter() - t0
    result = Eigenpairs(lam, X[:, :n_wanted], {})
    checks = normalise_and_check(result, K, M, comm, tol=tol, progress=progress,
                                 floors_of=floors_of)
    return result, checks


def purify_locked(op, X: np.ndarray, n_locked: int, block: int,
                  locked: tuple[np.ndarray, np.ndarray], progress=None,
                  timings: dict | None = None, n_purify: int | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """An extra purification pass with the first ``n_locked`` columns of ``X`` locked.

    The other columns ``W`` are purified once more (one solve and one step of iterative
    refinement each, its residual by one product with ``K - sigma M``): the first
    ``n_purify`` of them (default: all); the ones after those (the guards) enter as they
    are, by their K and M products alone (see :func:`purified_modes`). Then ``W`` is
    M-orthogonalised
    against the locked modes ``Phi_c`` (``W' = W - Phi_c C``, ``C = G_c^-1 Phi_c^T M W``)
    and projected in that complement: ``W'^T M W' = W^T M W - (Phi_c^T M W)^T C`` and
    ``W'^T K W' = W^T K W - C^T Phi_c^T K W - (Phi_c^T K W)^T C + C^T S_c C``, with
    ``S_c, G_c = locked`` (``Phi_c^T K Phi_c``, ``Phi_c^T M Phi_c`` as the last checks
    measured), so no product with the locked modes
    is formed but the block ones ``Phi_c^T K W`` and ``Phi_c^T M W``. ``X[:, n_locked:]``
    becomes ``W' Z`` (the Ritz vectors, ascending eigenvalues); the locked columns are not
    touched.

    Returns the new eigenvalues and, per new vector, an upper bound of its solve residual
    ``||S z||`` (the triangle inequality over the columns' refined solve residuals ``S``;
    the projection's share, ``(K - sigma M) Phi_c C z``, is of the order of the locked
    modes' coupling ``||C||``, itself of the order of their residuals, and not included).
    ``progress``: :data:`~railvib_hpc.model.factor.Progress` (phases "purification"
    and "Rayleigh-Ritz"); ``timings``: seconds added under ``"solves"``, ``"products"`` (the
    K and M products and solve residuals) and ``"rayleigh_ritz"`` (projection, dense
    eigenproblem, rotation).
    """
    from mpi4py import MPI
    from scipy.linalg import eigh

    from .block_lanczos import ROTATE_ROWS, no_progress, symmetric_from_upper

    progress = progress or no_progress
    timings = {} if timings is None else timings
    clock = dict.fromkeys(("solves", "products", "rayleigh_ritz"), 0.0)
    c, k = n_locked, X.shape[1]
    q = k - c
    end = k if n_purify is None else c + n_purify
    kp, mp, sres = np.zeros((q, q)), np.zeros((q, q)), np.zeros(q)
    ck, cm = np.zeros((c, q)), np.zeros((c, q))
    # the purified columns by blocks, then the guards by blocks (a block never mixes them)
    starts = [*range(c, end, block), *range(end, k, block)]
    for j in starts:
        s = slice(j, min(j + block, end if j < end else k))
        w = slice(s.start - c, s.stop - c)
        t0, s0 = time.perf_counter(), op.time_solves
        if j < end:
            B = op.mass(X[:, s])
            Y = op.solve(B, chunk=max(B.shape[1], 1))
            # the refinement's residual by one product with the factored K - sigma M (was
            # K Y and M Y: one sparse product per vector less)
            Y += op.solve(B - op.shifted(Y), chunk=max(B.shape[1], 1))
            KY, MY = op.stiffness_and_mass(Y)
            sres[w] = np.sum((B - (KY - op.sigma * MY)) ** 2, axis=0)
            X[:, s] = Y
        else:                          # a guard as it is: no solve, no solve residual
            KY, MY = op.stiffness_and_mass(X[:, s])
        t1 = time.perf_counter()
        clock["solves"] += op.time_solves - s0
        clock["products"] += t1 - t0 - (op.time_solves - s0)
        kp[:w.stop, w] = X[:, c:s.stop].T @ KY
        mp[:w.stop, w] = X[:, c:s.stop].T @ MY
        ck[:, w], cm[:, w] = X[:, :c].T @ KY, X[:, :c].T @ MY
        clock["rayleigh_ritz"] += time.perf_counter() - t1
        progress("purification", w.stop, q)
    t0 = time.perf_counter()
    for a in (sres, kp, mp, ck, cm):
        op.comm.Allreduce(MPI.IN_PLACE, a, op=MPI.SUM)
    stiff_c, gram_c = locked
    C = np.linalg.solve(gram_c, cm) if c else cm
    mw = symmetric_from_upper(mp) - cm.T @ C
    kw = symmetric_from_upper(kp) - C.T @ ck - ck.T @ C + C.T @ stiff_c @ C
    lam, Z = eigh(0.5 * (kw + kw.T), 0.5 * (mw + mw.T))
    CZ = C @ Z
    n = X.shape[0]
    for r in range(0, n, ROTATE_ROWS):
        rows = slice(r, r + ROTATE_ROWS)
        X[rows, c:] = X[rows, c:] @ Z - X[rows, :c] @ CZ
        progress("Rayleigh-Ritz", min(r + ROTATE_ROWS, n), n)
    clock["rayleigh_ritz"] += time.perf_counter() - t0
    for key, value in clock.items():
        timings[key] = timings.get(key, 0.0) + value
    return lam, np.abs(Z).T @ np.sqrt(sres)


def _known_checks(result: Eigenpairs, checks: Checks, idx: np.ndarray) -> Known:
    """What :func:`normalise_and_check` measured of the modes ``idx`` (for its ``known``)."""
    return Known(checks.gram[np.ix_(idx, idx)], checks.stiff[np.ix_(idx, idx)],
                 checks.knorm[idx], result.residuals[idx], result.residual_floors[idx])


def _permuted(result: Eigenpairs, checks: Checks, order: np.ndarray, phi: np.ndarray
              ) -> tuple[Eigenpairs, Checks]:
    """The result and its checks with the modes in ``order`` (``phi``: the reordered
    modes)."""
    out = Eigenpairs(result.eigenvalues[order], phi, result.stats)
    out.residuals, out.residual_floors = result.residuals[order], result.residual_floors[order]
    ix = np.ix_(order, order)
    return out, Checks(checks.scale[order], checks.knorm[order], checks.gram[ix],
                       checks.stiff[ix])


def in_window(result: Eigenpairs, window: tuple[float, float] | None) -> np.ndarray:
    """Modes whose eigenvalue lies in ``window`` (all without one)."""
    lam = result.eigenvalues
    if window is None:
        return np.ones(len(lam), dtype=bool)
    return (lam >= window[0]) & (lam <= window[1])


def within_roundoff(result: Eigenpairs, tol: float) -> np.ndarray:
    """Modes whose measured relative residual is at most ``tol`` plus its round-off floor.

    The floor bounds the error of evaluating the residual in double precision (see
    :func:`normalise_and_check`): the measured ``rho`` is the true residual of the stored
    vector plus an error of at most ``floor``, so ``rho <= tol + floor`` is what every pair
    whose true residual is within ``tol`` shows, on any CPU kernel, and only a measured
    ``rho`` above it proves the pair above ``tol``. (With ``max(tol, floor)`` instead, a
    pair whose floor is near ``tol`` fell on either side by the rounding of its evaluation:
    measured on the 60-element column at ``tol = 1e-10``, residual 1.94e-10 against a floor
    1.72e-10 with OpenBLAS's SkylakeX kernel, 1.45e-10 against 1.73e-10 with Haswell's.)"""
    return result.residuals <= tol + result.residual_floors


def unconverged(result: Eigenpairs, tol: float) -> np.ndarray:
    """Modes whose relative residual exceeds ``tol`` by more than its round-off floor
    (:func:`within_roundoff`)."""
    return ~within_roundoff(result, tol)


def hopeless(result: Eigenpairs, tol: float) -> np.ndarray:
    """Modes :func:`convergence_verdict` rejects: above ``RETRY_TOL_FACTOR * tol`` and above
    ``tol`` plus their round-off floor, or above ``sqrt(tol)`` and ``tol``."""
    res = result.residuals
    return (unconverged(result, tol) & (res > RETRY_TOL_FACTOR * tol)) | \
        ((res > np.sqrt(tol)) & (res > tol))


def convergence_verdict(result: Eigenpairs, tol: float) -> list[str]:
    """Judge the final residuals: raise, warn, or accept (the documented rule).

    With ``rho`` the relative residual ``||K phi - lambda M phi|| / ||K phi||`` of a mode
    and ``floor`` its round-off floor (:func:`normalise_and_check`):

    * ``rho <= tol``: converged.
    * ``tol < rho <= tol + floor`` and ``rho <= sqrt(tol)``: limited by round-off (the
      measured residual exceeds ``tol`` by no more than the error of evaluating it,
      :func:`within_roundoff`; with ``floor >= tol`` the model is ill-conditioned: tiny or
      extremely flat elements, huge stiffness contrasts). Accepted with a warning: the
      eigenvalue error is ``~ rho^2 / relgap`` (Kato-Temple), no worse than what ``tol``
      buys for eigenvalues, but the shapes are only accurate to ``~ rho / relgap``.
    * ``tol + floor < rho <= RETRY_TOL_FACTOR * tol`` (after the extra purifications and a
      Lanczos run at ``tol / RETRY_TOL_FACTOR``): accepted with a warning. The solver's own
      test (on the shift-inverted operator) is met; the true residual exceeds it by the
      scaling of the mass matrix (see :data:`RETRY_TOL_FACTOR`).

    A pair whose true residual is within ``tol`` is converged or limited by round-off on
    every CPU kernel (the measured ``rho`` moves by at most ``floor``): the kernel can
    move a pair between these two accepted classes, never into the third or into an
    error.
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
    limited = (res > tol) & within_roundoff(result, tol)
    near = (res > tol) & ~limited
    if limited.any():
        worst = int(np.argmax(np.where(limited, res, -1.0)))
        model = ("of this ill-conditioned model" if floor[worst] >= tol else
                 "(the error of evaluating the residual in double precision)")
        out.append(f"{int(limited.sum())} of {len(res)} modes are limited by round-off: "
                   f"relative residual up to {res[worst]:.2e} (mode {worst + 1}, "
                   f"{f[worst]:.3f} Hz) > modal.tol = {tol:.1e}, within the round-off floor "
                   f"{floor[worst]:.1e} {model}; their frequencies are accurate to "
                   "~residual^2, their shapes only to ~residual / relative gap (check the "
                   "mesh: aspect ratios, tiny elements)")
    if near.any():
        worst = int(np.argmax(np.where(near, res, -1.0)))
        out.append(f"{int(near.sum())} of {len(res)} modes end with a relative residual "
                   f"above modal.tol = {tol:.1e}, up to {res[worst]:.2e} (mode {worst + 1}, "
                   f"{f[worst]:.3f} Hz; <= {RETRY_TOL_FACTOR:g} x tol: the solver's own test "
                   "is met, the mass matrix's scaling makes the true residual larger); "
                   "frequencies accurate to ~residual^2")
    return out


class Checks(NamedTuple):
    """What :func:`normalise_and_check` measured besides the residuals (see there)."""

    scale: np.ndarray
    knorm: np.ndarray
    gram: np.ndarray
    stiff: np.ndarray


class Known(NamedTuple):
    """Checks already made of the leading modes (:func:`normalise_and_check`'s ``known``):
    ``Phi^T M Phi`` and ``Phi^T K Phi`` among them, ``||K phi_i||``, the relative residuals
    and their round-off floors."""

    gram: np.ndarray
    stiff: np.ndarray
    knorm: np.ndarray
    residuals: np.ndarray
    floors: np.ndarray


#: Columns per chunk when normalise_and_check forms M Phi (and K Phi).
NORMALISE_CHUNK = 64


def normalise_and_check(result: Eigenpairs, K, M, comm: MPI.Comm, tol: float = 0.0,
                        progress=None, known: Known | None = None,
                        rayleigh: bool = False, floors_of=None) -> Checks:
    """Scale modes to unit modal mass and record max |Phi^T M Phi - I| and residuals.

    One pass over :data:`NORMALISE_CHUNK` columns at a time forms ``M Phi`` and ``K Phi``
    afresh from the modes as they are, one sparse product each per chunk, and from them the
    upper triangles of ``Phi^T M Phi`` and ``Phi^T K Phi`` (chunk ``j`` against the chunks
    up to ``j``: half the products of the full matrices) and the residual norms; the modal
    masses are the diagonal of the first, so the scaling to unit modal mass is applied to
    all of them afterwards (exact up to rounding: ``(D Phi)^T M (D Phi) = D Phi^T M Phi D``).
    ``known``: the checks of the first ``len(known.knorm)`` modes, made before and still
    valid (locked modes, :func:`purified_modes`): those modes are neither scaled nor
    formed again; the others are formed and checked against all of them. ``rayleigh``:
    the eigenvalues of the modes checked here become their Rayleigh quotients
    ``phi^T K phi / phi^T M phi`` (the diagonals of the chunk's own Gram blocks, summed over
    the ranks chunk by chunk before its residuals; ``result.eigenvalues`` is replaced),
    for Ritz vectors that no Rayleigh-Ritz step with K and M went over. ``floors_of``:
    ``floors_of(result)`` (residuals and eigenvalues measured) is a mask of the modes whose
    round-off floors are wanted (default: all); the others get 0, for modes the caller
    replaces or drops anyway (:func:`purified_modes`: the first pass's pairs above ``tol``
    that it purifies next, and a band's pairs outside its window; their floors were never
    read).

    Records the relative residuals ``rho_i = ||K phi_i - lambda_i M phi_i|| / ||K phi_i||``
    (``result.residuals``) and, for the modes with ``rho_i > tol``, their round-off floor
    ``gamma_k || |K| |phi_i| + |lambda_i| |M| |phi_i| || / ||K phi_i||`` (k = longest row
    + 1, :func:`railvib_hpc.tolerances.gamma`; ``result.residual_floors``, 0 elsewhere):
    the error of evaluating the residual in double precision, below which no solver can
    verify an eigenpair. (Computing it needs |K| and |M|, so it is only done when needed.)
    Memory: ``result.phi`` is scaled in place and every other n x m temporary is formed
    :data:`NORMALISE_CHUNK` columns at a time (the floors' bound: n x the modes above
    ``tol``). ``progress``: :data:`~railvib_hpc.model.factor.Progress` (phases
    "residual checks" and "round-off floors").

    Returns
    -------
    Checks
        ``scale`` (m,): the factors the modes were scaled by; ``knorm`` (m,): ``||K
        phi_i||`` of the scaled modes; ``gram``, ``stiff`` (m, m): ``Phi^T M Phi`` and
        ``Phi^T K Phi`` of the scaled modes (symmetric, from their upper triangles).
    """
    from mpi4py import MPI

    from ..model.factor import sparse_times_block_pair
    from .block_lanczos import no_progress

    progress = progress or no_progress
    t0 = time.perf_counter()
    phi = result.phi
    lam = result.eigenvalues
    m = len(lam)
    c = 0 if known is None else len(known.knorm)
    gram = np.zeros((m, m))
    stiff = np.zeros((m, m))
    res = np.zeros(m)
    knorm = np.zeros(m)
    if rayleigh:
        lam = result.eigenvalues = np.array(lam, dtype=float)
    for j in range(c, m, NORMALISE_CHUNK):
        cols = slice(j, min(j + NORMALISE_CHUNK, m))
        KP, MP = sparse_times_block_pair(K, M, phi[:, cols], comm)
        gram[:cols.stop, cols] = phi[:, :cols.stop].T @ MP
        stiff[:cols.stop, cols] = phi[:, :cols.stop].T @ KP
        if rayleigh:                      # the Rayleigh quotients of the chunk (all ranks)
            quot = np.array([np.diag(stiff[cols, cols]), np.diag(gram[cols, cols])])
            comm.Allreduce(MPI.IN_PLACE, quot, op=MPI.SUM)
            lam[cols] = quot[0] / quot[1]
        res[cols] = np.sum((KP - MP * lam[cols]) ** 2, axis=0)
        knorm[cols] = np.sum(KP**2, axis=0)
        progress("residual checks", cols.stop - c, m - c)
    for a in (gram, stiff, res, knorm):
        comm.Allreduce(MPI.IN_PLACE, a, op=MPI.SUM)
    scale = np.ones(m)
    scale[c:] = 1.0 / np.sqrt(np.diag(gram)[c:])
    phi[:, c:] *= scale[c:]
    outer = np.triu(np.outer(scale, scale))
    gram, stiff = gram * outer, stiff * outer            # (upper triangles)
    knorm = np.sqrt(knorm) * scale
    residuals = np.zeros(m)
    residuals[c:] = np.sqrt(res[c:]) * scale[c:] / knorm[c:]
    if known is not None:
        gram[:c, :c], stiff[:c, :c] = np.triu(known.gram), np.triu(known.stiff)
        knorm[:c], residuals[:c] = known.knorm, known.residuals
    result.residuals = residuals
    wanted = None if floors_of is None else np.asarray(floors_of(result), dtype=bool)
    result.residual_floors = _residual_floors(result, K, M, comm, tol, knorm, progress, c,
                                              wanted)
    if known is not None:
        result.residual_floors[:c] = known.floors
    upper = np.triu(np.ones((m, m), dtype=bool))
    result.stats.update({
        "max_orthonormality_error": float(np.abs(gram - np.eye(m))[upper].max(initial=0.0)),
        "max_stiffness_diag_error": float(np.abs(stiff - np.diag(lam))[upper].max(initial=0.0)
                                          / lam.max()) if m else 0.0,
        "max_relative_residual": float(result.residuals.max(initial=0.0)),
        "max_residual_floor": float(result.residual_floors.max(initial=0.0)),
        "time_checks": time.perf_counter() - t0,
    })
    return Checks(scale, knorm, gram + np.triu(gram, 1).T, stiff + np.triu(stiff, 1).T)


def _residual_floors(result: Eigenpairs, K, M, comm: MPI.Comm, tol: float,
                     knorm: np.ndarray, progress, first: int = 0,
                     wanted: np.ndarray | None = None) -> np.ndarray:
    """The round-off floors of :func:`normalise_and_check` for the modes from ``first`` on
    that are above ``tol`` (and in the mask ``wanted``, if given; 0 elsewhere); ``knorm``:
    ``||K phi_i||``."""
    from mpi4py import MPI

    from .. import tolerances
    from ..model.factor import abs_matrix, longest_row, sparse_times_block

    phi, lam = result.phi, result.eigenvalues
    floor = np.zeros(len(lam))
    above = result.residuals > tol
    if wanted is not None:
        above &= wanted
    need = first + np.flatnonzero(above[first:])
    if not need.size:
        return floor
    chunk = NORMALISE_CHUNK
    k = max(longest_row(K, comm), longest_row(M, comm)) + 1
    bound = np.zeros((phi.shape[0], need.size))
    for step, (A, w) in enumerate(((K, np.ones(need.size)), (M, np.abs(lam[need])))):
        Aabs = abs_matrix(A, comm)
        for j in range(0, need.size, chunk):
            c = slice(j, j + chunk)
            bound[:, c] += sparse_times_block(Aabs, np.abs(phi[:, need[c]]), comm) * w[c]
            progress("round-off floors", step * need.size + min(j + chunk, need.size),
                     2 * need.size)
        Aabs.destroy()
    floor[need] = tolerances.gamma(k) * np.sqrt(
        comm.allreduce(np.einsum("ij,ij->j", bound, bound), op=MPI.SUM)) / knorm[need]
    return floor
