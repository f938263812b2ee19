"""The ``modal`` stage: mesh (reused) -> DOFs -> distributed K, M -> eigensolve -> modes.h5."""

from __future__ import annotations

import json
import resource
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .. import __version__
from ..config import Case
from ..constants import BYTES_PER_DOUBLE, BYTES_PER_GB
from ..io.modes_io import (
    has_probe_roles,
    read_modes_summary,
    read_strain_energies,
    write_modes,
    write_modes_xdmf,
)
from ..io.xdmf import ensure_views
from ..log import Reporter
from ..mesh.stage import MESH_INPUTS, run_mesh_stage
from ..parallel import on_root
from .dofmap import build_dofmap
from .eigen import solve_modes
from .elements import nodal_masses
from .energy import group_strain_energies
from .petsc import assemble
from .static import rail_load_dofs, solve_static, static_is_valid, unit_loads, write_static

if TYPE_CHECKING:
    from mpi4py import MPI

#: Keys of [modal] and of each material that do not change the modes (not in the reuse key);
#: the band split and its parallel layout change them by round-off only.
_NOT_MODAL_INPUTS = ("damping_ratio", "damping", "out_of_core", "bands", "band_modes",
                     "band_groups", "band_only")


def modal_digest(case: Case) -> str:
    """Hash of everything the modes depend on (damping settings excluded, so changing them
    reuses the modes)."""
    import hashlib

    modal = {k: v for k, v in case["modal"].items() if k not in _NOT_MODAL_INPUTS}
    physics = case.digest("materials", "sections", "pads", exclude=_NOT_MODAL_INPUTS)
    text = json.dumps({"mesh": case.digest(*MESH_INPUTS), "physics": physics,
                       "modal": modal}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


#: Memory budget of the automatic Lanczos basis (all ranks together) [GB]: the basis holds
#: ``3 n_modes`` vectors unless that exceeds this (the thesis model's 300 modes: 1.2 GB).
AUTO_BASIS_BUDGET_GB = 4.0
#: Seconds between two progress lines of the eigensolve.
PROGRESS_INTERVAL_S = 2.0
#: ``ru_maxrss`` is in kB on Linux: kB per GB.
KB_PER_GB = 1e6


def _max_basis(case: Case, n_dofs: int) -> int:
    """``modal.max_basis``, or 3 n_modes capped at :data:`AUTO_BASIS_BUDGET_GB` of basis
    vectors (all ranks)."""
    if case["modal.max_basis"] > 0:
        return case["modal.max_basis"]
    cap = int(AUTO_BASIS_BUDGET_GB * BYTES_PER_GB / (BYTES_PER_DOUBLE * n_dofs))
    return max(min(3 * case["modal.n_modes"], cap),
               case["modal.n_modes"] + 3 * case["modal.block_size"])


def _progress(rep: Reporter):
    t_start = time.perf_counter()
    state = {"last": -1e9}

    def monitor(nconv: int, nev: int, basis: int, label: str | None = None) -> None:
        now = time.perf_counter()
        if now - state["last"] < PROGRESS_INTERVAL_S and nconv < nev:
            return
        state["last"] = now
        rep.progress(label or f"eigensolve: {nconv}/{nev} modes converged, basis {basis}",
                     max(nconv, 0), nev, t_start)

    return monitor


def run_modal_stage(case: Case, out_dir: Path, comm: MPI.Comm, rep: Reporter) -> dict:
    """Compute (or reuse) ``modes.h5`` in ``out_dir``; collective. Returns a summary dict."""
    key = modal_digest(case)
    path = out_dir / "modes.h5"

    def previous():
        if not path.exists():
            return None
        summary = read_modes_summary(path)
        if summary is None:
            rep.info(f"ignoring incomplete or unreadable {path}; recomputing")
            return None
        if summary.get("inputs_sha256") != key:
            return None
        if case["modal.damping"] == "strain_energy" and read_strain_energies(path) is None:
            rep.info(f"{path} has no per-material strain energies (modal.damping = "
                     "'strain_energy' needs them); recomputing")
            return None
        if not has_probe_roles(path):
            rep.info(f"{path} has no probe roles (written by an older version); recomputing")
            return None
        return summary

    old = on_root(previous, comm)
    want_static = bool(case["mbs.static_correction"])
    static_path = out_dir / "static.h5"
    if old is not None:
        f = old["frequency_hz"]
        rep.info(f"reusing {path} (same model and modal settings): {len(f)} modes, "
                 f"{f[0]:.3f} - {f[-1]:.3f} Hz")
        xdmf = path.with_suffix(".xdmf")
        if on_root(lambda: ensure_views(xdmf, lambda: write_modes_xdmf(path)), comm):
            rep.info(f"rewrote {xdmf} (per-step views for both ParaView XDMF readers)")
        if want_static and not on_root(lambda: static_is_valid(static_path, key), comm):
            _static_only(case, out_dir, comm, rep, key)
        return {"reused": True, "n_modes": len(f), "f_min": float(f[0]), "f_max": float(f[-1]),
                **json.loads(old.get("stats", "{}"))}

    with rep.stage("mesh (load/build + broadcast)"):
        mesh = on_root(lambda: run_mesh_stage(case, out_dir, rep)[0], comm)
    t0 = time.perf_counter()
    with rep.stage("dofs"):
        dofmap = build_dofmap(mesh, comm.size, case["modal.fix_sleeper_rotations"],
                              case["modal.fix_rail_rotations_at_pads"])
        rep.info(f"  {mesh.n_nodes} nodes, {dofmap.n_dofs} free DOFs on {comm.size} rank(s)")
    with rep.stage("assembly"):
        K, M, ainfo = assemble(mesh, case, dofmap, comm)
    t_assembly = time.perf_counter() - t0
    static_rhs = None
    if want_static:
        load_dofs, table = rail_load_dofs(mesh, dofmap)
        static_rhs, free = unit_loads(load_dofs, *dofmap.owned_dofs(comm.rank))
    with rep.stage("eigensolve"):
        result = solve_modes(
            K, M, comm, n_modes=case["modal.n_modes"], f_max=case["modal.f_max"],
            shift_hz=case["modal.shift_hz"], tol=case["modal.tol"],
            max_it=case["modal.max_restarts"], method=case["modal.method"],
            block_size=case["modal.block_size"],
            max_basis=_max_basis(case, dofmap.n_dofs), monitor=_progress(rep),
            static_rhs=static_rhs, out_of_core=case["modal.out_of_core"],
            bands=band_settings(case, out_dir), assemble=lambda sub: assemble(
                mesh, case, build_dofmap(mesh, sub.size, case["modal.fix_sleeper_rotations"],
                                         case["modal.fix_rail_rotations_at_pads"]), sub)[:2])
    if result is None:                                   # modal.band_only: one band cached
        K.destroy()
        M.destroy()
        rep.info(f"band {case['modal.band_only']} written to {out_dir / 'bands'}; run with "
                 "modal.band_only = 0 to merge the bands into modes.h5")
        return {"reused": False, "band_only": case["modal.band_only"], "n_modes": 0}
    for warning in result.warnings:
        rep.info(f"WARNING: {warning}")
    if result.stats.get("out_of_core"):
        rep.info(f"  MUMPS out of core (factor on disk): in-core estimate "
                 f"{result.stats['factor_memory_in_core_gb']:.1f} GB, out of core "
                 f"{result.stats['factor_memory_gb']:.1f} GB (modal.out_of_core = "
                 f"'{case['modal.out_of_core']}')")
    with rep.stage("strain energies"):
        energies = group_strain_energies(mesh, case, dofmap, comm, result.phi)
    x_static = result.static
    if want_static and x_static is None:
        with rep.stage("static solves"):
            x_static = solve_static(K, M, comm, static_rhs)
    K.destroy()
    M.destroy()
    with rep.stage("write modes"):
        translation, rotation, rot_nodes, rot_range, nodes = dofmap.node_arrays(result.phi,
                                                                                 comm.rank)
        mask = np.zeros(mesh.n_nodes, dtype=bool)
        mask[nodes] = True
        masses = nodal_masses(mesh, case, mask)[nodes]
        stats = dict(result.stats)
        stats["convergence_warnings"] = list(result.warnings)
        stats.update({"assembly_" + k: v for k, v in ainfo.items()})
        stats["time_assembly_total"] = t_assembly
        rss = comm.allgather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / KB_PER_GB)
        stats["peak_rss_gb_per_rank"] = rss
        stats["peak_rss_gb_total"] = float(sum(rss))
        stats["n_dofs"] = dofmap.n_dofs
        stats["ranks"] = comm.size
        # rank 0's (timings differ per rank): parallel HDF5 needs identical attributes
        stats = comm.bcast(stats, root=0)
        attrs = {"inputs_sha256": key, "case_toml": case.to_toml(), "railvib_version": __version__,
                 "petsc_version": _versions()[0], "slepc_version": _versions()[1],
                 "stats": json.dumps(stats), "n_dofs": dofmap.n_dofs}
        write_modes(path, comm, mesh, nodes, result.eigenvalues, translation, rotation,
                    rot_nodes, rot_range, masses, dofmap.index, attrs, pad_table(mesh, case),
                    energies)
    f = result.frequencies_hz
    summary = {"reused": False, "n_modes": len(f), "f_min": float(f[0]), "f_max": float(f[-1]),
               **stats}
    rep.info(f"{len(f)} modes, {f[0]:.3f} - {f[-1]:.3f} Hz; max |Phi^T M Phi - I| = "
             f"{stats['max_orthonormality_error']:.2e}, max relative residual "
             f"{stats['max_relative_residual']:.2e}; {stats['linear_solves']} right-hand sides "
             f"solved; peak memory {stats['peak_rss_gb_total']:.2f} GB (all ranks)")
    rep.info(f"wrote {path} and {path.with_suffix('.xdmf')}")
    if want_static:
        with rep.stage("write static.h5"):
            write_static(static_path, comm, mesh, dofmap, x_static, free, load_dofs, table, key)
        rep.info(f"wrote {static_path}: static solutions for {free.size} unit loads on the "
                 "rail DOFs (static correction)")
    return summary


