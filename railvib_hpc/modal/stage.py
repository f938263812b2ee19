"""The ``modal`` stage: mesh (reused) -> DOFs -> distributed K, M -> eigensolve -> modes.h5.

It needs the ``mesh`` stage: the runner hands it ``mesh.h5`` built or reused
(``ctx.input("mesh")``) when the modes are computed. It refuses a case without a track,
supported track ends without ``modal.damping = 'full'`` and perfectly matched layers
(:mod:`.refusals`), before anything runs.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..config import Case
from ..constants import BYTES_PER_DOUBLE, BYTES_PER_GB
from ..errors import DataError
from ..io.atomic import ensure_space
from ..io.files import BAND_CACHE, MESH_H5, MODAL_DAMPING_H5, MODES_H5, MODES_XDMF, STATIC_H5
from ..io.formats.bands import check_band_cache, read_index
from ..io.formats.modal_damping import check_modal_damping, write_damping_parts
from ..io.formats.modes import (
    check_eigenvalues,
    check_mode_shapes,
    check_modes,
    has_probe_roles,
    read_strain_energies,
    write_modes,
    write_modes_xdmf,
)
from ..io.formats.static import check_static
from ..io.products import Selection, StageFile
from ..io.stage_outputs import ModesOutput
from ..io.stage_protocol import NotReusable, Stage, StageContext, StageRunner
from ..io.xdmf import ensure_views
from ..log import Reporter
from ..model.boundary import problem_dofmap
from ..model.dofmap import NODE_ARRAY_CHUNK
from ..model.elements import nodal_masses
from ..model.factor import sparse_times_block
from ..model.petsc import assemble
from ..parallel import on_root
from ..problem import RANDOM_FIELD_KEYS, Problem
from ..resources import peak_memory_gb
from ..uncertainty.fields import resolution_warnings
from .eigen import ModalProblem, ModalSolver
from .energy import group_strain_energies
from .projection import project_damping_parts, read_phi_rows
from .refusals import modal_refusals
from .static import rail_load_dofs, residual_mass, solve_static, unit_loads, write_static

if TYPE_CHECKING:
    from mpi4py import MPI


#: Memory budget of the automatic Lanczos basis (all ranks together) [GB]: the basis holds
#: ``3 n_modes`` vectors unless that exceeds this (the thesis model's 300 modes: 1.2 GB).
AUTO_BASIS_BUDGET_GB = 4.0
#: Seconds between two progress lines of the eigensolve.
PROGRESS_INTERVAL_S = 2.0


def _max_basis(case: Case, n_dofs: int) -> int:
    """``modal.max_basis``, or 3 n_modes capped at :data:`AUTO_BASIS_BUDGET_GB` of basis
    vectors (all ranks)."""
    if case["modal.max_basis"] > 0:
        return case["modal.max_basis"]
    cap = int(AUTO_BASIS_BUDGET_GB * BYTES_PER_GB / (BYTES_PER_DOUBLE * n_dofs))
    return max(min(3 * case["modal.n_modes"], cap),
               case["modal.n_modes"] + 3 * case["modal.block_size"])


class EigenProgress:
    """The eigensolve's progress lines on rank 0, at most one per :data:`PROGRESS_INTERVAL_S`.

    Called as the Lanczos monitor (``self(nconv, nev, basis, label=None)``: converged
    modes, percent and ETA of the whole eigensolve) and, through :meth:`phase`, by the
    phases after the expansions (thick restarts, Ritz vectors, purification, Rayleigh-Ritz,
    residual checks, round-off floors, the band merge: their own percent and ETA). Both
    share one clock: no two lines within the interval, but a phase that has printed a line
    also prints its end (100 %), and the monitor its last expansion.
    """

    def __init__(self, rep: Reporter):
        self.rep = rep
        self.t_start = time.perf_counter()
        self.last = -1e9
        self.current: str | None = None     # the phase in progress
        self.t_phase = self.t_start
        self.shown = False                  # the phase has printed a line

    def __call__(self, nconv: int, nev: int, basis: int, label: str | None = None) -> None:
        now = time.perf_counter()
        if now - self.last < PROGRESS_INTERVAL_S and nconv < nev:
            return
        self.last = now
        self.rep.progress(label or f"eigensolve: {nconv}/{nev} modes converged, basis {basis}",
                          max(nconv, 0), nev, self.t_start)

    def phase(self, name: str, done: int, total: int) -> None:
        """``done`` of ``total`` units of the phase ``name`` (a new name starts its clock)."""
        now = time.perf_counter()
        if name != self.current:
            self.current, self.t_phase, self.shown = name, now, False
        finished = done >= total
        if now - self.last < PROGRESS_INTERVAL_S and not (finished and self.shown):
            return
        if finished and not self.shown and now - self.t_phase < PROGRESS_INTERVAL_S:
            return                          # a short phase: no line of its own
        self.last, self.shown = now, True
        self.rep.progress(f"eigensolve, {name} ({done}/{total})", done, total, self.t_phase)
        if finished:
            self.current = None


def compute(ctx: StageContext) -> ModesOutput:
    """``railvib modal``: compute (or reuse) ``modes.h5`` (and ``static.h5``,
    ``modal_damping.h5``) in the output folder (collective; the runner has started PETSc
    and checked the stage's refusals).

    The runner hands it ``mesh.h5`` (built or reused) when the modes are recomputed. The
    summary holds ``reused``, ``n_modes``, ``f_min``, ``f_max`` and the solver statistics.
    """
    old = _reused_modes(ctx)
    if old is not None:
        return old
    summary, freqs, mesh_size = _modal(ctx)
    return ModesOutput.of_summary(summary, freqs, ctx.out_dir,
                                  bool(ctx.case["mbs.static_correction"]), mesh_size)


# ----------------------------------------------------------------------------- products
#: The random fields of the soil layers (the element matrices: ``Problem.fields``); at
#: their defaults (realisation 0: no field) they enter no digest.
RANDOM_FIELDS: Selection = RANDOM_FIELD_KEYS
#: A sample of the reduced model (``uncertainty.basis``: its modes are the reduced model's
#: on the basis's nominal mesh, or a full solve on that mesh; at their defaults, a plain
#: model, they enter no digest).
REDUCED: Selection = (("uncertainty.basis", ()), ("uncertainty.reduced_tol", ()),
                      ("uncertainty.reference", ()))
#: How the modes are computed, not what they are: the out-of-core switch and the band
#: split with its parallel layout (they change the modes by round-off only).
MODAL_SOLVER_LAYOUT = ("out_of_core", "bands", "band_modes", "band_groups", "band_only")
#: The damping settings of [modal] and [pads] (and the materials' ratios): not the modes.
MODAL_DAMPING_KEYS = ("damping_ratio", "damping")
#: Damping settings and the solver layout do not change the modes.
MODAL_ONLY_EXCLUDED = (*MODAL_DAMPING_KEYS, *MODAL_SOLVER_LAYOUT)
#: A band of the band-sliced solve (its cache in ``<out>/bands``) depends on [modal] as the
#: modes do, except on how many modes up to which frequency are wanted and on the basis
#: and shift of an unsliced solve: the band cache's inputs leave them out, so raising
#: ``modal.f_max`` keeps the cache and only adds bands.
BAND_EXTENT = ("f_max", "n_modes", "max_basis", "shift_hz")
#: The modes' case keys (and the static fields') beyond the mesh's (every row here extends
#: ``mesh.h5``'s keys): materials, sections, pads and [modal] less damping and solver
#: layout, the boundary, the random fields.
MODES_KEYS: Selection = (
    ("materials", MODAL_ONLY_EXCLUDED), ("sections", ()), ("pads", MODAL_ONLY_EXCLUDED),
    ("modal", MODAL_ONLY_EXCLUDED), ("boundary", ())) + RANDOM_FIELDS + REDUCED
_BAND_KEYS: Selection = (
    ("materials", MODAL_ONLY_EXCLUDED), ("sections", ()), ("pads", MODAL_ONLY_EXCLUDED),
    ("modal", (*MODAL_ONLY_EXCLUDED, *BAND_EXTENT)), ("boundary", ())) + RANDOM_FIELDS
#: The projected parts of C (``modal.damping = 'full'``): the modes' inputs, the pads'
#: dashpots and [damping] (the ratios only enter when composed, but the whole section is
#: kept for safety). Whether the static fields are projected too is in the file's shape:
#: one with them serves a run without the static correction as well.
_DAMPING_KEYS: Selection = MODES_KEYS + (("pads", ()), ("damping", ()))
#: The products: the modes (and their XDMF view), the static fields, the projected damping,
#: the band cache (:mod:`~railvib_hpc.io.formats.bands`); each depends on the mesh's case
#: keys too (``extends``).
PRODUCTS = (
    StageFile(MODES_H5, "modal", 2, MODES_KEYS, (MESH_H5,), (MODES_XDMF,), ("mesh.file",),
              check=check_modes, extends=(MESH_H5,)),
    StageFile(STATIC_H5, "modal", 2, MODES_KEYS, (MESH_H5, MODES_H5), (), ("mesh.file",),
              check=check_static, extends=(MESH_H5,)),
    StageFile(MODAL_DAMPING_H5, "modal", 2, _DAMPING_KEYS, (MESH_H5, MODES_H5), (),
              ("mesh.file",), check=check_modal_damping, extends=(MESH_H5,)),
    StageFile(BAND_CACHE, "modal", 2, _BAND_KEYS, (), (), ("mesh.file",),
              check=check_band_cache, extends=(MESH_H5,)),
)

STAGE = Stage(name="modal", help="assemble K, M and extract mass-normalised modes",
              products=PRODUCTS, reads=(MESH_H5,), compute=compute, petsc=True,
              needs=("mesh",), refuse=modal_refusals)


def _mesh(ctx: StageContext):
    """The mesh and the digest of ``mesh.h5``, from the runner (``ctx.input("mesh")``: built
    or reused), on every rank (collective)."""
    def load():
        given = ctx.input("mesh")
        return given.value, given.sha256

    return on_root(load, ctx.comm)


def run_modal_stage(case: Case, out_dir: Path, comm: MPI.Comm, rep: Reporter,
                    petsc_options: list[str] | None = None) -> dict:
    """The ``modal`` stage from a script: :data:`STAGE` through the runner (the folder's
    lock, PETSc started with ``petsc_options``; no ``run.json`` entry). Returns its summary
    (``reused``, ``n_modes``, ``f_min``, ``f_max`` and the solver statistics)."""
    runner = StageRunner(out_dir, comm, rep, petsc_options or (), command="modal")
    return dict(runner.run(STAGE, case, record=False).result.summary)


def _reused_modes(ctx: StageContext) -> ModesOutput | None:
    """Current modes (and their static fields and projected damping, recomputed when only
    those are stale), or None when the modes are to be recomputed (collective)."""
    case, out_dir, comm, rep = ctx.case, ctx.out_dir, ctx.comm, ctx.rep
    path = out_dir / MODES_H5
    want_static = bool(case["mbs.static_correction"])

    def read(verdict):
        if case["modal.damping"] == "strain_energy" and read_strain_energies(path) is None:
            raise NotReusable("it has no per-material strain energies (modal.damping = "
                              "'strain_energy' needs them)")
        if not has_probe_roles(path):
            raise NotReusable("it has no probe roles (written by an older version)")
        with h5py_file(path) as f:
            hexes = f.get("mesh/hexes")
            return (f["modes/frequency_hz"][()], str(f.attrs.get("stats", "{}")),
                    (int(f["mesh/points"].shape[0]),
                     int(hexes.shape[0]) if hexes is not None else None))

    def previous():
        old = ctx.reuse(MODES_H5, path=path, why="same model and modal settings",
                        detail=lambda v: f"{len(v[0])} modes, {v[0][0]:.3f} - "
                                         f"{v[0][-1]:.3f} Hz", accept=read)
        return (*old.value, old.sha256) if old.ok else None

    old = on_root(previous, comm)
    if old is None:
        return None
    f, stats, mesh_size, modes_sha = old
    xdmf = path.with_suffix(".xdmf")
    if on_root(lambda: ensure_views(xdmf, lambda: write_modes_xdmf(path)), comm):
        rep.info(f"rewrote {xdmf} (per-step views for both ParaView XDMF readers)")
    if want_static and not on_root(lambda: ctx.reuse(STATIC_H5, discard=False).ok, comm):
        _static_only(ctx, modes_sha)
    if case["modal.damping"] == "full":
        def projected(verdict) -> None:
            if want_static and damping_size(ctx.path(MODAL_DAMPING_H5)) <= len(f):
                raise NotReusable("it holds the modes only (mbs.static_correction = true "
                                  "needs the static fields projected too)")

        if not on_root(lambda: ctx.reuse(MODAL_DAMPING_H5, accept=projected,
                                         discard=False).ok, comm):
            _damping_only(ctx, modes_sha, len(f))
    summary = {"reused": True, "n_modes": len(f), "f_min": float(f[0]), "f_max": float(f[-1]),
               **json.loads(stats)}
    return ModesOutput.of_summary(summary, f, out_dir, want_static, mesh_size)


def _element_sizes(mesh, problem: Problem) -> dict[str, tuple[float, float]]:
    """The largest horizontal and vertical extent of the hexahedra of every soil part with
    a random field [m]."""
    from ..schema import PART_ID

    out = {}
    for part in {f.part for f in problem.fields}:
        x = mesh.points[mesh.hexes[mesh.hex_part == PART_ID[part]]]
        if len(x):
            ext = x.max(axis=1) - x.min(axis=1)
            out[part] = (float(ext[:, :2].max()), float(ext[:, 2].max()))
    return out


def _modal(ctx: StageContext) -> tuple[dict, np.ndarray, tuple[int, int] | None]:
    """Mesh, DOFs, K and M, the eigensolve and the files written from it (collective);
    returns the summary, the frequencies and the mesh size (nodes, hexahedra; None with
    ``modal.band_only``)."""
    case, out_dir, comm, rep = ctx.case, ctx.out_dir, ctx.comm, ctx.rep
    problem = Problem.from_case(case)
    path = out_dir / MODES_H5
    static_path = out_dir / STATIC_H5
    want_static = bool(case["mbs.static_correction"])
    want_damping = case["modal.damping"] == "full"
    damping_path = out_dir / MODAL_DAMPING_H5
    rom_path = case.resolve(case["uncertainty.basis"]) if case["uncertainty.basis"] else None
    with rep.stage("mesh (load/build + broadcast)"):
        if rom_path is None:
            mesh, mesh_sha = _mesh(ctx)
        else:                 # a reduced-model sample: the nominal mesh the basis lives on
            mesh, mesh_sha = on_root(lambda: _basis_mesh(rom_path), comm)
    if problem.fields:
        for warning in resolution_warnings(problem.fields, _element_sizes(mesh, problem)):
            rep.info(f"WARNING: {warning}")
    t0 = time.perf_counter()
    with rep.stage("dofs"):
        dofmap = problem_dofmap(mesh, problem, comm.size)
        rep.info(f"  {mesh.n_nodes} nodes, {dofmap.n_dofs} free DOFs on {comm.size} rank(s)")
    on_root(lambda: _check_space(case, out_dir, mesh, dofmap, want_static), comm)
    with rep.stage("assembly"):
        K, M, ainfo = assemble(mesh, problem, dofmap, comm)
        problem = _with_track_ends(ctx, mesh, dofmap, problem, K, M)
    t_assembly = time.perf_counter() - t0
    static_rhs = None
    if want_static:
        load_dofs, table = rail_load_dofs(mesh, dofmap)
        static_rhs, free = unit_loads(load_dofs, *dofmap.owned_dofs(comm.rank))
    reduced = None
    if rom_path is not None:
        with rep.stage("reduced model"):
            reduced = _reduced_sample(case, problem, rom_path, dofmap, comm, K, M, rep)
    if reduced is not None and reduced.get("eigenpairs") is not None:
        result = reduced.pop("eigenpairs")
    else:
        result = _full_eigensolve(ctx, mesh, problem, dofmap, K, M, static_rhs)
    if reduced is not None and result is not None:
        reduced.pop("eigenpairs", None)
        result.stats["reduced"] = _compare(reduced, result)
    if result is None:                                   # modal.band_only: one band cached
        K.destroy()
        M.destroy()
        rep.info(f"band {case['modal.band_only']} written to {out_dir / 'bands'}; run with "
                 "modal.band_only = 0 to merge the bands into modes.h5")
        return {"reused": False, "band_only": case["modal.band_only"], "n_modes": 0}, [], None
    for warning in result.warnings:
        rep.info(f"WARNING: {warning}")
    if result.stats.get("out_of_core"):
        rep.info(f"  MUMPS out of core (factor on disk): in-core estimate "
                 f"{result.stats['factor_memory_in_core_gb']:.1f} GB, out of core "
                 f"{result.stats['factor_memory_gb']:.1f} GB (modal.out_of_core = "
                 f"'{case['modal.out_of_core']}')")
    with rep.stage("strain energies"):
        energies = group_strain_energies(mesh, problem, dofmap, comm, result.phi)
    x_static = result.static
    x_mass = None
    if want_static:
        if x_static is None:
            with rep.stage("static solves"):
                x_static = solve_static(K, M, comm, static_rhs)
        x_def, x_mass = residual_mass(M, result.phi, x_static, free, load_dofs.size, comm)
    parts = None
    if want_damping:
        with rep.stage("projected damping"):
            basis = result.phi if not want_static else np.hstack([result.phi, x_def])
            parts = project_damping_parts(mesh, problem, dofmap, comm, K, basis)
    if want_static:
        del x_def
    K.destroy()
    M.destroy()
    with rep.stage("write modes"):
        translation, rotation, rot_nodes, rot_range, nodes = dofmap.node_arrays(result.phi,
                                                                                 comm.rank)
        result.phi = None           # the node arrays hold the modes now (n x m doubles freed)
        mask = np.zeros(mesh.n_nodes, dtype=bool)
        mask[nodes] = True
        masses = nodal_masses(mesh, problem, mask)[nodes]
        _check_modes_before_writing(comm, result.eigenvalues, translation, masses, path)
        stats = dict(result.stats)
        stats["convergence_warnings"] = list(result.warnings)
        stats.update({"assembly_" + k: v for k, v in ainfo.items()})
        stats["time_assembly_total"] = t_assembly
        rss = comm.allgather(peak_memory_gb())
        stats["peak_rss_gb_per_rank"] = rss
        stats["peak_rss_gb_total"] = float(sum(rss))
        stats["n_dofs"] = dofmap.n_dofs
        stats["ranks"] = comm.size
        # rank 0's (timings differ per rank): parallel HDF5 needs identical attributes
        stats = comm.bcast(stats, root=0)
        attrs = on_root(lambda: ctx.provenance(MODES_H5, {MESH_H5: mesh_sha}), comm)
        attrs.update({"petsc_version": _versions()[0], "slepc_version": _versions()[1],
                      "stats": json.dumps(stats), "n_dofs": dofmap.n_dofs})
        modes_sha = write_modes(path, comm, mesh, nodes, result.eigenvalues, translation,
                                rotation, rot_nodes, rot_range, masses, dofmap.index, attrs,
                                pad_table(mesh, case), energies)
    f = result.frequencies_hz
    summary = {"reused": False, "n_modes": len(f), "f_min": float(f[0]), "f_max": float(f[-1]),
               **stats}
    rep.info(f"{len(f)} modes, {f[0]:.3f} - {f[-1]:.3f} Hz; max |Phi^T M Phi - I| = "
             f"{stats['max_orthonormality_error']:.2e}, max relative residual "
             f"{stats['max_relative_residual']:.2e}; {stats['linear_solves']} right-hand sides "
             f"solved; peak memory {stats['peak_rss_gb_total']:.2f} GB (all ranks)")
    rep.info(f"wrote {path} and {path.with_suffix('.xdmf')}")
    if parts is not None:
        _write_damping(ctx, parts, mesh_sha, modes_sha)
        rep.info(f"wrote {damping_path}: Phi^T C Phi of the dashpots, pads and materials "
                 "(modal.damping = 'full')")
    if want_static:
        with rep.stage("write static.h5"):
            sattrs = on_root(lambda: ctx.provenance(STATIC_H5, {MESH_H5: mesh_sha,
                                                                  MODES_H5: modes_sha}), comm)
            on_root(lambda: ctx.discard(static_path), comm)
            write_static(static_path, comm, mesh, dofmap, x_static, free, load_dofs, table,
                         sattrs, x_mass)
        rep.info(f"wrote {static_path}: static solutions for {free.size} unit loads on the "
                 "rail DOFs (static correction)")
    return summary, f, (int(mesh.n_nodes), len(mesh.hexes))


#: PETSc options prefix of the static solve that fits the supported track ends' springs.
TRACK_ENDS_PREFIX = "railvib_eig_ends_"


def _with_track_ends(ctx: StageContext, mesh, dofmap, problem: Problem, K, M) -> Problem:
    """The problem with the supported track ends' fitted springs, added to K
    (:func:`~.petsc.fit_track_ends`, shared with the full-order path; its line goes to the
    log). Rigid ends: ``problem`` unchanged (collective)."""
    from ..errors import UserError
    from ..model.petsc import fit_track_ends

    try:
        problem, line = fit_track_ends(mesh, dofmap, problem, K, M, ctx.comm,
                                       TRACK_ENDS_PREFIX)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if line:
        ctx.rep.info(line)
    return problem


def _full_eigensolve(ctx: StageContext, mesh, problem: Problem, dofmap, K, M, static_rhs):
    """The full eigensolve of K, M (SLEPc or block Lanczos, ``[modal]``), collective."""
    case, comm, rep = ctx.case, ctx.comm, ctx.rep
    with rep.stage("eigensolve"):
        progress = EigenProgress(rep)
        eigenproblem = ModalProblem(
            K, M, comm, n_modes=case["modal.n_modes"], f_max=case["modal.f_max"],
            shift_hz=case["modal.shift_hz"], static_rhs=static_rhs,
            assemble=lambda sub: assemble(
                mesh, problem, problem_dofmap(mesh, problem, sub.size), sub)[:2])
        solver = ModalSolver(
            method=case["modal.method"], tol=case["modal.tol"],
            max_it=case["modal.max_restarts"], block_size=case["modal.block_size"],
            max_basis=_max_basis(case, dofmap.n_dofs), out_of_core=case["modal.out_of_core"],
            bands=band_settings(ctx), monitor=progress, log=rep.info, progress=progress.phase)
        return solver.solve(eigenproblem)


def _basis_mesh(rom_path: Path):
    """The nominal mesh a reduced basis lives on and its content digest (rank 0)."""
    import h5py

    from ..errors import CaseError
    from ..mesh.mesh_io import read_mesh_h5

    if not rom_path.exists():
        raise CaseError([("uncertainty.basis", str(rom_path), "no such reduced basis (it "
                          "is written by railvib study uncertainty with uncertainty.model "
                          "= 'reduced')")])
    with h5py.File(rom_path, "r") as f:
        sha = str(f.attrs["mesh_sha256"])
    return read_mesh_h5(rom_path.parent / MESH_H5)[0], sha


def _reduced_sample(case: Case, problem: Problem, rom_path: Path, dofmap, comm, K, M,
                    rep: Reporter) -> dict:
    """The reduced eigenpairs of a sample, accepted (``eigenpairs``) when every relative
    residual is at most ``uncertainty.reduced_tol`` and the case is no reference solve
    (``uncertainty.reference``); else the reason for the full solve (collective)."""
    from .reduced import read_basis, reduced_modes
    from .ritz import Eigenpairs

    rom = read_basis(rom_path, dofmap, comm.rank)
    red = reduced_modes(rom, problem, comm, K, M, case["modal.n_modes"])
    tol = case["uncertainty.reduced_tol"]
    worst = float(red["residuals"].max())
    info = {"projection": red["projection"], "size": red["size"],
            "seconds": red["seconds"], "tol": tol, "max_residual": worst,
            "residuals": red["residuals"].tolist(), "factors": red["factors"],
            "frequencies_hz": (np.sqrt(np.maximum(red["eigenvalues"], 0.0))
                               / (2 * np.pi)).tolist()}
    rep.info(f"  reduced model: {red['size']} basis vectors ({red['projection']}), "
             f"max relative residual {worst:.2e} (tolerance {tol:g}), {red['seconds']:.2f} s")
    if case["uncertainty.reference"]:
        info.update(used=False, reason="reference sample: full eigensolve to compare")
    elif worst > tol:
        why = (f"max relative residual {worst:.3g} > uncertainty.reduced_tol = {tol:g}"
               + ("; the random field is not represented by the reduced basis"
                  if problem.fields else ""))
        rep.info(f"  reduced model rejected ({why}): full eigensolve")
        info.update(used=False, reason=why)
    else:
        mp = sparse_times_block(M, red["phi"], comm)
        gram = red["phi"].T @ mp
        gram = comm.allreduce(gram)
        ortho = float(np.abs(gram - np.eye(len(gram))).max())
        info.update(used=True, reason="")
        info["eigenpairs"] = Eigenpairs(
            eigenvalues=red["eigenvalues"], phi=red["phi"], residuals=red["residuals"],
            stats={"method": "reduced", "max_orthonormality_error": ortho,
                   "max_relative_residual": worst, "linear_solves": 0,
                   "time_solve": red["seconds"], "reduced_basis_size": red["size"]})
    return info


def _compare(reduced: dict, result) -> dict:
    """The reduced model's record for the modes' stats: with the full eigensolve's
    frequencies (a fallback or reference sample) the relative error of each frequency."""
    out = dict(reduced)
    if not reduced["used"]:
        f_full = result.frequencies_hz
        f_red = np.asarray(reduced["frequencies_hz"])
        n = min(len(f_full), len(f_red))
        out["full_frequencies_hz"] = f_full.tolist()
        out["frequency_errors"] = (np.abs(f_red[:n] - f_full[:n]) / f_full[:n]).tolist()
    return out


def band_settings(ctx: StageContext):
    """The band-sliced solve's settings (``modal.f_max`` with block Lanczos), else None;
    with the band cache (:data:`~railvib_hpc.io.files.BAND_CACHE`, a product of this
    stage) as the product layer judged it (collective)."""
    from .band_solve import BandSettings

    md = ctx.case["modal"]
    if md["f_max"] <= 0 or md["method"] != "block_lanczos":
        return None
    index, prov = on_root(lambda: _band_cache(ctx), ctx.comm)
    return BandSettings(f_max=md["f_max"], edges=list(md["bands"]),
                        band_modes=md["band_modes"], groups=md["band_groups"],
                        band_only=md["band_only"], tol=md["tol"],
                        block_size=md["block_size"], max_restarts=md["max_restarts"],
                        out_of_core=md["out_of_core"], cache_dir=ctx.path(BAND_CACHE).parent,
                        index=index, provenance=prov)


def _band_cache(ctx: StageContext) -> tuple[dict | None, dict]:
    """The band cache's index when it is current and sound (``reusing ...``; else
    ``recomputing ...: <reason>`` and None), and the provenance its index is written with
    (rank 0)."""
    path = ctx.path(BAND_CACHE)
    old = ctx.reuse(BAND_CACHE, why="same model and solver settings",
                    detail=lambda index: f"{len(index['bands'])} band(s) solved",
                    accept=lambda verdict: read_index(path))
    return old.value, ctx.provenance(BAND_CACHE, {})


def _check_space(case: Case, out_dir: Path, mesh, dofmap, want_static: bool) -> None:
    """Before the eigensolve: room for ``modes.h5`` (and ``static.h5``)? (rank 0)"""
    n, nr = mesh.n_nodes, int(np.count_nonzero(dofmap.has_rotations))
    m = case["modal.n_modes"]
    size = BYTES_PER_DOUBLE * (m * (n + nr) * 3 + 11 * n + mesh.hexes.size + mesh.lines.size)
    what = f"modes.h5 ({m} modes)"
    if want_static:
        size += BYTES_PER_DOUBLE * 4 * mesh.rail_nodes().size * n * 3
        what += " and static.h5"
    ensure_space(out_dir, size, what)


def h5py_file(path: Path):
    """``h5py.File(path, "r")`` (imported lazily)."""
    import h5py

    return h5py.File(path, "r")


def _check_modes_before_writing(comm: MPI.Comm, eigenvalues, translation, masses,
                                path: Path) -> None:
    """The data checks of ``modes.h5`` on the computed arrays (collective): a NaN or an
    implausible mode never reaches the file."""
    problems = check_eigenvalues(eigenvalues)
    for j in range(0, translation.shape[0], NODE_ARRAY_CHUNK):    # temporaries: a chunk's
        problems += check_mode_shapes(translation[j:j + NODE_ARRAY_CHUNK], masses, first=j)
        if problems:
            break
    everywhere = [p for ps in comm.allgather(problems) for p in ps]
    if everywhere:
        raise DataError(f"the computed modes fail their data checks ({everywhere[0]}); "
                        f"{path} was not written. Check the material values and supports")


def _static_only(ctx: StageContext, modes_sha: str) -> None:
    """static.h5 for reused modes: assemble K again and factor it once."""
    case, out_dir, comm, rep = ctx.case, ctx.out_dir, ctx.comm, ctx.rep
    problem = Problem.from_case(case)
    with rep.stage("static correction: mesh + assembly"):
        mesh, mesh_sha = _mesh(ctx)
        dofmap = problem_dofmap(mesh, problem, comm.size)
        K, M, _ = assemble(mesh, problem, dofmap, comm)
        problem = _with_track_ends(ctx, mesh, dofmap, problem, K, M)
    load_dofs, table = rail_load_dofs(mesh, dofmap)
    rhs, free = unit_loads(load_dofs, *dofmap.owned_dofs(comm.rank))
    with rep.stage("static solves"):
        try:
            x_static = solve_static(K, M, comm, rhs)
            phi = read_phi_rows(out_dir / MODES_H5, dofmap, comm.rank, None)
            x_mass = residual_mass(M, phi, x_static, free, load_dofs.size, comm)[1]
            del phi
        finally:
            K.destroy()
            M.destroy()
    static_path = out_dir / STATIC_H5
    with rep.stage("write static.h5"):
        attrs = on_root(lambda: ctx.provenance(STATIC_H5, {MESH_H5: mesh_sha,
                                                             MODES_H5: modes_sha}), comm)
        on_root(lambda: ctx.discard(static_path), comm)
        write_static(static_path, comm, mesh, dofmap, x_static, free, load_dofs, table, attrs,
                     x_mass)
    rep.info(f"wrote {static_path}: static solutions for {free.size} unit loads on the "
             "rail DOFs (static correction)")


def damping_size(path: Path) -> int:
    """Size of the basis ``modal_damping.h5`` is projected on (modes, + static fields)."""
    with h5py_file(path) as f:
        return int(f["dashpots"].shape[0])


def _write_damping(ctx: StageContext, parts: dict, mesh_sha: str, modes_sha: str) -> None:
    """Write ``modal_damping.h5`` on rank 0 (a stage file: provenance, checked, atomic)."""
    path = ctx.path(MODAL_DAMPING_H5)

    def write() -> None:
        ctx.discard(path)
        write_damping_parts(path, parts, ctx.provenance(MODAL_DAMPING_H5,
                                                        {MESH_H5: mesh_sha,
                                                         MODES_H5: modes_sha}))

    on_root(write, ctx.comm)


def _damping_only(ctx: StageContext, modes_sha: str, m: int) -> None:
    """modal_damping.h5 for reused modes: assemble again, read the modes' rows, project."""
    case, out_dir, comm, rep = ctx.case, ctx.out_dir, ctx.comm, ctx.rep
    problem = Problem.from_case(case)
    with rep.stage("projected damping (reused modes)"):
        mesh, mesh_sha = _mesh(ctx)
        dofmap = problem_dofmap(mesh, problem, comm.size)
        want_static = bool(case["mbs.static_correction"])
        # (the supported track ends' fit needs M for its factor's memory check)
        K, M, _ = assemble(mesh, problem, dofmap, comm,
                           mass=want_static or problem.track_ends.supported)
        problem = _with_track_ends(ctx, mesh, dofmap, problem, K, M)
        phi = read_phi_rows(out_dir / MODES_H5, dofmap, comm.rank, m)
        if want_static:           # the residual vectors' rows too (their rotations included)
            load_dofs, _ = rail_load_dofs(mesh, dofmap)
            rhs, free = unit_loads(load_dofs, *dofmap.owned_dofs(comm.rank))
            x_def = residual_mass(M, phi, solve_static(K, M, comm, rhs), free,
                                  load_dofs.size, comm)[0]
            phi = np.hstack([phi, x_def])
        if M is not None:
            M.destroy()
        parts = project_damping_parts(mesh, problem, dofmap, comm, K, phi)
        K.destroy()
    _write_damping(ctx, parts, mesh_sha, modes_sha)
    rep.info(f"wrote {out_dir / MODAL_DAMPING_H5} (modal.damping = 'full')")


def pad_table(mesh, case: Case) -> dict[str, np.ndarray]:
    """Rail-pad spring-dampers: node pairs, direction, stiffness and damping."""
    from ..schema import PART_ID

    rows = []
    for d, (name, k, c) in enumerate((("pad_x", "kx", "cx"), ("pad_y", "ky", "cy"),
                                      ("pad_z", "kz", "cz"))):
        conn = mesh.lines[mesh.line_part == PART_ID[name]]
        rows.append((conn, np.full(len(conn), d), np.full(len(conn), case[f"pads.{k}"]),
                     np.full(len(conn), case[f"pads.{c}"])))
    return {"nodes": np.concatenate([r[0] for r in rows]).reshape(-1, 2).astype(np.int64),
            "direction": np.concatenate([r[1] for r in rows]).astype(np.int8),
            "stiffness": np.concatenate([r[2] for r in rows]).astype(float),
            "damping": np.concatenate([r[3] for r in rows]).astype(float)}


def _versions() -> tuple[str, str]:
    from petsc4py import PETSc
    from slepc4py import SLEPc

    return (".".join(map(str, PETSc.Sys.getVersion())),
            ".".join(map(str, SLEPc.Sys.getVersion())))
