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

from ..mesh.model import Mesh
from ..model.dofmap import DofMap
from ..model.elements import group_damping_ratio, material_groups
from ..model.petsc import assemble
from ..problem import Problem

if TYPE_CHECKING:
    from mpi4py import MPI

#: Modes per sparse product in :func:`group_strain_energies`: the product and the block's
#: copy take 2 x ``ENERGY_CHUNK`` n-vectors, not two more copies of all modes (1013 modes of
#: 1.03M DOFs: 8.3 GB each, which ran the 24 GB machine out of memory after the eigensolve).
ENERGY_CHUNK = 64


def group_strain_energies(mesh: Mesh, problem: Problem, dofmap: DofMap, comm: MPI.Comm,
                          phi: np.ndarray, chunk: int = ENERGY_CHUNK) -> dict[str, np.ndarray]:
    """``E_ig = phi_i^T K_g phi_i`` for every mode and material group (collective).

    Parameters
    ----------
    mesh, problem, dofmap
        The model as assembled by :func:`~railvib_hpc.model.petsc.assemble`.
    comm
        MPI communicator.
    phi
        This rank's rows of the mass-normalised modes, shape (n_local_dofs, m).
    chunk
        Modes per sparse product (the memory beyond ``phi``: two blocks of this width).

    Returns
    -------
    dict
        Group name -> (m,) strain energies (the same on every rank); their sum over the
        groups is ``omega^2``.
    """
    from ..model.factor import sparse_times_block

    m = phi.shape[1]
    energies = {}
    for group, parts in material_groups(mesh).items():
        # the group's own sparsity pattern: the product costs its nonzeros only
        K, _, _ = assemble(mesh, problem, dofmap, comm, parts=parts, mass=False)
        local = np.empty(m)
        for j in range(0, m, chunk):
            block = phi[:, j:j + chunk]
            local[j:j + chunk] = np.einsum("ij,ij->j", block,
                                           sparse_times_block(K, block, comm))
        energies[group] = comm.allreduce(local)
        K.destroy()
    return energies


def damping_from_energies(energies: dict[str, np.ndarray], problem: Problem) -> np.ndarray:
    """Modal damping ratios ``sum_g zeta_g E_ig / sum_g E_ig`` (pure numpy).

    ``zeta_g`` is ``materials.<g>.damping_ratio``, ``modal.damping_ratio`` for the pads and
    half the loss factor for an elastic interface (:func:`.elements.group_damping_ratio`).
    """
    names = list(energies)
    e = np.stack([np.asarray(energies[g], dtype=float) for g in names], axis=1)
    ratios = np.array([group_damping_ratio(problem, g) for g in names])
    total = e.sum(axis=1)
    return (e @ ratios) / np.where(total > 0, total, 1.0)