def band_settings(case: Case, out_dir: Path):
    """The band-sliced solve's settings (``modal.f_max`` with block Lanczos), else None."""
    from .band_solve import BandSettings, cache_key

    md = case["modal"]
    if md["f_max"] <= 0 or md["method"] != "block_lanczos":
        return None
    return BandSettings(f_max=md["f_max"], edges=list(md["bands"]),
                        band_modes=md["band_modes"], groups=md["band_groups"],
                        band_only=md["band_only"], tol=md["tol"],
                        block_size=md["block_size"], max_restarts=md["max_restarts"],
                        out_of_core=md["out_of_core"], cache_dir=out_dir / "bands",
                        key=cache_key(case))


def _static_only(case: Case, out_dir: Path, comm: MPI.Comm, rep: Reporter, key: str) -> None:
    """static.h5 for reused modes: assemble K again and factor it once."""
    with rep.stage("static correction: mesh + assembly"):
        mesh = on_root(lambda: run_mesh_stage(case, out_dir, rep)[0], comm)
        dofmap = build_dofmap(mesh, comm.size, case["modal.fix_sleeper_rotations"],
                              case["modal.fix_rail_rotations_at_pads"])
        K, M, _ = assemble(mesh, case, dofmap, comm)
    load_dofs, table = rail_load_dofs(mesh, dofmap)
    rhs, free = unit_loads(load_dofs, *dofmap.owned_dofs(comm.rank))
    with rep.stage("static solves"):
        try:
            x_static = solve_static(K, M, comm, rhs)
        finally:
            K.destroy()
            M.destroy()
    with rep.stage("write static.h5"):
        write_static(out_dir / "static.h5", comm, mesh, dofmap, x_static, free, load_dofs,
                     table, key)
    rep.info(f"wrote {out_dir / 'static.h5'}: static solutions for {free.size} unit loads on "
             "the rail DOFs (static correction)")


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
