"""The ``modal`` stage: mesh (reused) -> DOFs -> distributed K, M -> eigensolve -> modes.h5."""

from __future__ import annotations

import json
import resource
import time
from pathlib import Path

import numpy as np

from .. import __version__
from ..config import Case
from ..io.modes_io import read_modes_summary, read_strain_energies, write_modes
from ..log import Reporter
from ..mesh.stage import MESH_INPUTS, run_mesh_stage
from ..parallel import on_root
from .boundary import case_dofmap
from .eigen import solve_modes
from .elements import nodal_masses
from .energy import group_strain_energies
from .petsc import assemble
from .projection import (
    project_damping_parts,
    read_damping_parts,
    read_phi_rows,
    write_damping_parts,
)
from .static import rail_load_dofs, solve_static, static_is_valid, unit_loads, write_static

#: Keys of [modal] and of each material that do not change the modes (not in the reuse key).
_NOT_MODAL_INPUTS = ("damping_ratio", "damping", "out_of_core")


def modal_digest(case: Case) -> str:
    """Hash of everything the modes depend on (damping settings excluded, so changing them
    reuses the modes)."""
    import hashlib

    modal = {k: v for k, v in case["modal"].items() if k not in _NOT_MODAL_INPUTS}
    physics = case.digest("materials", "sections", "pads", exclude=_NOT_MODAL_INPUTS)
    text = json.dumps({"mesh": case.digest(*MESH_INPUTS), "physics": physics,
                       "modal": modal, "boundary": case.digest("boundary")}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _max_basis(case: Case, n_dofs: int) -> int:
    """``modal.max_basis``, or 3 n_modes capped at ~4 GB of basis vectors (all ranks)."""
    if case["modal.max_basis"] > 0:
        return case["modal.max_basis"]
    cap = int(4e9 / (8.0 * n_dofs))
    return max(min(3 * case["modal.n_modes"], cap),
               case["modal.n_modes"] + 3 * case["modal.block_size"])


def _progress(rep: Reporter):
    t_start = time.perf_counter()
    state = {"last": -1e9}

    def monitor(nconv: int, nev: int, basis: int) -> None:
        now = time.perf_counter()
        if now - state["last"] < 2.0 and nconv < nev:
            return
        state["last"] = now
        rep.progress(f"eigensolve: {nconv}/{nev} modes converged, basis {basis}",
                     max(nconv, 0), nev, t_start)

    return monitor


def run_modal_stage(case: Case, out_dir: Path, comm, rep: Reporter) -> dict:
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
        return summary

    old = on_root(previous, comm)
    want_static = bool(case["mbs.static_correction"])
    static_path = out_dir / "static.h5"
    want_damping = case["modal.damping"] == "full"
    damping_path = out_dir / "modal_damping.h5"
    if old is not None:
        f = old["frequency_hz"]
        rep.info(f"reusing {path} (same model and modal settings): {len(f)} modes, "
                 f"{f[0]:.3f} - {f[-1]:.3f} Hz")
        if want_static and not on_root(lambda: static_is_valid(static_path, key), comm):
            _static_only(case, out_dir, comm, rep, key)
        if want_damping and not on_root(
                lambda: read_damping_parts(damping_path, key) is not None, comm):
            _damping_only(case, out_dir, comm, rep, key, len(f))
        return {"reused": True, "n_modes": len(f), "f_min": float(f[0]), "f_max": float(f[-1]),
                **json.loads(old.get("stats", "{}"))}

    with rep.stage("mesh (load/build + broadcast)"):
        mesh = on_root(lambda: run_mesh_stage(case, out_dir, rep)[0], comm)
    t0 = time.perf_counter()
    with rep.stage("dofs"):
        dofmap = case_dofmap(mesh, case, comm.size)
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
            static_rhs=static_rhs, out_of_core=case["modal.out_of_core"])
    if result.stats.get("out_of_core"):
        rep.info(f"  MUMPS out of core (factor on disk): in-core estimate "
                 f"{result.stats['factor_memory_in_core_gb']:.1f} GB, out of core "
                 f"{result.stats['factor_memory_gb']:.1f} GB (modal.out_of_core = "
                 f"'{case['modal.out_of_core']}')")
    with rep.stage("strain energies"):
        energies = group_strain_energies(mesh, case, dofmap, comm, result.phi)
    parts = None
    if want_damping:
        with rep.stage("projected damping"):
            parts = project_damping_parts(mesh, case, dofmap, comm, K, result.phi)
    x_static = result.static
    if want_static and x_static is None:
        with rep.stage("static solves"):
            x_static = solve_static(K, M, comm, static_rhs)
    K.destroy()
    M.destroy()
    with rep.stage("write modes"):
        translation, rotation, rot_nodes, rot_range, nodes = node_arrays(result.phi, dofmap,
                                                                          comm.rank)
        mask = np.zeros(mesh.n_nodes, dtype=bool)
        mask[nodes] = True
        masses = nodal_masses(mesh, case, mask)[nodes]
        stats = dict(result.stats)
        stats.update({"assembly_" + k: v for k, v in ainfo.items()})
        stats["time_assembly_total"] = t_assembly
        rss = comm.allgather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6)
        stats["peak_rss_gb_per_rank"] = rss
        stats["peak_rss_gb_total"] = float(sum(rss))
        stats["n_dofs"] = dofmap.n_dofs
        stats["ranks"] = comm.size
        # attributes are written collectively: every rank must pass the same text (the
        # assembly timings and counts differ per rank; rank 0's are kept)
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
    if parts is not None:
        on_root(lambda: write_damping_parts(damping_path, parts, key), comm)
        rep.info(f"wrote {damping_path}: Phi^T C Phi of the dashpots, pads and materials "
                 "(modal.damping = 'full')")
    if want_static:
        with rep.stage("write static.h5"):
            write_static(static_path, comm, mesh, dofmap, x_static, free, load_dofs, table, key)
        rep.info(f"wrote {static_path}: static solutions for {free.size} unit loads on the "
                 "rail DOFs (static correction)")
    return summary


