"""Band-sliced eigensolve: every mode below ``f_max``, band by band (PETSc/MPI driver).

The plan and its proof are in :mod:`railvib_hpc.modal.bands`. Here:

1. ``N(f_max)``: one factorisation of ``K - omega(f_max)^2 M`` and its inertia.
2. Per band: factor ``K - sigma M`` (its inertia gives ``N(sigma)``), block shift-invert
   Lanczos until every eigenvalue of the band and two beyond it have converged
   (:func:`~railvib_hpc.modal.block_lanczos.block_lanczos` with ``theta_cut``), purify
   (:func:`~railvib_hpc.modal.eigen.purified_modes`; only the band's own pairs must reach
   the tolerance), write the band's own modes to
   ``<out>/bands/band_<shift>.h5`` and free the basis: the dense memory is bounded by the
   largest band, not by all modes. The lowest band (shift 0) also solves the static
   correction with its factor.
3. Bands run one after the other on all ranks, or ``modal.band_groups`` at a time on
   sub-communicators, or as separate jobs (``modal.band_only``); the merge reads the band
   files.
4. Merge: a Rayleigh-Ritz step with K and M in the union of the bands' modes removes
   the modes two bands found both (directions of the union's M-Gram matrix below
   :data:`DUPLICATE_GRAM`) and makes all modes M-orthonormal together; the eigenvalues
   below ``f_max`` are kept and counted against the inertia of every stretch between two
   counted points (:func:`railvib_hpc.modal.bands.check_counts`). Bands solved in this run
   need less: their modes as they are when the measured Gram matrices allow
   (:func:`_merge_as_they_are`), else the step on the coupled pairs only
   (:func:`_merge_coupled`), else the full step.

Cache: ``<out>/bands`` (:mod:`railvib_hpc.io.formats.bands`: its layout, writer, reader
and check) records the bands, the inertia counts and the merged chain. It is a product of
the modal stage: the stage reuses it through the product layer (its inputs digest leaves
out ``f_max`` and the band split) and gives its index and provenance in
:class:`BandSettings`; a run reuses every band of its plan, and a higher ``f_max`` only
adds bands above the old one.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.files import BAND_INDEX_JSON
from ..io.formats.bands import band_file_name, empty_index, read_band, write_band, write_index
from ..resources import (
    current_memory_gb,
    peak_memory_gb,
    release_memory,
    reset_peak_memory,
)
from .bands import Band, check_counts, hz, omega2, plan_bands
from .ritz import (
    PREFIX,
    RETRY_TOL_FACTOR,
    Eigenpairs,
    EigenSolveError,
    convergence_verdict,
    hopeless,
    in_window,
    purified_modes,
)

#: A direction of the union of the bands' modes whose M-Gram eigenvalue is below this
#: fraction of the largest is a duplicate (two bands found the same mode): two copies
#: differing by e give an eigenvalue ~|e|^2 / 2, and |e| <= 2 rho / relgap <= 1e-4 for
#: residuals rho <= 1e-8 and relative gaps >= 2e-4, i.e. <= 5e-9; distinct M-orthogonal
#: modes give ~1.
DUPLICATE_GRAM = 1e-6

#: Converged modes beyond each band's edge that the Lanczos run must also deliver: the
#: proof that the band is complete (Krylov methods converge the largest |theta| first).
#: They are not kept (:func:`_trim`): the neighbouring band computes them.
EDGE_MARGIN = 2

#: Relative widening of a band's eigenvalue range when its modes are kept: an eigenvalue
#: on an edge is computed by both bands to ~1e-12 and may fall on either side; with the
#: overlap at least one band keeps it (two copies are merged by the Gram test).
EDGE_OVERLAP = 1e-6

#: Relative nudge of a shift that hits an eigenvalue (singular factor).
SHIFT_NUDGE = 1e-6

#: Basis size of a band's Lanczos run before a thick restart, in multiples of the band's
#: modes (as the single-shift stage's 3 n_modes): measured on the thesis model, 1006 modes
#: in 5 bands, 2 x needed 5-7 restarts per band and 7-9.5 right-hand sides per mode.
BASIS_FACTOR = 3

#: The most modes a band-sliced solve computes, as a share of the model's free DOFs. A mesh
#: resolves only the bottom of its spectrum: at ``mesh.min_elements_per_wavelength`` = 6,
#: Weyl's law for shear waves (two polarisations, N(f) = 8 pi V f^3 / (3 c_S^3)) puts
#: about 4 % of the elements, 1-2 % of the DOFs, below the resolved frequency. Above a
#: quarter of the DOFs the modes are mesh artefacts, the Weyl band plan misjudges the
#: saturated top of a discrete spectrum, and the merge's dense eigenproblem (cubic in the
#: count) dominates; a higher ``modal.f_max`` is refused before the bands are solved.
MAX_MODE_SHARE = 0.25


@dataclass
class BandRecord:
    """A solved band as cached in ``index.json`` (rank 0's view)."""

    band: Band
    file: str
    n_below: int
    n_modes: int
    cover_lo_hz: float
    cover_hi_hz: float
    stats: dict = field(default_factory=dict)
    #: the band file's content digest (the cache's check compares it)
    sha256: str = ""

    def to_json(self) -> dict:
        b = self.band
        return {"index": b.index, "lo_hz": b.lo_hz, "hi_hz": b.hi_hz, "shift_hz": b.shift_hz,
                "file": self.file, "n_below": self.n_below, "n_modes": self.n_modes,
                "cover_lo_hz": self.cover_lo_hz, "cover_hi_hz": self.cover_hi_hz,
                "stats": self.stats, "sha256": self.sha256}

    @classmethod
    def from_json(cls, d: dict) -> BandRecord:
        return cls(Band(int(d["index"]), float(d["lo_hz"]), float(d["hi_hz"]),
                        float(d["shift_hz"])), d["file"], int(d["n_below"]), int(d["n_modes"]),
                   float(d["cover_lo_hz"]), float(d["cover_hi_hz"]), dict(d.get("stats", {})),
                   str(d.get("sha256", "")))


def _same(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1.0)


class BandCache:
    """The band cache in memory: the index of ``<out>/bands`` as the modal stage reused it
    (checked and current, on every rank; None: empty), saved by rank 0 with its provenance
    (:mod:`railvib_hpc.io.formats.bands`)."""

    def __init__(self, folder: Path, comm, index: dict | None = None,
                 provenance: dict | None = None):
        self.folder, self.comm, self.provenance = Path(folder), comm, provenance
        data = index or empty_index()
        self.counts: dict[float, int] = {float(k): int(v) for k, v in data["counts"].items()}
        self.bands = [BandRecord.from_json(d) for d in data["bands"]]
        self.chain = data.get("chain")

    def find(self, band: Band) -> BandRecord | None:
        for r in self.bands:
            if _same(r.band.lo_hz, band.lo_hz) and _same(r.band.hi_hz, band.hi_hz) and \
                    _same(r.band.shift_hz, band.shift_hz):
                return r
        return None

    def count(self, f_hz: float) -> int | None:
        for f, n in self.counts.items():
            if _same(f, f_hz):
                return n
        return None

    def save(self) -> None:
        """Rank 0 writes the index (call on every rank after the band files exist)."""
        if self.comm.rank == 0:
            data = {"counts": {repr(k): v for k, v in self.counts.items()},
                    "bands": [r.to_json() for r in self.bands], "chain": self.chain}
            write_index(self.folder / BAND_INDEX_JSON, data, self.provenance)
        self.comm.Barrier()


@dataclass
class BandSettings:
    """What :func:`solve_bands` needs besides the matrices."""

    f_max: float
    edges: list[float]
    band_modes: int
    groups: int
    band_only: int
    tol: float
    block_size: int
    max_restarts: int
    out_of_core: str
    cache_dir: Path
    #: the cache's index as the modal stage reused it (None: an empty cache)
    index: dict | None = None
    #: the provenance its index is written with (None: a temporary cache, never reused)
    provenance: dict | None = None


def _factor(K, M, comm, sigma: float, extra_gb: float, out_of_core: str, inertia: bool):
    """The :class:`~.factor.ShiftInvertFactor` at ``sigma`` (nudged when it hits an
    eigenvalue)."""
    from ..model.factor import FactorizationError, InsufficientMemory, ShiftInvertFactor

    for attempt in range(3):
        s = sigma * (1.0 + SHIFT_NUDGE * attempt) if sigma else 0.0
        try:
            return ShiftInvertFactor(K, M, s, comm, PREFIX, extra_gb=extra_gb,
                                     out_of_core=out_of_core, inertia=inertia)
        except InsufficientMemory as exc:
            raise EigenSolveError(str(exc)) from None
        except FactorizationError as exc:
            if attempt == 2 or not sigma:
                raise EigenSolveError(str(exc)) from None
    raise AssertionError("unreachable")


def count_below(K, M, comm, f_hz: float, out_of_core: str) -> int:
    """``N(f)``: eigenvalues below ``f_hz``, from the inertia of ``K - omega^2 M``."""
    op = _factor(K, M, comm, float(omega2(f_hz)), 0.0, out_of_core, inertia=True)
    try:
        return int(op.n_below)
    finally:
        op.destroy()


def count_band(K, M, comm, band: Band, cache: BandCache, out_of_core: str, log=None,
               f_max: float = math.inf) -> int:
    """The modes in ``band``: ``N(hi) - N(lo)`` by inertia (one factorisation per edge not in
    the cache, none for ``lo = 0``), recorded in the cache (collective).

    For an array task with the user's edges (``modal.band_only`` with ``modal.bands``), which
    has no count at ``f_max`` to estimate its band from: a basis sized for the count converges
    on the first try, where Weyl's guess without a count (16 modes) took two retries, each
    with its own factorisation (coarse thesis model, 2 ranks, the 193-mode band
    [44.03, 55.47] Hz: 107 s before, 27 s now).
    """
    counts = []
    for f in (band.lo_hz, band.hi_hz):
        n = 0 if f == 0.0 else cache.count(f)
        if n is None:
            t0 = time.perf_counter()
            n = count_below(K, M, comm, f, out_of_core)
            cache.counts[float(f)] = n
            if log is not None:
                log(f"  {n} modes below {f:g} Hz (counted in {time.perf_counter() - t0:.1f} s)")
        counts.append(n)
    check_mode_count("modal.f_max" if band.hi_hz >= f_max else "modal.bands", band.hi_hz,
                     counts[1], K.getSize()[0], comm)
    return max(1, counts[1] - counts[0])


def mode_count_limit(n_dofs: int, avail_gb: float) -> tuple[int, str]:
    """The most modes a band-sliced solve of ``n_dofs`` DOFs may compute, and why: the
    smaller of :data:`MAX_MODE_SHARE` of the DOFs and what the merge's dense arrays
    (:func:`merge_memory_gb`) leave of 90 % of ``avail_gb``."""
    from .ritz import NORMALISE_CHUNK

    by_share = int(MAX_MODE_SHARE * n_dofs)
    by_memory = max(0, int(0.9 * avail_gb * 1e9 / (8.0 * n_dofs)) - 4 * NORMALISE_CHUNK)
    if by_memory < by_share:
        return by_memory, (f"the merge holds them all, {8.0 * n_dofs / 1e9:.2g} GB per mode, "
                           f"and {avail_gb:.1f} GB are available")
    return by_share, (f"{100 * MAX_MODE_SHARE:g} % of its {n_dofs:,} free DOFs; a mesh "
                      "resolves only the lowest 1-2 % of its spectrum")


def check_mode_count(key: str, f_hz: float, n_below: int, n_dofs: int, comm) -> None:
    """Refuse (:class:`EigenSolveError`, one line) a band plan up to ``f_hz`` (the value of
    the case key ``key``) whose inertia count ``n_below`` exceeds :func:`mode_count_limit`;
    called before any band is solved (collective)."""
    from ..model.factor import available_memory_gb

    limit, why = mode_count_limit(n_dofs, available_memory_gb(comm))
    if n_below <= limit:
        return
    every = ": every DOF of the model" if n_below >= n_dofs else ""
    raise EigenSolveError(
        f"{key} = {f_hz:g} Hz: {n_below:,} modes lie below it (inertia count{every}), more "
        f"than the {limit:,} a band-sliced solve of this model may compute ({why}); use a "
        f"lower {key}")


def _band_estimate(band: Band, f_max: float, n_total: int | None) -> int:
    """Weyl's estimate of the modes in ``band`` (at least 1; 16 without a count)."""
    if n_total is None:
        return 16
    share = (band.hi_hz**3 - band.lo_hz**3) / max(f_max**3, 1e-300)
    return max(1, int(math.ceil(share * n_total)))


def solve_band(K, M, comm, band: Band, estimate: int, s: BandSettings, monitor=None,
               static_rhs: np.ndarray | None = None, progress=None
               ) -> tuple[Eigenpairs, int, dict]:
    """One band: factor, block Lanczos to the band's radius, purify. Collective on ``comm``.

    Returns the modes (all converged: the band plus :data:`EDGE_MARGIN` beyond each edge),
    ``N(sigma)`` and statistics. ``progress``:
    :data:`~railvib_hpc.model.factor.Progress` of the phases after the expansions.
    """
    from mpi4py import MPI

    from .block_lanczos import (
        NotConverged,
        block_lanczos,
        default_max_basis,
        dense_gb,
        effective_block,
    )

    t0 = time.perf_counter()
    n_global = K.getSize()[0]
    b = effective_block(s.block_size, n_global)
    nev = min(estimate + 2 * EDGE_MARGIN, max(n_global - 3 * b, 1))
    for attempt in range(3):
        max_basis = min(max(BASIS_FACTOR * nev, default_max_basis(nev, b)) * (2**attempt),
                        n_global - b)
        extra_gb = dense_gb(n_global, max_basis, b, nev + b, 0 if static_rhs is None else
                            comm.allreduce(static_rhs.shape[1], op=MPI.MAX))
        op = _factor(K, M, comm, band.sigma, extra_gb, s.out_of_core, inertia=band.sigma > 0)
        try:
            for lanczos_tol in (s.tol, s.tol / RETRY_TOL_FACTOR):
                result = X = None          # a retry's Lanczos run reuses their memory
                _, X, st = block_lanczos(op, min(nev, max_basis - 2 * b),
                                         K.getOwnershipRange()[0], block=b, tol=lanczos_tol,
                                         max_basis=max_basis, max_restarts=s.max_restarts,
                                         monitor=monitor, theta_cut=band.theta_cut,
                                         margin=EDGE_MARGIN, guard=b, progress=progress)
                t_p = time.perf_counter()
                window = band_window(band)
                result = purified_modes(op, X, st["block_size"], K, M, comm, s.tol, st, window,
                                        progress=progress)
                X = None                   # overwritten by the modes (and guards)
                st["time_purify_project"] = time.perf_counter() - t_p
                st["lanczos_tol"] = lanczos_tol
                if not (hopeless(result, s.tol) & in_window(result, window)).any():
                    break
        except NotConverged as exc:
            op.destroy()
            if attempt == 2:
                raise EigenSolveError(f"{band.label(0)}: {exc}; use more bands "
                                      "(smaller modal.band_modes or more modal.bands)") from None
            continue
        except BaseException:
            op.destroy()
            raise
        try:
            if static_rhs is not None and op.sigma == 0.0:
                t_s = time.perf_counter()
                result.static = op.solve(static_rhs, progress=progress, phase="static solves")
                st["time_static_solves"] = time.perf_counter() - t_s
            n_below = 0 if op.n_below is None else op.n_below
            st["linear_solves"] = op.n_solves            # Lanczos, purification, static
            st["time_block_solves"] = op.time_solves
            st.update(time_factorization=op.time_factorization,
                      factor_memory_gb=op.factor_memory_gb, out_of_core=op.out_of_core,
                      predicted_peak_gb=op.predicted_peak_gb,
                      predicted_parts_gb=dict(op.memory_parts), shift_hz=float(hz(op.sigma)))
        finally:
            op.destroy()
        st["basis_attempts"] = attempt + 1       # > 1: the band outgrew its first basis
        st["time_band"] = time.perf_counter() - t0
        return result, n_below, st
    raise AssertionError("unreachable")


def free_memory(comm) -> None:
    """Collective on ``comm``: destroy the PETSc objects petsc4py stashed when their last
    Python reference went (``PETSc.garbage_cleanup``; the band's own objects are destroyed
    explicitly, this catches any other), then return the freed heap to the system."""
    from petsc4py import PETSc

    PETSc.garbage_cleanup(comm)
    release_memory()


def _total(comm, value: float) -> float:
    """Sum of a per-rank value over ``comm`` (memory of all ranks)."""
    return float(comm.allreduce(value))


def band_memory(comm, own_peak: bool) -> dict:
    """Memory after a band is freed, summed over the ranks of ``comm`` [GB].

    ``rss_after_free_gb``: resident now (``VmRSS``; the band's factor, basis and modes are
    gone, only what outlives it is left); ``peak_rss_band_gb``: the band's own peak
    (``VmHWM`` since its start, when ``own_peak``: every rank could restart the count;
    else NaN); ``peak_rss_gb``: the peak of the processes so far.
    """
    return {"rss_after_free_gb": _total(comm, current_memory_gb()),
            "peak_rss_band_gb": _total(comm, peak_memory_gb(since_reset=True))
            if own_peak else float("nan"),
            "peak_rss_gb": _total(comm, peak_memory_gb())}


def band_line(rec: BandRecord, n_bands: int) -> str:
    """The log line of a solved band: modes, time and memory (all ranks)."""
    st = rec.stats
    return (f"  {rec.band.label(n_bands)}: {rec.n_modes} modes in {st['time_band']:.1f} s; "
            f"memory (all ranks) before {st['rss_before_gb']:.2f} GB, peak "
            f"{st['peak_rss_band_gb']:.2f} GB (predicted {st['predicted_peak_gb']:.2f} GB, "
            f"factor {st['factor_memory_gb']:.2f} GB), at the end "
            f"{st['rss_band_end_gb']:.2f} GB, freed {st['rss_after_free_gb']:.2f} GB")


def band_window(band: Band) -> tuple[float, float]:
    """The band's eigenvalue range, widened by :data:`EDGE_OVERLAP` at both edges."""
    return (float(omega2(band.lo_hz)) * (1.0 - EDGE_OVERLAP),
            float(omega2(band.hi_hz)) * (1.0 + EDGE_OVERLAP))


def _trim(result: Eigenpairs, band: Band) -> Eigenpairs:
    """The band's own modes (:func:`band_window`): what the merge needs. The pairs beyond
    the edges (the Lanczos margin) are the neighbouring bands' modes, computed there."""
    keep = np.flatnonzero(in_window(result, band_window(band)))
    out = Eigenpairs(result.eigenvalues[keep], np.ascontiguousarray(result.phi[:, keep]),
                      result.stats, result.static)
    out.residuals = result.residuals[keep]
    out.residual_floors = result.residual_floors[keep]
    if result.roundoff_floors is not None:
        out.roundoff_floors = result.roundoff_floors[keep]
    if result.gram is not None:
        out.gram, out.stiff = result.gram[np.ix_(keep, keep)], result.stiff[np.ix_(keep, keep)]
    return out


def _record(cache: BandCache, rec: BandRecord) -> None:
    """Put a solved band (and the inertia count at its shift) into the cache's index."""
    cache.bands = [c for c in cache.bands if c.file != rec.file] + [rec]
    if rec.band.shift_hz > 0:
        cache.counts[float(rec.band.shift_hz)] = rec.n_below


def plan_for(cache: BandCache, s: BandSettings, n_total: int) -> list[Band]:
    """The bands for ``[0, f_max]``: the cached merged chain (when it covers a lower f_max,
    only bands above it are added), or a fresh plan."""
    chain = cache.chain
    if chain:
        f_c = float(chain["f_hz"])
        old = [Band(int(d["index"]), float(d["lo_hz"]), float(d["hi_hz"]), float(d["shift_hz"]))
               for d in chain["bands"]]
        n_c = cache.count(f_c)
        if n_c is not None and all(cache.find(b) for b in old):
            if f_c >= s.f_max * (1 - 1e-12):
                return [b for b in old if b.lo_hz < s.f_max]
            return old + plan_bands(s.f_max, n_total, s.band_modes, s.edges, start_hz=f_c,
                                    first_index=len(old) + 1, n_below_start=n_c)
    return plan_bands(s.f_max, n_total, s.band_modes, s.edges)


def solve_bands(K, M, comm, s: BandSettings, assemble=None, monitor=None,
                static_rhs: np.ndarray | None = None, log=None,
                progress=None) -> Eigenpairs | None:
    """Every mode below ``s.f_max`` by band slicing (collective on ``comm``).

    Parameters
    ----------
    K, M
        The matrices on ``comm``.
    s
        :class:`BandSettings`.
    assemble
        ``assemble(subcomm) -> (K, M)`` for band groups on sub-communicators.
    monitor
        ``monitor(done, total, basis, label=...)`` progress callback (modes of all bands).
    static_rhs
        Rows of right-hand sides solved with the lowest band's factor (shift 0).
    log
        ``log(line)``: one line per solved band (modes, time, memory: :func:`band_line`);
        the numbers are also in the band's ``stats`` (:func:`band_memory`).
    progress
        ``progress(phase, done, total)``: the phases after each band's expansions and the
        merge's (:data:`~railvib_hpc.model.factor.Progress`).

    Returns
    -------
    Eigenpairs, or None with ``band_only`` (the band is cached, nothing merged).
    """
    t_start = time.perf_counter()
    plan = _plan_solve(K, M, comm, s, log)
    records, proven, static = _solve_planned(K, M, comm, s, plan, assemble, monitor,
                                             static_rhs, log, progress)
    cache, n_bands = plan.cache, len(plan.bands)
    for rec in (r for part in comm.allgather(records) for r in part):
        r = BandRecord.from_json(rec)
        if log is not None and plan.groups > 1:
            log(band_line(r, n_bands))
        _record(cache, r)
    cache.save()
    if s.band_only:
        return None
    return _merge_planned(K, M, comm, s, plan, static, proven, log, progress, t_start)


@dataclass
class _SolvePlan:
    """What :func:`solve_bands` plans before it solves a band: the band cache, ``N(f_max)``
    (None: an array task with given edges, which counts its own band instead) and the
    seconds its count took, the bands of the plan, those to solve here, the band groups,
    and the exact mode counts of the bands to solve (by index, when ``n_total`` is None)."""

    cache: BandCache
    n_total: int | None
    t_count: float
    bands: list[Band]
    todo: list[Band]
    groups: int
    exact: dict[int, int]


def _plan_solve(K, M, comm, s: BandSettings, log=None) -> _SolvePlan:
    """The cache, the count at ``f_max``, the plan and the bands to solve; the refusals
    before any band is solved (collective)."""
    s.cache_dir.mkdir(parents=True, exist_ok=True) if comm.rank == 0 else None
    comm.Barrier()
    cache = BandCache(s.cache_dir, comm, s.index, s.provenance)
    t0 = time.perf_counter()
    n_total = cache.count(s.f_max)
    if n_total is None and not (s.band_only and s.edges):
        if log is not None:
            log(f"counting the modes below modal.f_max = {s.f_max:g} Hz (inertia of one "
                f"factorisation of K - omega^2 M, {K.getSize()[0]:,} DOFs) ...")
        n_total = count_below(K, M, comm, s.f_max, s.out_of_core)
        cache.counts[float(s.f_max)] = n_total
        if log is not None:
            log(f"  {n_total} modes below {s.f_max:g} Hz (counted in "
                f"{time.perf_counter() - t0:.1f} s)")
    # an array task with given edges needs no count at f_max (the merge counts there); it
    # counts its own band instead (:func:`count_band`)
    t_count = time.perf_counter() - t0
    if n_total == 0:
        raise EigenSolveError(f"modal.f_max = {s.f_max}: no mode below this frequency")
    if n_total is not None:                  # before any band: a plan that cannot be solved
        check_mode_count("modal.f_max", s.f_max, n_total, K.getSize()[0], comm)
    bands = plan_for(cache, s, n_total or 0)
    n_bands = len(bands)
    if s.band_only and not 1 <= s.band_only <= n_bands:
        raise EigenSolveError(f"modal.band_only = {s.band_only}: the plan has {n_bands} "
                              f"band(s) below modal.f_max = {s.f_max} Hz (1 .. {n_bands})")
    todo = [b for b in bands if cache.find(b) is None
            and (not s.band_only or b.index == s.band_only)]
    groups = 1 if s.band_only else s.groups
    if comm.size % groups:
        raise EigenSolveError(f"modal.band_groups = {groups} must divide the number of ranks "
                              f"({comm.size})")
    exact: dict[int, int] = {}
    if n_total is None:
        for band in todo:
            exact[band.index] = count_band(K, M, comm, band, cache, s.out_of_core, log,
                                           s.f_max)
    return _SolvePlan(cache, n_total, t_count, bands, todo, groups, exact)


def _solve_planned(K, M, comm, s: BandSettings, plan: _SolvePlan, assemble=None,
                   monitor=None, static_rhs: np.ndarray | None = None, log=None,
                   progress=None
                   ) -> tuple[list[dict], dict[int, BandChecks], np.ndarray | None]:
    """Solve and write the bands ``plan.todo`` (on ``plan.groups`` sub-communicators), each
    recorded in the cache at once with one group. Returns rank 0's records of each group's
    bands, the checks of the bands solved here (:class:`BandChecks`, by index) and the static
    solutions (lowest band, one group). An error on any rank is raised on all (collective).
    """
    from mpi4py import MPI

    cache, n_total, groups, bands, todo = plan.cache, plan.n_total, plan.groups, plan.bands, \
        plan.todo
    n_bands = len(bands)
    done_modes = {"n": sum(min(r.n_modes, _band_estimate(r.band, s.f_max, n_total))
                           for b in bands if (r := cache.find(b)) is not None)}
    color = comm.rank * groups // comm.size
    sub = comm.Split(color, comm.rank) if groups > 1 else comm
    error = None
    records: list[dict] = []
    proven: dict[int, BandChecks] = {}      # the checks of the bands solved here
    static = None
    try:
        Kg, Mg = (K, M) if groups == 1 else assemble(sub)
        for i, band in enumerate(todo):
            if i % groups != color:
                continue
            est = plan.exact.get(band.index) or _band_estimate(band, s.f_max, n_total)

            def band_monitor(nconv, nev, basis, band=band, est=est):
                total = n_total or est
                if monitor is not None:
                    monitor(min(done_modes["n"] + min(nconv, est), total), total, basis,
                            label=f"{band.label(n_bands)}: {nconv}/{nev} converged, "
                                  f"basis {basis}")

            def band_progress(phase, done, total, band=band):
                if progress is not None:
                    progress(f"{band.label(n_bands)}: {phase}", done, total)

            rhs = static_rhs if (groups == 1 and band.shift_hz == 0.0) else None
            if log is not None and groups == 1:
                log(f"{band.label(n_bands)}: factorising K - sigma M at {band.shift_hz:.2f} Hz, "
                    f"then block Lanczos for ~{est} modes ...")
            free_memory(sub)       # (what came before: the heap trimmed, the count's factor)
            rss_before = _total(sub, current_memory_gb())
            own_peak = sub.allreduce(reset_peak_memory(), op=MPI.LAND)
            result, n_below, st = solve_band(Kg, Mg, sub, band, est, s, band_monitor, rhs,
                                             band_progress)
            if rhs is not None:
                static = result.static
            done_modes["n"] += est
            result = _trim(result, band)
            if groups == 1 and result.roundoff_floors is not None:
                proven[band.index] = BandChecks.of(result)
            name = band_file_name(band)
            st["rss_before_gb"] = rss_before
            sha = write_band(s.cache_dir / name, sub, band, result, n_below, st)
            f = result.frequencies_hz
            rec = BandRecord(band, name, n_below, len(f),     # (a band may hold no mode)
                             float(f[0]) if len(f) else band.lo_hz,
                             float(f[-1]) if len(f) else band.hi_hz, st, sha)
            st["rss_band_end_gb"] = _total(sub, current_memory_gb())
            del result, f
            free_memory(sub)
            st.update(band_memory(sub, own_peak))
            if sub.rank == 0:
                records.append(rec.to_json())
            if groups == 1:
                # recorded at once: an interrupted run (a job's time limit, a kill) keeps
                # every band it finished for the rerun (band groups record at the end)
                _record(cache, rec)
                cache.save()
            if log is not None and groups == 1:
                log(band_line(rec, n_bands))
        if groups > 1:
            Kg.destroy()
            Mg.destroy()
    except Exception as exc:                          # reported collectively below
        error = exc
    errors = comm.allgather(None if error is None else
                            (isinstance(error, EigenSolveError), f"{error}"))
    if groups > 1:
        sub.Free()
    failed = [e for e in errors if e is not None]
    if failed:
        if error is not None and not isinstance(error, EigenSolveError):
            raise error
        raise EigenSolveError(failed[0][1]) if failed[0][0] else RuntimeError(failed[0][1])
    return records, proven, static


def _merge_planned(K, M, comm, s: BandSettings, plan: _SolvePlan, static: np.ndarray | None,
                   proven: dict[int, BandChecks], log=None, progress=None,
                   t_start: float = 0.0) -> Eigenpairs:
    """Merge the bands of the plan (:func:`_merge`), with the static solutions, the bands'
    reuse flags and timings, and record the merged chain in the cache (collective)."""
    cache, bands = plan.cache, plan.bands
    n_bands = len(bands)
    if log is not None:
        log(f"merging {n_bands} band(s): {sum(cache.find(b).n_modes for b in bands)} band modes, "
            f"{K.getSize()[0]:,} DOFs (Rayleigh-Ritz with K and M, duplicates, inertia "
            "check) ...")
    t_m = time.perf_counter()
    result = _merge(K, M, comm, bands, cache, s, plan.n_total, progress, proven)
    if log is not None:
        st = result.stats
        log(f"  {len(result.eigenvalues)} modes, {st['n_duplicates']} duplicate(s) dropped, "
            f"max |Phi^T M Phi - I| = {st['max_orthonormality_error']:.1e} (merged in "
            f"{time.perf_counter() - t_m:.1f} s)")
    result.static = static
    computed = {b.index for b in plan.todo}
    for d in result.stats["bands"]:
        d["reused"] = d["index"] not in computed
    result.stats.update(time_count_fmax=plan.t_count,
                        time_bands_total=time.perf_counter() - t_start)
    chain = {"f_hz": float(s.f_max), "bands": [
        {"index": b.index, "lo_hz": b.lo_hz, "hi_hz": b.hi_hz, "shift_hz": b.shift_hz}
        for b in bands]}
    if cache.chain is None or float(cache.chain["f_hz"]) <= s.f_max:
        cache.chain = chain
        cache.save()
    return result


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


#: A multi-band merge keeps the bands' modes as they are (no Rayleigh-Ritz step, no checks
#: afresh: :func:`_merge_as_they_are`) when, each band's own modes taken once, the measured
#: Gram matrices show them M-orthonormal and K-orthogonal as well as that step would make
#: them: :data:`~railvib_hpc.modal.ritz.RAW_RITZ_GRAM` and
#: :data:`~railvib_hpc.modal.ritz.RAW_RITZ_STIFF`, as for a band's own Ritz vectors.


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
