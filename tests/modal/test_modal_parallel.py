"""Distributed assembly and eigensolve: the same answer on 1 and N ranks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from railvib_hpc.config import load_case
from railvib_hpc.petsc_env import init_petsc

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
comm = MPI.COMM_WORLD


@pytest.fixture(scope="module")
def coarse():
    from railvib_hpc.mesh.gmsh_model import generate
    from railvib_hpc.mesh.layout import build_layout
    from railvib_hpc.parallel import on_root

    case = load_case(BASELINE, ["mesh.refinement=0.5"])
    mesh = on_root(lambda: generate(build_layout(case))[0])
    return case, mesh


@pytest.mark.mpi
def test_matrix_norms_and_eigenvalues_equal_serial(coarse):
    init_petsc([])
    from petsc4py import PETSc

    from railvib_hpc.modal.dofmap import build_dofmap
    from railvib_hpc.modal.eigen import solve_modes
    from railvib_hpc.modal.petsc import assemble

    case, mesh = coarse
    K1, M1, _ = assemble(mesh, case, build_dofmap(mesh, 1), MPI.COMM_SELF)
    dofmap = build_dofmap(mesh, comm.size)
    KN, MN, _ = assemble(mesh, case, dofmap, comm)
    assert KN.getSize() == K1.getSize()
    for norm in (PETSc.NormType.FROBENIUS, PETSc.NormType.INFINITY, PETSc.NormType.NORM_1):
        assert KN.norm(norm) == pytest.approx(K1.norm(norm), rel=1e-12)  # reduction order differs
        assert MN.norm(norm) == pytest.approx(M1.norm(norm), rel=1e-12)  # reduction order differs
    # exact preallocation: no mallocs during assembly
    assert KN.getInfo()["mallocs"] == 0 and MN.getInfo()["mallocs"] == 0
    serial = solve_modes(K1, M1, MPI.COMM_SELF, n_modes=20, tol=1e-10)
    parallel = solve_modes(KN, MN, comm, n_modes=20, tol=1e-10)
    assert parallel.eigenvalues == pytest.approx(serial.eigenvalues, rel=1e-9)
    assert parallel.stats["max_orthonormality_error"] < 1e-10
    # the mode shapes agree up to sign: compare the owned rows of each mode
    r0, r1 = dofmap.owned_dofs(comm.rank)
    for k in range(20):
        a, b = parallel.phi[:, k], serial.phi[r0:r1, k]
        dot = comm.allreduce(float(a @ b))
        if k == 0 or serial.eigenvalues[k] - serial.eigenvalues[k - 1] > 1e-6 * \
                serial.eigenvalues[k]:
            if k + 1 < 20 and serial.eigenvalues[k + 1] - serial.eigenvalues[k] < 1e-6 * \
                    serial.eigenvalues[k]:
                continue                                   # repeated pair: any basis is fine
            assert abs(abs(dot) / np.sqrt(comm.allreduce(float(a @ a)) *
                                          comm.allreduce(float(b @ b))) - 1) < 1e-6


@pytest.mark.mpi
def test_modal_command_writes_the_same_modes_on_all_rank_counts(shared_tmp, coarse):
    import h5py

    from railvib_hpc.cli import run

    out = shared_tmp / "res"
    args = ["modal", str(BASELINE), "--set", "mesh.refinement=0.5", "--set",
            "modal.n_modes=20", "--out", str(out)]
    assert run(args) == 0
    comm.Barrier()
    with h5py.File(out / "modes.h5", "r") as f:
        freq = f["modes/frequency_hz"][()]
        trans = f["modes/translation"][()]
        energy = f["modes/strain_energy"][()]
        assert int(f.attrs["complete"]) == 1
        assert f["mesh/nodal_mass"][()].min() >= 0
    if comm.rank == 0:
        (out / "modes.h5").rename(out / "modes_parallel.h5")
    comm.Barrier()
    # serial reference computed on rank 0 alone, in this process
    if comm.rank == 0:
        from railvib_hpc.log import Reporter
        from railvib_hpc.modal.stage import run_modal_stage

        case = load_case(BASELINE, ["mesh.refinement=0.5", "modal.n_modes=20"])
        run_modal_stage(case, shared_tmp / "serial", MPI.COMM_SELF, Reporter(1))
        with h5py.File(shared_tmp / "serial" / "modes.h5", "r") as f:
            assert f["modes/frequency_hz"][()] == pytest.approx(freq, rel=1e-9)
            ref = f["modes/translation"][()]
            # per-material strain energies do not depend on the rank count (nor on the
            # sign of a mode); rows of repeated eigenvalues may mix, their sums may not
            e_ref = f["modes/strain_energy"][()]
        assert e_ref.sum(axis=0) == pytest.approx(energy.sum(axis=0), rel=1e-7)
        assert e_ref.sum(axis=1) == pytest.approx(energy.sum(axis=1), rel=1e-8)
        for k in range(20):
            c = np.vdot(ref[k], trans[k]) / np.sqrt(np.vdot(ref[k], ref[k]) *
                                                    np.vdot(trans[k], trans[k]))
            repeated = any(abs(freq[k] - freq[j]) < 1e-6 * freq[k] for j in range(20) if j != k)
            assert repeated or abs(abs(c) - 1) < 1e-6
    comm.Barrier()


@pytest.mark.mpi
def test_incompatible_modes_and_out_of_core_equal_serial(coarse, monkeypatch):
    """Incompatible-modes hexahedra assembled on N ranks give the serial matrices and
    eigenvalues; with too little memory for the in-core factor (simulated), 'auto' factors
    out of core on every rank and still finds the serial eigenvalues."""
    init_petsc([])
    from petsc4py import PETSc

    from railvib_hpc.config import load_case
    from railvib_hpc.modal import block_lanczos
    from railvib_hpc.modal.dofmap import build_dofmap
    from railvib_hpc.modal.eigen import solve_modes
    from railvib_hpc.modal.petsc import assemble

    _, mesh = coarse
    case = load_case(BASELINE, ["mesh.refinement=0.5", "modal.hex_formulation=incompatible"])
    K1, M1, _ = assemble(mesh, case, build_dofmap(mesh, 1), MPI.COMM_SELF)
    KN, MN, _ = assemble(mesh, case, build_dofmap(mesh, comm.size), comm)
    # each rank condenses the bubbles of its own representative element per shape (a
    # different element on 1 and N ranks): round-off eps * cond(K_aa) (<= 192 on this mesh)
    # per entry, accumulated over a row's 243 entries in the worst case: 2.2e-16 * 192 *
    # 243 = 1e-11
    for norm in (PETSc.NormType.FROBENIUS, PETSc.NormType.INFINITY):
        assert KN.norm(norm) == pytest.approx(K1.norm(norm), rel=1e-11)
    serial = solve_modes(K1, M1, MPI.COMM_SELF, n_modes=10, tol=1e-10)

    def estimate(self, prefix):
        ooc = PETSc.Options().getInt("railvib_eig_st_mat_mumps_icntl_22", 0) == 1
        return 0.001 if ooc else 100.0

    monkeypatch.setattr(block_lanczos, "available_memory_gb", lambda c: 1.0)
    monkeypatch.setattr(block_lanczos.BlockOperator, "_estimate_factor_memory", estimate)
    parallel = solve_modes(KN, MN, comm, n_modes=10, tol=1e-10, out_of_core="auto")
    assert parallel.stats["out_of_core"] is True
    assert parallel.eigenvalues == pytest.approx(serial.eigenvalues, rel=1e-9)
    assert not PETSc.Options().hasName("railvib_eig_st_mat_mumps_icntl_22")