def _static_only(case: Case, out_dir: Path, comm, rep: Reporter, key: str) -> None:
    """static.h5 for reused modes: assemble K again and factor it once."""
    with rep.stage("static correction: mesh + assembly"):
        mesh = on_root(lambda: run_mesh_stage(case, out_dir, rep)[0], comm)
        dofmap = case_dofmap(mesh, case, comm.size)
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


def _damping_only(case: Case, out_dir: Path, comm, rep: Reporter, key: str, m: int) -> None:
    """modal_damping.h5 for reused modes: assemble again, read the modes' rows, project."""
    with rep.stage("projected damping (reused modes)"):
        mesh = on_root(lambda: run_mesh_stage(case, out_dir, rep)[0], comm)
        dofmap = case_dofmap(mesh, case, comm.size)
        K, _, _ = assemble(mesh, case, dofmap, comm, mass=False)
        phi = read_phi_rows(out_dir / "modes.h5", dofmap, comm.rank, m)
        parts = project_damping_parts(mesh, case, dofmap, comm, K, phi)
        K.destroy()
    on_root(lambda: write_damping_parts(out_dir / "modal_damping.h5", parts, key), comm)
    rep.info(f"wrote {out_dir / 'modal_damping.h5'} (modal.damping = 'full')")


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


def node_arrays(phi: np.ndarray, dofmap, rank: int):
    """Reshape this rank's DOF rows of the modes into per-node translation/rotation arrays.

    Returns
    -------
    translation : (m, owned nodes, 3)
    rotation : (m, owned rotation nodes, 3)
    rotation_nodes : all rotation nodes (global)
    rot_range : slice of ``rotation_nodes`` owned here
    nodes : slice of owned nodes
    """
    nodes = dofmap.owned_nodes(rank)
    r0, _ = dofmap.owned_dofs(rank)
    idx = dofmap.index[nodes]
    m = phi.shape[1]
    full = np.zeros((m, idx.shape[0], 6))
    ok = idx >= 0
    full[:, ok] = phi[idx[ok] - r0].T
    rotation_nodes = np.flatnonzero(dofmap.has_rotations)
    lo, hi = np.searchsorted(rotation_nodes, [nodes.start, nodes.stop])
    owned_rot = rotation_nodes[lo:hi] - nodes.start
    return (full[:, :, :3], full[:, owned_rot, 3:], rotation_nodes, slice(int(lo), int(hi)),
            nodes)
