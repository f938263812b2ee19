"""Strain energy of every mode per material (PETSc code): the basis of material damping.

For mass-normalised modes ``phi_i`` the strain energies ``E_ig = phi_i^T K_g phi_i`` of the
material groups ``g`` (the stiffness of the elements of one material) add up to
``phi_i^T K phi_i = omega_i^2``. With per-material damping ratios ``zeta_g`` the modal
strain energy method (ANSYS ``MP,DMPR``) gives each mode the damping ratio
``zeta_i = sum_g zeta_g E_ig / sum_g E_ig`` — a diagonal approximation of the
non-proportional damping matrix that keeps the modal equations uncoupled.

Groups: one per material of the solids and beams (``ballast``, ``subballast``,
``subgrade``, ``concrete``, ``rail``, ``sleeper``) and ``pads`` (the rail-pad springs,
damped with ``modal.damping_ratio``). Only groups with elements in the mesh appear.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..config import Case
from ..mesh.model import Mesh
from .dofmap import DofMap
from .elements import group_damping_ratio, material_groups
from .petsc import assemble

if TYPE_CHECKING:
    from mpi4py import MPI

def group_strain_energies(mesh: Mesh, case: Case, dofmap: DofMap, comm: MPI.Comm,
                          phi: np.ndarray) -> dict[str, np.ndarray]:
    """``E_ig = phi_i^T K_g phi_i`` for every mode and material group (collective).

    Parameters
    ----------
    mesh, case, dofmap
        The model as assembled by :func:`~railvib_hpc.modal.petsc.assemble`.
    comm
        MPI communicator.
    phi
        This rank's rows of the mass-normalised modes, shape (n_local_dofs, m).

    Returns
    -------
    dict
        Group name -> (m,) strain energies (the same on every rank); their sum over the
        groups is ``omega^2``.
    """
    from petsc4py import PETSc

    n_local, m = phi.shape
    basis = PETSc.Mat().createDense(size=((n_local, dofmap.n_dofs), (PETSc.DECIDE, m)),
                                    array=np.asfortranarray(phi, dtype=float), comm=comm)
    energies = {}
    for group, parts in material_groups(mesh).items():
        # the group's own sparsity pattern: the product costs its nonzeros only
        K, _, _ = assemble(mesh, case, dofmap, comm, parts=parts, mass=False)
        product = K.matMult(basis)
        local = np.einsum("ij,ij->j", phi, product.getDenseArray())
        energies[group] = comm.allreduce(local)
        product.destroy()
        K.destroy()
    basis.destroy()
    return energies


def damping_from_energies(energies: dict[str, np.ndarray], case: Case) -> np.ndarray:
    """Modal damping ratios ``sum_g zeta_g E_ig / sum_g E_ig`` (pure numpy).

    ``zeta_g`` is ``materials.<g>.damping_ratio``, ``modal.damping_ratio`` for the pads and
    half the loss factor for an elastic interface (:func:`.elements.group_damping_ratio`).
    """
    names = list(energies)
    e = np.stack([np.asarray(energies[g], dtype=float) for g in names], axis=1)
    ratios = np.array([group_damping_ratio(case, g) for g in names])
    total = e.sum(axis=1)
    return (e @ ratios) / np.where(total > 0, total, 1.0)
