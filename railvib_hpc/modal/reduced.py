"""The uncertainty study's parametric reduced model: the basis built once, each sample's modes.

Offline (:func:`build_basis`, collective, on the nominal model): the nominal modes ``Phi``
augmented with the static sensitivity vectors ``K0^-1 K_g Phi`` (and ``K0^-1 M_g Phi``
where the part's density varies) of every varied part ``g``, M-orthonormalised
(:func:`~railvib_hpc.uncertainty.reduced.orthonormalising_map`), and every part's K and
M projected on it; written to ``reduced_basis.h5`` (:func:`write_basis`) next to the
nominal ``mesh.h5`` and ``modes.h5``.

The parts (:func:`rom_parts`): every material group of
:func:`~.elements.material_groups` (its K scales with the material's E, its M with its
rho), and each rail-pad direction (its K scales with ``pads.k<x|y|z>``); what is left of
K and M (the elastic interfaces, the absorbing faces' springs) is the fixed rest.

Online (:func:`reduced_modes`, the ``modal`` stage of a sample with
``uncertainty.basis``): the sample's factors ``s_g = E_g / E_g0``, ``t_g = rho_g / rho_g0``
give ``K_r(p)``, ``M_r(p)`` (a sum of the projected parts; with a random field, which is
no such sum, the Galerkin projection of the sample's assembled K and M instead), their
``n_modes`` lowest eigenpairs, the Ritz vectors ``V Y`` and their relative residuals
``||K phi - lambda M phi|| / ||K phi||`` with the sample's own assembled (distributed) K
and M. Above ``uncertainty.reduced_tol`` the stage falls back to the full eigensolve.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..model.elements import PAD_DIRECTION, PADS, material_groups
from ..model.factor import sparse_times_block
from ..model.petsc import assemble
from ..uncertainty.reduced import (
    orthonormalising_map,
    reduced_eigenpairs,
    reduced_matrices,
    relative_residuals,
)

if TYPE_CHECKING:
    from mpi4py import MPI

    from ..problem import Problem

#: Neumann terms per sensitivity vector (:func:`build_basis`): the static vector
#: ``K0^-1 K_g phi`` misses the inertia of the mode's change, ``K0^-1 M0 K0^-1 K_g phi``
#: adds its first term (measured on the coarse thesis model: docs/uncertainty.md).
SENSITIVITY_DEPTH = 2
#: The reduced model's file in the study's nominal model folder (``tag``: a digest of its
#: inputs, so that another basis gives its samples other digests).
BASIS_H5 = "reduced_basis_{tag}.h5"


def rom_parts(mesh, problem: Problem) -> dict[str, tuple[str, ...]]:
    """Part name -> mesh parts: the material groups (without the pads and the elastic
    interfaces) and ``pad_x``, ``pad_y``, ``pad_z``."""
    from ..schema import INTERFACE_PARTS

    out = {}
    for g, parts in material_groups(mesh).items():
        if g == PADS:
            out.update({p: (p,) for p in parts})
        elif g not in INTERFACE_PARTS:
            out[g] = parts
    return out


def part_values(problem: Problem, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The stiffness and mass measures of each part: (E or k, rho; 0 for a pad's mass)."""
    k, r = np.empty(len(names)), np.empty(len(names))
    for i, n in enumerate(names):
        if n in PAD_DIRECTION:
            k[i], r[i] = getattr(problem.pads, PAD_DIRECTION[n][0]), 0.0
        else:
            mat = problem.material(n)
            k[i], r[i] = mat.E, mat.rho
    return k, r


def _gram(v: np.ndarray, mv: np.ndarray, comm: MPI.Comm) -> np.ndarray:
    """``V^T (M V)`` summed over the ranks."""
    from mpi4py import MPI

    out = v.T @ mv
    comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
    return out


