"""The static start of the explicit engines (a wheel resting on the flexible rail at t = 0):
one solve per wheel, a MUMPS factor of K where it fits and the model is not too large, else
CG + GAMG with the rigid-body near null space (issue 28: the static start took 185-523 s
on the reflection study's 68k-178k DOF boxes, longer than the steps).

Measured on the coarse thesis model (18,063 DOFs, imex): 40.1 s before (CG + GAMG without
a near null space, one solve per rail DOF under the wheels: 16), 0.22 s with the factor;
the CG path with the near null space needs 156 iterations per wheel where it needed 491
(75 and 455 on the thesis baseline's coarse mesh).
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import FACES
from test_pml_stage import SHORT
from wave_cases import box_mesh, soil_case

from railvib_hpc.transient import explicit

#: The wheelset starting on the flexible rail (its first 20 steps).
ON_RAIL = ["vehicle.x_start=9", "vehicle.x_end=9.2", "transient.engine=imex"]


def test_the_rigid_body_modes_are_the_near_null_space_of_a_free_box():
    """K of an unsupported soil box times each of the six modes is zero to round-off, and
    the six are independent (each translation moves its own component only)."""
    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap, rigid_body_modes
    from railvib_hpc.model.petsc import assemble
    from railvib_hpc.problem import Problem

    comm = MPI.COMM_SELF
    mesh = box_mesh((4, 3, 2), (4.0, 3.0, 2.0))
    problem = Problem.from_case(soil_case(*(f"boundary.{f}=free" for f in FACES)))
    dofmap = build_dofmap(mesh, 1, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    K, _, _ = assemble(mesh, problem, dofmap, comm, mass=False)
    modes = rigid_body_modes(mesh.points, dofmap, 0)
    assert modes.shape == (dofmap.n_dofs, 6)
    assert np.linalg.matrix_rank(modes) == 6
    for c in range(3):
        assert np.count_nonzero(modes[:, c]) == mesh.n_nodes
    x, y = K.createVecRight(), K.createVecLeft()
    scale = K.norm() * np.abs(modes).max()
    for j in range(6):
        x.getArray()[:] = modes[:, j]
        K.mult(x, y)
        assert np.abs(y.getArray()).max() < 1e-12 * scale, j
    for obj in (x, y, K):
        obj.destroy()


@pytest.mark.mpi
def test_the_cg_static_start_with_rigid_body_modes_matches_the_factor(shared_tmp, monkeypatch):
    """The coarse thesis model with the wheelset on the flexible rail, the static
    deflections under its two wheels (``K x_j = E_D c_j``): by the factor (the default at
    this size) and with the factor ruled out (CG + GAMG, the path of models above
    ``STATIC_FACTOR_MAX_DOFS``) they agree within 1e-9 (CG's relative residual 1e-12;
    measured ~1e-12), and CG needs fewer than 250 iterations per wheel with the near null
    space (measured 156; 491 without: the same solve on a K that has none). On 1 and 2
    ranks."""
    from transient_cases import BASELINE

    from railvib_hpc.config import load_case
    from railvib_hpc.io.stage_protocol import StageContext
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import _setup

    comm = MPI.COMM_WORLD
    case = load_case(BASELINE, [*SHORT, *ON_RAIL])
    init = _setup(StageContext(case, shared_tmp / f"static_{comm.size}", comm,
                               Reporter(1)))
    system = init["system"]
    dofs, coef, _ = init["driver"].coupling.at(init["driver"].x[0])
    rhs = np.zeros((system.n_local, 2))
    for j in range(2):
        own = (dofs[j] >= system.r0) & (dofs[j] < system.r1)
        rhs[dofs[j][own] - system.r0, j] = coef[j][own]
    by_factor = system.solve_matrix(system.K, rhs)
    assert system.static_method.startswith("MUMPS Cholesky of K")
    monkeypatch.setattr(explicit, "STATIC_FACTOR_MAX_DOFS", 0)
    by_cg = system.solve_matrix(system.K, rhs)
    iterations = int(system.static_method.split(", ")[1].split()[0])
    assert system.static_method.startswith("CG + GAMG") and iterations < 250 * 2
    scale = comm.allreduce(np.abs(by_factor).max(), op=MPI.MAX)
    assert comm.allreduce(np.abs(by_cg - by_factor).max(), op=MPI.MAX) < 1e-9 * scale
    system.destroy()
