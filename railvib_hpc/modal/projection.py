"""The full damping matrix in modal coordinates, ``D = Phi^T C Phi`` (``modal.damping = 'full'``).

Absorbing faces (Lysmer-Kuhlemeyer dashpots on part of the boundary) and per-material
Rayleigh damping are not proportional to K and M: in modal coordinates they couple the
modes. ``modal.damping = 'full'`` keeps the whole (m, m) matrix ``D`` of the damping matrix
C of the full-order model (:func:`~.petsc.assemble_damping`, the same ``[damping]`` and
``[boundary]``), and the multibody stage integrates the coupled modal equations
(:class:`~railvib_hpc.mbs.propagator.CoupledPropagator`).

So that changing the damping ratios or frequencies reuses the modes, ``modal_damping.h5``
stores the projected *parts* of C, which do not depend on them (collective computation,
rank 0 writes; a stage file of :data:`railvib_hpc.io.products.STAGE_FILES`: provenance
with the content digest of the ``modes.h5`` it projects on, checked atomic write, record):

* ``/dashpots`` (m, m): ``Phi^T C_dashpots Phi`` of the absorbing faces;
* ``/pads`` (m, m): ``Phi^T C_pads Phi`` of the rail pads' dashpots (``pads.c*``);
* ``/mass/<group>``, ``/stiffness/<group>`` (m, m): ``Phi^T M_g Phi``, ``Phi^T K_g Phi`` of
  every material group of :func:`~.energy.material_groups` (per-material Rayleigh).

With ``mbs.static_correction`` the basis is ``[Phi, X]``: the modes followed by the static
fields of the rail DOFs (:mod:`.static`), so every part is (m + n_r, m + n_r) and the
multibody stage can damp the residual vectors of the static correction consistently
(:func:`railvib_hpc.mbs.static_correction.residual_damping_parts`).

:func:`compose_damping` builds ``D`` for a problem from them (pure numpy): Rayleigh
``alpha I + beta Lambda`` (exact for mass-normalised modes), or ``sum_g alpha_g
Phi^T M_g Phi + beta_g Phi^T K_g Phi``, plus the dashpots and, with ``damping.pads``, the
pads.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..problem import Problem

#: Datasets of ``modal_damping.h5`` (besides the per-group ``mass/*`` and ``stiffness/*``).
PARTS = ("dashpots", "pads")


def read_phi_rows(modes_path: Path, dofmap, rank: int, m: int | None) -> np.ndarray:
    """This rank's DOF rows (n_local, m) of the first ``m`` modes of ``modes.h5`` (all of
    them for None).

    The inverse of :func:`railvib_hpc.modal.stage.node_arrays`: translations and rotations
    of the owned nodes mapped to their global DOF numbers.

    Raises
    ------
    ValueError
        When the file's DOF numbering differs from ``dofmap`` (another model).
    """
    import h5py

    nodes = dofmap.owned_nodes(rank)
    r0, r1 = dofmap.owned_dofs(rank)
    with h5py.File(modes_path, "r") as f:
        index = f["dofs/index"][()]
        if not np.array_equal(index, dofmap.index):
            raise ValueError(f"{modes_path} was computed with another DOF numbering")
        m = f["modes/eigenvalue"].shape[0] if m is None else m
        trans = f["modes/translation"][:m, nodes, :]
        rot_nodes = f["mesh/rotation_nodes"][()]
        lo, hi = np.searchsorted(rot_nodes, [nodes.start, nodes.stop])
        rot = f["modes/rotation"][:m, lo:hi, :] if hi > lo else np.zeros((m, 0, 3))
    full = np.zeros((m, nodes.stop - nodes.start, 6))
    full[:, :, :3] = trans
    full[:, rot_nodes[lo:hi] - nodes.start, 3:] = rot
    idx = dofmap.index[nodes]
    ok = idx >= 0
    out = np.zeros((r1 - r0, m))
    out[idx[ok] - r0] = full[:, ok].T
    return out


def project(A, phi: np.ndarray, comm) -> np.ndarray:
    """``Phi^T A Phi`` (m, m), the same on every rank (collective)."""
    from mpi4py import MPI
    from petsc4py import PETSc

    n_local, m = phi.shape
    basis = PETSc.Mat().createDense(size=((n_local, A.getSize()[0]), (PETSc.DECIDE, m)),
                                    array=np.asfortranarray(phi, dtype=float), comm=comm)
    product = A.matMult(basis)
    out = np.ascontiguousarray(phi.T @ product.getDenseArray())
    comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
    product.destroy()
    basis.destroy()
    return 0.5 * (out + out.T)


def project_damping_parts(mesh, problem: Problem, dofmap, comm, K, phi: np.ndarray
                          ) -> dict[str, np.ndarray]:
    """The projected parts of C (see the module notes), collective."""
    from ..model.elements import material_groups
    from ..model.petsc import assemble, node_block_matrix

    out: dict[str, np.ndarray] = {}
    for which in PARTS:
        A = node_block_matrix(K, mesh, problem, dofmap, comm.rank, which)
        out[which] = project(A, phi, comm)
        A.destroy()
    for group, parts in material_groups(mesh).items():
        Kg, Mg, _ = assemble(mesh, problem, dofmap, comm, parts=parts, mass=True)
        out[f"stiffness/{group}"] = project(Kg, phi, comm)
        out[f"mass/{group}"] = project(Mg, phi, comm)
        Kg.destroy()
        Mg.destroy()
    return out






def compose_damping(problem: Problem, parts: dict[str, np.ndarray], omega: np.ndarray
                    ) -> np.ndarray:
    """``D = Phi^T C Phi`` (m, m) of the problem's ``[damping]`` from the projected parts.

    ``omega`` are the circular frequencies of the modes used (their number ``m`` may be
    smaller than the stored parts).
    """
    from ..model.damping import material_rayleigh, problem_rayleigh

    om = np.asarray(omega, dtype=float)
    m = om.size
    d = parts["dashpots"][:m, :m].copy()
    if problem.damping.pads:
        d += parts["pads"][:m, :m]
    model = problem.damping.model
    if model == "rayleigh":
        alpha, beta = problem_rayleigh(problem)
        d += np.diag(alpha + beta * om**2)
    elif model == "per_material":
        groups = sorted(k.split("/", 1)[1] for k in parts if k.startswith("stiffness/"))
        for g, (alpha, beta) in material_rayleigh(problem, groups).items():
            d += alpha * parts[f"mass/{g}"][:m, :m] + beta * parts[f"stiffness/{g}"][:m, :m]
    return 0.5 * (d + d.T)