def build_basis(mesh, problem: Problem, dofmap, comm: MPI.Comm, K, M, phi: np.ndarray,
                varied: dict[str, tuple[str, ...]], depth: int = SENSITIVITY_DEPTH,
                second_order: bool = True, lowest: int | None = None) -> dict:
    """The augmented, M-orthonormal basis and the projected parts (collective).

    Parameters
    ----------
    mesh, problem, dofmap, K, M
        The nominal model (K, M assembled).
    phi
        This rank's rows of the nominal modes (n_local, m).
    varied
        Part name -> ``("K",)``, ``("K", "M")``: the sensitivity vectors to add.
    depth
        Degree of the sensitivity vectors: 1 ``X1 = K0^-1 K_g Phi``; 2 adds
        ``K0^-1 M0 X1`` (a Neumann term of ``(K0 - lambda M0)^-1``) and, with
        ``second_order``, ``K0^-1 K_h X1``; and so on.
    second_order
        Whether the higher degrees hold the parts' products too (else only ``M0``'s).
    lowest
        The higher degrees only from the vectors of the ``lowest`` modes (None: all).

    Returns
    -------
    dict
        ``basis`` (n_local, r), ``names``, ``k_parts``, ``m_parts`` (G, r, r), ``rest_k``,
        ``rest_m`` (r, r), ``nominal_k``, ``nominal_rho`` (G,), ``n_modes``,
        ``n_sensitivity``, ``seconds``.
    """
    from mpi4py import MPI

    from ..model.factor import ShiftInvertFactor
    from .eigen import PREFIX

    t0 = time.perf_counter()
    parts = rom_parts(mesh, problem)
    names = sorted(parts)
    mats = {n: assemble(mesh, problem, dofmap, comm, parts=parts[n],
                        mass=n not in PAD_DIRECTION)[:2] for n in names}
    rhs = [sparse_times_block(mats[n][i], phi, comm) for n, which in varied.items()
           if n in mats for i, w in enumerate(("K", "M"))
           if w in which and mats[n][i] is not None]
    blocks = [phi]
    if rhs:
        op = ShiftInvertFactor(K, M, 0.0, comm, PREFIX)
        try:
            x = op.solve(np.hstack(rhs))
            blocks.append(x)
            if lowest is not None:    # the higher degrees from the lowest modes' vectors
                m = phi.shape[1]
                x = x[:, [j for j in range(x.shape[1]) if j % m < lowest]]
            ops = [M] + [mats[n][0] for n in varied if n in mats and "K" in varied[n]]
            for _ in range(1, depth):
                # the next terms: K0^-1 M0 x (the inertia of the change, a Neumann term of
                # (K0 - lambda M0)^-1) and K0^-1 K_h x (second order in the factors)
                x = op.solve(np.hstack([sparse_times_block(A, x, comm)
                                        for A in ops[:1 + second_order * len(ops)]]))
                blocks.append(x)
        finally:
            op.destroy()
    extra = np.hstack(blocks[1:]) if rhs else np.zeros((phi.shape[0], 0))
    v = np.hstack(blocks)
    v = v @ orthonormalising_map(_gram(v, sparse_times_block(M, v, comm), comm))
    # a second pass: one Gram-Schmidt step is not enough in floating point ("twice is
    # enough", Giraud et al., Numer. Math. 101, 2005)
    v = v @ orthonormalising_map(_gram(v, sparse_times_block(M, v, comm), comm))

    def project(A) -> np.ndarray:
        out = v.T @ sparse_times_block(A, v, comm)
        comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return 0.5 * (out + out.T)

    r = v.shape[1]
    k_parts, m_parts = np.zeros((len(names), r, r)), np.zeros((len(names), r, r))
    for i, n in enumerate(names):
        Kg, Mg = mats[n]
        k_parts[i] = project(Kg)
        if Mg is not None:
            m_parts[i] = project(Mg)
            Mg.destroy()
        Kg.destroy()
    nominal_k, nominal_rho = part_values(problem, names)
    return {"basis": v, "names": names, "k_parts": k_parts, "m_parts": m_parts,
            "rest_k": project(K) - k_parts.sum(axis=0),
            "rest_m": project(M) - m_parts.sum(axis=0), "nominal_k": nominal_k,
            "nominal_rho": nominal_rho, "n_modes": phi.shape[1],
            "n_sensitivity": extra.shape[1], "seconds": time.perf_counter() - t0}


def write_basis(path: Path, comm: MPI.Comm, dofmap, rom: dict, attrs: dict) -> None:
    """``reduced_basis.h5`` (the basis gathered on rank 0, in global DOF order)."""
    rows = comm.gather(rom["basis"], root=0)
    if comm.rank != 0:
        return
    import h5py

    from ..io.atomic import atomic_file

    with atomic_file(path) as tmp, h5py.File(tmp, "w") as f:
        f.create_dataset("basis", data=np.vstack(rows))
        f.create_dataset("dofs/index", data=dofmap.index)
        for key in ("k_parts", "m_parts", "rest_k", "rest_m", "nominal_k", "nominal_rho"):
            f.create_dataset(key, data=rom[key])
        f.attrs["names"] = list(rom["names"])
        f.attrs.update({"n_modes": rom["n_modes"], "n_sensitivity": rom["n_sensitivity"],
                        **attrs})


def read_basis(path: Path, dofmap, rank: int) -> dict:
    """This rank's rows of the basis and the projected parts.

    Raises
    ------
    ValueError
        When the file's DOF numbering differs from ``dofmap`` (another mesh).
    """
    import h5py

    r0, r1 = dofmap.owned_dofs(rank)
    with h5py.File(path, "r") as f:
        if not np.array_equal(f["dofs/index"][()], dofmap.index):
            raise ValueError(f"{path} was built on another mesh (DOF numbering)")
        out = {k: f[k][()] for k in ("k_parts", "m_parts", "rest_k", "rest_m", "nominal_k",
                                     "nominal_rho")}
        out["basis"] = f["basis"][r0:r1]
        out["names"] = [str(n) for n in f.attrs["names"]]
        out["attrs"] = {k: (v.decode() if isinstance(v, bytes) else v)
                        for k, v in f.attrs.items() if k != "names"}
    return out


