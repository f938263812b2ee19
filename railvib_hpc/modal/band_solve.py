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
   :data:`~.band_cache.DUPLICATE_GRAM`) and makes all modes M-orthonormal together; the
   eigenvalues below ``f_max`` are kept and counted against the inertia of every stretch between two
   counted points (:func:`railvib_hpc.modal.bands.check_counts`). Bands solved in this run
   need less: their modes as they are when the measured Gram matrices allow, else the
   step on the coupled pairs only, else the full step (:mod:`.band_merge`).

Cache: ``<out>/bands`` (:mod:`railvib_hpc.io.formats.bands`: its layout, writer, reader
and check) records the bands, the inertia counts and the merged chain
(:mod:`.band_cache`: the records, the cache and the settings). It is a product of
the modal stage: the stage reuses it through the product layer (its inputs digest leaves
out ``f_max`` and the band split) and gives its index and provenance in
:class:`BandSettings`; a run reuses every band of its plan, and a higher ``f_max`` only
adds bands above the old one.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..io.formats.bands import band_file_name, write_band
from ..resources import current_memory_gb, peak_memory_gb, release_memory, reset_peak_memory
from .band_cache import (
    BASIS_FACTOR,
    EDGE_MARGIN,
    EDGE_OVERLAP,
    MAX_MODE_SHARE,
    SHIFT_NUDGE,
    BandCache,
    BandRecord,
    BandSettings,
)
from .band_merge import BandChecks, _merge
from .bands import Band, hz, omega2, plan_bands
from .ritz import (
    PREFIX,
    RETRY_TOL_FACTOR,
    Eigenpairs,
    EigenSolveError,
    hopeless,
    in_window,
    purified_modes,
)


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
