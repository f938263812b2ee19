"""The merge of a band-sliced eigensolve's bands: a Rayleigh-Ritz step with K and M in the
union of the bands' modes (:func:`_merge`), or less where the measured Gram matrices
allow: the modes as they are (:func:`_merge_as_they_are`), the step on the coupled pairs
only (:func:`_merge_coupled`) or, for one band, its own checks
(:func:`_merge_one_band`); the eigenvalues below ``f_max`` counted against the inertia.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..io.formats.bands import read_band
from .band_cache import DUPLICATE_GRAM, BandCache, BandSettings
from .bands import Band, check_counts, hz, omega2
from .ritz import Eigenpairs, EigenSolveError, convergence_verdict


def merge_memory_gb(n_dofs: int, n_candidates: int, n_modes: int) -> float:
    """Dense memory of the merge [GB, all ranks]: the candidates (the merged modes are formed
    in their memory, :func:`~railvib_hpc.modal.block_lanczos.rotate_narrowing`), and the
    chunks of K Phi and M Phi in :func:`~railvib_hpc.modal.eigen.normalise_and_check` and
    of the Gram products (8 bytes each); the matrices and the mesh are already there.
    ``n_modes`` (<= ``n_candidates``) takes no memory of its own."""
    from .ritz import NORMALISE_CHUNK

    return 8.0 * n_dofs * (max(n_candidates, n_modes) + 4 * NORMALISE_CHUNK) / 1e9


def _gram(A, Phi: np.ndarray, comm, chunk: int = 0, progress=None,
          phase: str = "merge: Gram products") -> np.ndarray:
    """``Phi^T A Phi`` (all ranks), A applied ``chunk`` columns at a time (0: the
    :data:`~railvib_hpc.modal.ritz.NORMALISE_CHUNK` that :func:`merge_memory_gb` counts;
    the product's three blocks of 256 columns were 3 GB a rank beyond it at 1M DOFs).
    Chunk ``j`` against the chunks up to ``j`` only (the upper triangle: half the
    products), with ``progress``."""
    from mpi4py import MPI

    from ..model.factor import sparse_times_block
    from .block_lanczos import no_progress, symmetric_from_upper
    from .ritz import NORMALISE_CHUNK

    chunk = chunk or NORMALISE_CHUNK
    progress = progress or no_progress
    m = Phi.shape[1]
    G = np.zeros((m, m))
    for j in range(0, m, chunk):
        c = slice(j, min(j + chunk, m))
        G[:c.stop, c] = Phi[:, :c.stop].T @ sparse_times_block(A, Phi[:, c], comm)
        progress(phase, c.stop, m)
    comm.Allreduce(MPI.IN_PLACE, G, op=MPI.SUM)
    return symmetric_from_upper(G)


def _band_grams(K, M, Phi: np.ndarray, comm, stiff: list[np.ndarray],
                gram: list[np.ndarray], progress=None) -> tuple[np.ndarray, np.ndarray]:
    """``Phi^T K Phi`` and ``Phi^T M Phi`` (all ranks) for ``Phi`` = the bands' modes side
    by side, whose diagonal blocks (each band's ``Phi_b^T K Phi_b``, ``Phi_b^T M Phi_b``)
    the bands' own checks measured of these very vectors (``stiff``, ``gram``): only the
    blocks between bands are formed, band ``j``'s products against the bands before it,
    :data:`~railvib_hpc.modal.ritz.NORMALISE_CHUNK` columns at a time (the sparse products
    of every band but the first, and the dense products between bands only: measured at
    the issue-26 case, 2 bands of 161 and 135 modes, half of :func:`_gram`'s work); the K
    and M products of a chunk in one pass (the chunk copied to PETSc once)."""
    from mpi4py import MPI

    from ..model.factor import sparse_times_block_pair
    from .block_lanczos import no_progress, symmetric_from_upper
    from .ritz import NORMALISE_CHUNK

    progress = progress or no_progress
    m = Phi.shape[1]
    GK, GM = np.zeros((m, m)), np.zeros((m, m))
    edges = np.concatenate([[0], np.cumsum([len(d) for d in gram])])
    for b0, b1 in zip(edges[1:-1], edges[2:]):
        for j in range(b0, b1, NORMALISE_CHUNK):
            c = slice(j, min(j + NORMALISE_CHUNK, b1))
            KP, MP = sparse_times_block_pair(K, M, Phi[:, c], comm)
            GK[:b0, c], GM[:b0, c] = Phi[:, :b0].T @ KP, Phi[:, :b0].T @ MP
            progress("merge: K- and M-Gram products", c.stop - edges[1], m - edges[1])
    out = []
    for G, diagonal in ((GK, stiff), (GM, gram)):
        comm.Allreduce(MPI.IN_PLACE, G, op=MPI.SUM)
        for d, b0, b1 in zip(diagonal, edges[:-1], edges[1:]):
            G[b0:b1, b0:b1] = np.triu(d)
        out.append(symmetric_from_upper(G))
    return out[0], out[1]


def _merge(K, M, comm, bands: list[Band], cache: BandCache, s: BandSettings,
           n_total: int, progress=None, proven: dict | None = None) -> Eigenpairs:
    """Union of the bands' modes -> dedup + Rayleigh-Ritz -> the modes below f_max,
    counted against the inertia of every stretch. A one-band plan skips the Rayleigh-Ritz
    step (:func:`_merge_one_band`; ``proven``: :class:`BandChecks` by band index, of the
    bands solved in this run); a multi-band plan of bands solved in this run keeps their
    modes as they are (:func:`_merge_as_they_are`) or rotates only the coupled pairs
    (:func:`_merge_coupled`) where the measured Gram matrices allow."""
    from scipy.linalg import eigh

    from ..model.factor import available_memory_gb
    from .block_lanczos import narrow_columns, rotate_narrowing
    from .ritz import normalise_and_check

    t0 = time.perf_counter()
    r0, r1 = K.getOwnershipRange()
    n_global = K.getSize()[0]
    lam_max = float(omega2(s.f_max))
    m_c = sum(cache.find(b).n_modes for b in bands)
    need = merge_memory_gb(n_global, m_c, n_total)
    avail = available_memory_gb(comm)
    if need > 0.9 * avail:
        raise EigenSolveError(
            f"merging {len(bands)} bands ({m_c} candidate modes of {n_global:,} DOFs) needs "
            f"~{need:.1f} GB, {avail:.1f} GB are available on {comm.size} rank(s); use more "
            "nodes or a lower modal.f_max")
    import h5py

    per_band = [cache.find(b) for b in bands]
    keeps, lams = [], []
    for rec in per_band:
        with h5py.File(s.cache_dir / rec.file, "r") as f:
            # the band's own modes and its margin, but nothing far above f_max
            lam_b = f["eigenvalue"][()]
            keeps.append(np.flatnonzero(lam_b <= lam_max * (1.0 + 0.05)))
            lams.append(lam_b[keeps[-1]])
    Phi = np.empty((r1 - r0, sum(len(k) for k in keeps)))
    col = 0
    for rec, keep in zip(per_band, keeps):
        _, rows = read_band(s.cache_dir / rec.file, r0, r1)
        Phi[:, col:col + len(keep)] = rows[:, keep]
        col += len(keep)
        del rows
    t_read = time.perf_counter() - t0
    points = [0.0] + sorted(r.band.shift_hz for r in per_band
                            if 0 < r.band.shift_hz < s.f_max) + [s.f_max]
    counts = [0] + [r.n_below for r in sorted(per_band, key=lambda r: r.band.shift_hz)
                    if 0 < r.band.shift_hz < s.f_max] + [n_total]
    stats = {"bands": [r.to_json() for r in per_band],
             "n_bands": len(bands), "inertia_points_hz": points, "inertia_counts": counts,
             "merge_predicted_gb": need, "available_gb": avail,
             "eps_type": "block_lanczos_bands", "st_type": "sinvert", "factor_solver": "mumps",
             "tol": s.tol, "nconv": int(n_total), "time_merge_read": t_read,
             "linear_solves": int(sum(r.stats.get("linear_solves", 0) for r in per_band)),
             "time_factorization": float(sum(r.stats.get("time_factorization", 0.0)
                                             for r in per_band)),
             "time_solve": float(sum(r.stats.get("time_band", 0.0) for r in per_band)),
             "time_extract": 0.0}
    if len(per_band) == 1:
        lam1 = read_band(s.cache_dir / per_band[0].file, r0, r0)[0][keeps[0]]
        if len(lam1) >= n_total and (np.diff(lam1) >= 0).all():
            # the modes above the count are not needed: the first n_total, in place
            Phi = narrow_columns(Phi, n_total)
            band_checks = (proven or {}).get(bands[0].index)
            result = _merge_one_band(K, M, comm, Phi, lam1, points, counts, n_total, s,
                                     stats, progress,
                                     None if band_checks is None else
                                     band_checks.subset(keeps[0][:n_total]))
            if result is not None:
                return result
    t1 = time.perf_counter()
    known = [(proven or {}).get(b.index) for b in bands]
    if all(c is not None and c.gram is not None for c in known):
        blocks = [c.subset(k) for c, k in zip(known, keeps)]
        GK, GM = _band_grams(K, M, Phi, comm, [c.stiff for c in blocks],
                             [c.gram for c in blocks], progress)
        stats["merge_gram"] = "cross-band blocks (the bands' own blocks from their checks)"
        # (one band: _merge_one_band's rule; it only comes here when that refused)
        result = None if len(bands) == 1 else _merge_as_they_are(
            Phi, np.concatenate(lams), bands, blocks, GK, GM, points, counts, n_total, s,
            stats, t1)
        if result is None and len(bands) > 1:
            result = _merge_coupled(K, M, comm, Phi, np.concatenate(lams), bands, blocks, GK,
                                    GM, points, counts, n_total, s, stats, t1, progress)
        if result is not None:
            return result
    else:
        GM = _gram(M, Phi, comm, progress=progress, phase="merge: M-Gram products")
        GK = _gram(K, Phi, comm, progress=progress, phase="merge: K-Gram products")
        stats["merge_gram"] = "full"
    w, U = eigh(GM)
    good = w > DUPLICATE_GRAM * w.max()
    W = U[:, good] / np.sqrt(w[good])
    lam, Y = eigh(W.T @ GK @ W)
    n_dup = int((~good).sum())
    # the counted points: 0, every positive shift below f_max, f_max
    _check_merged_counts(points, counts, lam, n_total, s.f_max)
    Z = W @ Y[:, :n_total]
    Phi = rotate_narrowing(Phi, Z, progress, "merge: rotation")   # in the candidates' memory
    t_rr = time.perf_counter() - t1
    stats.update(n_candidates=int(W.shape[0]), n_duplicates=n_dup,
                 time_merge_rayleigh_ritz=t_rr, merge_rayleigh_ritz="full")
    result = Eigenpairs(lam[:n_total], np.ascontiguousarray(Phi), stats)
    normalise_and_check(result, K, M, comm, tol=s.tol, progress=progress)
    result.warnings = convergence_verdict(result, s.tol)
    return result


def _merge_as_they_are(Phi: np.ndarray, lam: np.ndarray, bands: list[Band],
                       blocks: list[BandChecks], GK: np.ndarray, GM: np.ndarray,
                       points: list[float], counts: list[int], n_total: int, s: BandSettings,
                       stats: dict, t1: float) -> Eigenpairs | None:
    """The merge of a multi-band plan without its Rayleigh-Ritz step, or ``None`` (the caller
    runs it). ``Phi``, ``lam``: the candidates (the bands' kept modes side by side, as the
    band files hold them bit for bit, and their eigenvalues); ``blocks``: their bands' checks
    (:class:`BandChecks`); ``GK``, ``GM``: ``Phi^T K Phi`` and ``Phi^T M Phi``, measured
    (:func:`_band_grams`: the bands' own blocks by their checks, the blocks between bands
    afresh). Each band contributes the modes inside its own edges (``[lo, hi)``, at most
    f_max): the duplicates of the neighbours' margins drop out. Taken when they are
    ``n_total``, agree with every inertia count, and their Gram matrices (the submatrices of
    ``GK``, ``GM``: every entry measured) meet :data:`~railvib_hpc.modal.ritz.
    RAW_RITZ_GRAM` and :data:`~railvib_hpc.modal.ritz.RAW_RITZ_STIFF`: then the residuals
    and round-off floors are the bands' (measured of these very vectors), the maxima of
    ``|Phi^T M Phi - I|`` and ``|Phi^T K Phi - Lambda| / lambda_max`` are those of the
    submatrices, and the rotation and the checks afresh (two sparse products per mode and
    two Gram products) are saved. ``Phi`` is overwritten (the modes, ascending, in its
    first ``n_total`` columns) only when taken."""
    from .block_lanczos import narrow_columns, permute_columns
    from .ritz import RAW_RITZ_GRAM, RAW_RITZ_STIFF

    lam_max = float(omega2(s.f_max))
    sel = _own_modes(lam, bands, blocks, lam_max)
    if len(sel) != n_total or check_counts(points, counts, hz(lam[sel])):
        stats["merge_as_they_are"] = "no: the bands' own modes do not match the counts"
        return None
    ix = np.ix_(sel, sel)
    upper = np.triu(np.ones((n_total, n_total), dtype=bool))
    err_m = float(np.abs(GM[ix] - np.eye(n_total))[upper].max(initial=0.0))
    err_k = float(np.abs(GK[ix] - np.diag(lam[sel]))[upper].max(initial=0.0)
                  / max(float(lam[sel].max(initial=0.0)), 1e-300))
    stats.update(merge_raw_gram_error=err_m, merge_raw_stiffness_error=err_k)
    if err_m > RAW_RITZ_GRAM or err_k > RAW_RITZ_STIFF * s.tol:
        stats["merge_as_they_are"] = (f"no: Gram errors {err_m:.1e} (M), {err_k:.1e} (K) "
                                      f"> {RAW_RITZ_GRAM:g}, {RAW_RITZ_STIFF:g} tol")
        return None
    residuals = np.concatenate([b.residuals for b in blocks])[sel]
    floors = np.concatenate([b.floors for b in blocks])[sel]
    rest = np.setdiff1d(np.arange(Phi.shape[1]), sel)
    permute_columns(Phi, np.concatenate([sel, rest]))
    result = Eigenpairs(lam[sel].copy(), narrow_columns(Phi, n_total), stats)
    result.residuals, result.residual_floors = residuals, floors
    stats.update(max_orthonormality_error=err_m, max_stiffness_diag_error=err_k,
                 max_relative_residual=float(residuals.max(initial=0.0)),
                 max_residual_floor=float(floors.max(initial=0.0)),
                 n_candidates=int(Phi.shape[1]), n_duplicates=int((lam[rest] <= lam_max).sum()),
                 merge_rayleigh_ritz="skipped: the bands' modes as they are",
                 merge_as_they_are="yes", merge_checks="the bands'", time_checks=0.0,
                 time_merge_rayleigh_ritz=time.perf_counter() - t1)
    result.warnings = convergence_verdict(result, s.tol)
    return result


def _coupled_set(GK: np.ndarray, GM: np.ndarray, lam: np.ndarray, tol: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The pairs of a merge that its Rayleigh-Ritz step must rotate, and the step.

    ``GK``, ``GM``: the measured ``Phi^T K Phi`` and ``Phi^T M Phi`` of the bands' own
    modes (each once, eigenvalues ``lam``). An entry is *coupled* when it exceeds what a
    Ritz vector kept as it is may show: ``|(Phi^T M Phi - I)_ij| >``
    :data:`~railvib_hpc.modal.ritz.RAW_RITZ_GRAM` or ``|(Phi^T K Phi - Lambda)_ij| /
    lambda_max >`` :data:`~railvib_hpc.modal.ritz.RAW_RITZ_STIFF` ``tol``; the pairs of a
    coupled entry form ``S``, the others ``U``. The Rayleigh-Ritz step in ``span(Phi_S)``
    (``Z``: ``Z^T G_SS Z = I``, ``Z^T K_SS Z = diag(mu)``) leaves ``Phi_U`` as it is and
    changes the blocks between the two sets to ``G_US Z`` and ``K_US Z``; a pair of ``U``
    with an entry there above the same bounds joins ``S`` and the step is made again, until
    none has (``S`` only grows). Then every entry among ``U`` (measured) and, to the
    rotation's rounding, between ``U`` and the rotated ``S`` meets the bounds (the merge's
    checks measure the latter afresh).

    Returns ``(S, U, Z, mu)`` (positions in ``lam``), or ``None`` when the full merge must
    run instead: every pair is coupled, or ``G_SS`` has a direction below
    :data:`DUPLICATE_GRAM` (a duplicate, which the full merge drops).
    """
    from scipy.linalg import eigh

    from .ritz import RAW_RITZ_GRAM, RAW_RITZ_STIFF

    n = len(lam)
    lam_top = max(float(np.abs(lam).max(initial=0.0)), 1e-300)

    def above(gm: np.ndarray, gk: np.ndarray) -> np.ndarray:
        return (np.abs(gm) > RAW_RITZ_GRAM) | (np.abs(gk) / lam_top > RAW_RITZ_STIFF * tol)

    bad = above(GM - np.eye(n), GK - np.diag(lam))
    coupled = bad.any(axis=0) | bad.any(axis=1)
    while True:
        S, U = np.flatnonzero(coupled), np.flatnonzero(~coupled)
        if not U.size:
            return None
        w, V = eigh(GM[np.ix_(S, S)])
        if w.min(initial=1.0) <= DUPLICATE_GRAM * w.max(initial=1.0):
            return None
        W = V / np.sqrt(w)
        mu, Y = eigh(W.T @ GK[np.ix_(S, S)] @ W)
        Z = W @ Y
        grow = above(GM[np.ix_(U, S)] @ Z, GK[np.ix_(U, S)] @ Z).any(axis=1)
        if not grow.any():
            return S, U, Z, mu
        coupled[U[grow]] = True


def _merge_coupled(K, M, comm, Phi: np.ndarray, lam: np.ndarray, bands: list[Band],
                   blocks: list[BandChecks], GK: np.ndarray, GM: np.ndarray,
                   points: list[float], counts: list[int], n_total: int, s: BandSettings,
                   stats: dict, t1: float, progress=None) -> Eigenpairs | None:
    """The merge of a multi-band plan with its Rayleigh-Ritz step on the coupled pairs only,
    or ``None`` (the caller runs the full merge). Arguments as :func:`_merge_as_they_are`,
    which refused (some entries of the measured Gram matrices exceed its bounds: at the
    issue-26 case M-overlaps between bands up to 1.2e-9).

    The bands' own modes (each once, :func:`_own_modes`) must be ``n_total`` and agree with
    every inertia count, before and after the step. :func:`_coupled_set` splits them into
    ``U``, kept as they are, and ``S``, rotated by a Rayleigh-Ritz step in their own span.
    What is reported, and why it covers what the full merge's checks afresh measured:

    * ``U``: the same vectors, bit for bit, as the band files (the bands' checks measured
      them): their residuals and round-off floors are the bands'; their Gram blocks among
      themselves are the measured ones (the bands' own blocks from their checks, the
      cross-band blocks afresh, :func:`_band_grams`), every entry within
      :data:`~railvib_hpc.modal.ritz.RAW_RITZ_GRAM` and ``RAW_RITZ_STIFF tol``; their
      eigenvalues are the bands' (a coupling ``e`` within those bounds moves a Rayleigh-
      Ritz eigenvalue by ``O(e^2 / relgap)``, below the eigenvalues' own accuracy).
    * ``S``: rotated and checked afresh (:func:`~railvib_hpc.modal.ritz.
      normalise_and_check` with the ``U`` checks as ``known``): K and M products of the
      rotated vectors, their Gram entries against every mode, their residuals and floors.

    So every entry of ``Phi^T M Phi`` and ``Phi^T K Phi`` and every residual of the result
    is measured of the returned vectors, as in the full merge; the rotation of ``U``, its
    K and M products and its floors are saved (``stats["merge_coupled"]``: the size of
    ``S``). ``Phi`` is overwritten only when taken (the modes, ascending, in its first
    ``n_total`` columns). It pays where the coupling is local (the 60-element column:
    2 of 31 modes); at the issue-26 case (2 bands of 161 and 135 modes) every mode of
    the upper band overlaps some mode of the lower one by 1.6e-11 or more (measured: 99.99 %
    of each one's overlaps fall on the lower band's top 20 modes), so every pair is coupled
    and the full merge runs.
    """
    from .block_lanczos import narrow_columns, permute_columns, rotate_in_place
    from .ritz import Known, normalise_and_check

    lam_max = float(omega2(s.f_max))
    sel = _own_modes(lam, bands, blocks, lam_max)
    if len(sel) != n_total or check_counts(points, counts, hz(lam[sel])):
        return None
    ix = np.ix_(sel, sel)
    split = _coupled_set(GK[ix], GM[ix], lam[sel], s.tol)
    if split is None:
        stats["merge_coupled"] = "no: every pair coupled, or a duplicate"
        return None
    S, U, Z, mu = split
    lam_new = np.concatenate([lam[sel[U]], mu])
    if check_counts(points, counts, hz(np.sort(lam_new))):
        stats["merge_coupled"] = "no: the rotated eigenvalues do not match the counts"
        return None
    c, q = U.size, S.size
    rest = np.setdiff1d(np.arange(Phi.shape[1]), sel)
    permute_columns(Phi, np.concatenate([sel[U], sel[S], rest]))
    rotate_in_place(Phi[:, c:c + q], Z, progress, "merge: rotation")
    phi = narrow_columns(Phi, n_total)
    t_rr = time.perf_counter() - t1
    residuals = np.concatenate([b.residuals for b in blocks])[sel[U]]
    floors = np.concatenate([b.floors for b in blocks])[sel[U]]
    iu = np.ix_(sel[U], sel[U])
    # (||K phi|| of the known modes is not read: their floors are given)
    known = Known(GM[iu], GK[iu], np.full(c, np.nan), residuals, floors)
    result = Eigenpairs(lam_new, phi, stats)
    normalise_and_check(result, K, M, comm, tol=s.tol, progress=progress, known=known)
    asc = np.argsort(result.eigenvalues, kind="stable")
    permute_columns(result.phi, asc)
    result.eigenvalues = result.eigenvalues[asc]
    result.residuals = result.residuals[asc]
    result.residual_floors = result.residual_floors[asc]
    stats.update(n_candidates=int(Phi.shape[1]),
                 n_duplicates=int((lam[rest] <= lam_max).sum()),
                 merge_rayleigh_ritz=f"coupled pairs: {q} of {n_total}", merge_coupled=q,
                 merge_checks=f"afresh for the {q} rotated modes, the bands' for the others",
                 time_merge_rayleigh_ritz=t_rr)
    result.warnings = convergence_verdict(result, s.tol)
    return result


def _own_modes(lam: np.ndarray, bands: list[Band], blocks: list[BandChecks],
               lam_max: float) -> np.ndarray:
    """The candidates (``lam``: the bands' kept eigenvalues side by side, ``blocks``: their
    checks, one per band) that lie inside their own band's edges (``[lo, hi)``, at most
    ``lam_max``), ascending: each mode once, the neighbours' margins left out."""
    edges = np.concatenate([[0], np.cumsum([len(b.residuals) for b in blocks])])
    own = []
    for band, b0, b1 in zip(bands, edges[:-1], edges[1:]):
        lo, hi, lb = float(omega2(band.lo_hz)), float(omega2(band.hi_hz)), lam[b0:b1]
        own.append(b0 + np.flatnonzero((lb >= lo) & (lb < hi) & (lb <= lam_max)))
    sel = np.concatenate(own)
    return sel[np.argsort(lam[sel], kind="stable")]


def _check_merged_counts(points: list[float], counts: list[int], lam: np.ndarray,
                         n_total: int, f_max: float) -> None:
    """Raise :class:`EigenSolveError` when the merged eigenvalues ``lam`` (ascending) do not
    match the inertia ``counts`` at ``points`` [Hz] or are fewer than ``n_total``."""
    bad = check_counts(points, counts, hz(lam))
    if bad or len(lam) < n_total:
        lo, hi, expected, found = bad[0] if bad else (0.0, f_max, n_total, len(lam))
        raise EigenSolveError(
            f"band-sliced eigensolve: {found} distinct modes found in [{lo:.4f}, {hi:.4f}] Hz "
            f"but the inertia counts say {expected}; use more bands (smaller "
            "modal.band_modes) or a larger modal.block_size (repeated eigenvalues of a "
            "multiplicity above the block size)")


#: A one-band plan skips the merge's Rayleigh-Ritz step when the checks measure
#: ``max_i sum_j |(Phi^T M Phi - I)_ij|`` (Gershgorin) of the band's modes below this: the
#: M-Gram eigenvalues then lie in [0.5, 1.5] (no duplicate: :data:`DUPLICATE_GRAM`), and
#: the Rayleigh-Ritz eigenvalues of a basis whose Gram matrices are I and diag(lambda) up
#: to ``e`` differ from the band's by O(e) (measured: 1e-14 relative).
ONE_BAND_GRAM = 1e-8


@dataclass
class BandChecks:
    """What a band's own checks (:func:`~railvib_hpc.modal.ritz.normalise_and_check`)
    measured of the modes it wrote (its band file's columns, in order): the relative
    residuals, their round-off floors (without the solves' floors: the merge's own checks
    would not count them) and the largest errors of the whole set."""

    residuals: np.ndarray
    floors: np.ndarray
    max_orthonormality_error: float
    max_stiffness_diag_error: float
    #: Phi^T M Phi and Phi^T K Phi of the band's modes (the multi-band merge's diagonal
    #: blocks, :func:`_band_grams`)
    gram: np.ndarray | None = None
    stiff: np.ndarray | None = None

    @classmethod
    def of(cls, result: Eigenpairs) -> BandChecks:
        st = result.stats
        return cls(result.residuals.copy(), result.roundoff_floors.copy(),
                   float(st["max_orthonormality_error"]),
                   float(st["max_stiffness_diag_error"]), result.gram, result.stiff)

    def subset(self, cols: np.ndarray) -> BandChecks:
        """The checks of the columns ``cols`` (the set's maxima bound the subset's)."""
        ix = np.ix_(cols, cols)
        return BandChecks(self.residuals[cols], self.floors[cols],
                          self.max_orthonormality_error, self.max_stiffness_diag_error,
                          None if self.gram is None else self.gram[ix],
                          None if self.stiff is None else self.stiff[ix])


def _merge_one_band(K, M, comm, Phi: np.ndarray, lam: np.ndarray, points: list[float],
                    counts: list[int], n_total: int, s: BandSettings, stats: dict,
                    progress=None, proven: BandChecks | None = None) -> Eigenpairs | None:
    """The merge of a one-band plan: the band's modes ``Phi`` with its eigenvalues ``lam``
    (its own Rayleigh-Ritz step made them M-orthonormal and K-orthogonal), checked by one
    :func:`~railvib_hpc.modal.ritz.normalise_and_check` (K Phi and M Phi afresh from the
    band file: orthonormality, K-orthogonality, residuals, round-off floors) instead of
    the M and K Gram products, the merge's Rayleigh-Ritz step, and the same checks again.
    With ``proven`` (the band was solved in this run: its checks measured the vectors of
    its file) even that is skipped: the band's residuals, floors and maxima are the
    merge's (``stats["merge_checks"]``: "the band's" or "afresh").
    ``lam``: the band's kept eigenvalues, ascending (all of them are counted against the
    inertia); ``Phi`` holds the modes of the ``n_total`` lowest. Returns ``None`` (the
    caller runs the full merge on ``Phi``, scaled to unit modal mass) when the measured
    Gram matrix does not prove the band orthonormal (:data:`ONE_BAND_GRAM`).
    """
    from .ritz import normalise_and_check

    t0 = time.perf_counter()
    result = Eigenpairs(lam[:n_total].copy(), Phi, stats)
    if proven is not None:
        # the band's checks measured these very vectors (the band file holds them
        # bit for bit): its residuals, floors and maxima stand
        result.residuals, result.residual_floors = proven.residuals, proven.floors
        stats.update(max_orthonormality_error=proven.max_orthonormality_error,
                     max_stiffness_diag_error=proven.max_stiffness_diag_error,
                     max_relative_residual=float(proven.residuals.max(initial=0.0)),
                     max_residual_floor=float(proven.floors.max(initial=0.0)),
                     time_checks=0.0, merge_checks="the band's")
        if n_total * proven.max_orthonormality_error > ONE_BAND_GRAM:   # (Gershgorin)
            return None
    else:
        checks = normalise_and_check(result, K, M, comm, tol=s.tol, progress=progress)
        off = np.abs(checks.gram - np.eye(n_total)).sum(axis=1)
        stats["merge_checks"] = "afresh"
        if n_total and off.max() > ONE_BAND_GRAM:
            return None
    _check_merged_counts(points, counts, lam, n_total, s.f_max)
    stats.update(n_candidates=n_total, n_duplicates=0, merge_rayleigh_ritz="skipped: one band",
                 time_merge_rayleigh_ritz=0.0, time_merge_checks=time.perf_counter() - t0)
    result.warnings = convergence_verdict(result, s.tol)
    return result