def reduced_modes(rom: dict, problem: Problem, comm: MPI.Comm, K, M, n_modes: int) -> dict:
    """The sample's reduced eigenpairs and their residuals in the full space (collective).

    Returns
    -------
    dict
        ``eigenvalues`` (n,), ``phi`` (n_local, n), ``residuals`` (n,), ``projection``
        (``affine`` or ``galerkin``: a sample with a random field), ``factors``
        ``{part: [s, t]}``, ``size`` (the basis's directions), ``seconds``.
    """
    from mpi4py import MPI

    t0 = time.perf_counter()
    v = rom["basis"]
    k, rho = part_values(problem, rom["names"])
    s = k / rom["nominal_k"]
    t = np.divide(rho, rom["nominal_rho"], out=np.ones_like(rho),
                  where=rom["nominal_rho"] > 0)
    if problem.fields:            # no sum of the parts: project the sample's own K and M
        kv, mv = sparse_times_block(K, v, comm), sparse_times_block(M, v, comm)
        kr, mr = v.T @ kv, v.T @ mv
        comm.Allreduce(MPI.IN_PLACE, kr, op=MPI.SUM)
        comm.Allreduce(MPI.IN_PLACE, mr, op=MPI.SUM)
        kr, mr = 0.5 * (kr + kr.T), 0.5 * (mr + mr.T)
        projection = "galerkin"
    else:
        kr, mr = reduced_matrices(rom["rest_k"], rom["rest_m"], rom["k_parts"],
                                  rom["m_parts"], s, t)
        projection = "affine"
    lam, y = reduced_eigenpairs(kr, mr, n_modes)
    phi = v @ y
    kp, mp = sparse_times_block(K, phi, comm), sparse_times_block(M, phi, comm)
    r = kp - lam * mp                  # formed, not expanded: no cancellation
    sums = np.stack([np.einsum("ij,ij->j", r, r), np.einsum("ij,ij->j", kp, kp)])
    comm.Allreduce(MPI.IN_PLACE, sums, op=MPI.SUM)
    res = relative_residuals(sums[0], sums[1])
    return {"eigenvalues": lam, "phi": phi, "residuals": res, "projection": projection,
            "factors": {n: [float(a), float(b)] for n, a, b in zip(rom["names"], s, t)},
            "size": int(v.shape[1]), "seconds": time.perf_counter() - t0}


def prepare_basis(problem: Problem, path: Path, comm: MPI.Comm, rep,
                  varied: dict[str, tuple[str, ...]], lowest: int | None = None) -> Path:
    """The basis file ``path`` from the nominal ``mesh.h5`` and ``modes.h5`` beside it,
    reused while it was built from the same ``modes.h5`` for the same varied parts
    (collective); returns its path. ``lowest``: see :func:`build_basis`."""
    import json

    import h5py

    from ..io.digests import file_digest
    from ..io.files import MESH_H5, MODES_H5
    from ..mesh.mesh_io import read_mesh_h5
    from ..model.boundary import problem_dofmap
    from ..parallel import on_root
    from .projection import read_phi_rows

    folder = path.parent
    modes = folder / MODES_H5
    key = json.dumps({"parts": {k: list(v) for k, v in sorted(varied.items())},
                      "depth": SENSITIVITY_DEPTH, "lowest": lowest})

    def current() -> tuple[bool, str, str]:
        sha = str(file_digest(modes).sha256)
        with h5py.File(modes, "r") as f:
            mesh_sha = json.loads(str(f.attrs["upstream_sha256"]))[MESH_H5]
        if path.exists():
            with h5py.File(path, "r") as f:
                if f.attrs.get("modes_sha256") == sha and f.attrs.get("varied") == key:
                    return True, sha, mesh_sha
        return False, sha, mesh_sha

    ok, sha, mesh_sha = on_root(current, comm)
    if ok:
        rep.info(f"reusing {path} (same nominal modes and varied parts)")
        return path
    with rep.stage("reduced model: basis"):
        mesh = on_root(lambda: read_mesh_h5(folder / MESH_H5)[0], comm)
        dofmap = problem_dofmap(mesh, problem, comm.size)
        K, M, _ = assemble(mesh, problem, dofmap, comm)
        try:
            phi = read_phi_rows(modes, dofmap, comm.rank, None)
            rom = build_basis(mesh, problem, dofmap, comm, K, M, phi, varied,
                              lowest=lowest)
        finally:
            K.destroy()
            M.destroy()
        write_basis(path, comm, dofmap, rom, {"modes_sha256": sha, "mesh_sha256": mesh_sha,
                                              "varied": key})
        comm.Barrier()
    rep.info(f"wrote {path}: {rom['n_modes']} modes + {rom['n_sensitivity']} sensitivity "
             f"vectors -> {rom['basis'].shape[1]} M-orthonormal directions, "
             f"{len(rom['names'])} parts projected ({rom['seconds']:.1f} s)")
    return path
