"""The explicit engines' memory-lean matrices (issue 28): Rayleigh damping applied as an
operator, the diagonal lumped mass, the pattern built by chunks, against the assembled
matrices of the same model, on 1 and 2 ranks."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from wave_cases import box_mesh, soil_case

from railvib_hpc.problem import Problem

comm = MPI.COMM_WORLD
FACES = [f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_min", "y_max", "base")]


def _model():
    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.petsc_env import init_petsc

    init_petsc([])
    mesh = box_mesh((4, 3, 3), (4.0, 3.0, 3.0))
    case = soil_case(*FACES, "modal.lumped_mass=true", "damping.model=rayleigh")
    dofmap = build_dofmap(mesh, comm.size, rules=constraint_rules(Problem.from_case(case)),
                          node_sets=face_node_sets(mesh))
    return mesh, case, dofmap


@pytest.mark.mpi
def test_rayleigh_operator_is_the_assembled_damping():
    """``C x`` of the shell (alpha m + beta K + the dashpots) and of the assembled C agree to
    round-off, and the fused ``K u + C v`` is the sum of the two products."""
    from railvib_hpc.model.petsc import (
        assemble,
        assemble_damping,
        destroy_damping,
        rayleigh_operator,
        stiffness_and_damping,
    )
    from railvib_hpc.transient.explicit import lumped_diagonal

    mesh, case, dofmap = _model()
    K, M, _ = assemble(mesh, Problem.from_case(case), dofmap, comm)
    _, M_diag, _ = assemble(mesh, Problem.from_case(case), dofmap, comm, mass="diagonal")
    m = lumped_diagonal(M_diag, comm)
    assert np.array_equal(m, lumped_diagonal(M, comm))
    C, _ = assemble_damping(mesh, Problem.from_case(case), dofmap, comm, K, M)
    C_op, info = rayleigh_operator(mesh, Problem.from_case(case), dofmap, comm, K, m)
    assert info["operator"] and info["dashpot_nodes"] > 0
    r0, r1 = K.getOwnershipRange()
    rng = np.random.default_rng(7)
    u_all, v_all = rng.standard_normal((2, dofmap.n_dofs))
    u, v, a, b, w = (K.createVecRight() for _ in range(5))
    u.getArray()[:], v.getArray()[:] = u_all[r0:r1], v_all[r0:r1]
    C.mult(v, a)
    C_op.mult(v, b)
    scale = comm.allreduce(float(np.abs(a.getArray()).max()), op=MPI.MAX)
    assert comm.allreduce(float(np.abs(a.getArray() - b.getArray()).max()),
                          op=MPI.MAX) <= 1e-12 * scale
    stiffness_and_damping(K, C_op, u, v, b, w)
    K.mult(u, w)
    a.axpy(1.0, w)
    scale = comm.allreduce(float(np.abs(a.getArray()).max()), op=MPI.MAX)
    assert comm.allreduce(float(np.abs(a.getArray() - b.getArray()).max()),
                          op=MPI.MAX) <= 1e-12 * scale
    for obj in (u, v, a, b, w, K, M, M_diag, C):
        obj.destroy()
    destroy_damping(C_op)


def test_the_pattern_by_chunks_is_the_pattern_at_once(monkeypatch):
    """Any chunk size gives the same CSR pattern, on every rank of 1 to 3."""
    from railvib_hpc.model import petsc
    from railvib_hpc.model.dofmap import build_dofmap

    mesh = _model()[0]
    for ranks in (1, 2, 3):
        dofmap = build_dofmap(mesh, ranks, rules={"bottom": ("ux", "uy", "uz")})
        for rank in range(ranks):
            for parts in (None, ()):
                monkeypatch.setattr(petsc, "PATTERN_CHUNK_NODES", 10**9)
                whole = petsc.local_pattern(mesh, dofmap, rank, parts)
                monkeypatch.setattr(petsc, "PATTERN_CHUNK_NODES", 7)
                chunked = petsc.local_pattern(mesh, dofmap, rank, parts)
                assert np.array_equal(whole.indptr, chunked.indptr)
                assert np.array_equal(whole.indices, chunked.indices)
