"""Distributed assembly and eigensolve: the same answer on 1 and N ranks.

Eigenvalues are compared to their componentwise round-off (the matrices differ by the order
of the element sums; block Lanczos's eigenvalues are Rayleigh quotients) and mode shapes
by the principal angles of each cluster against the Davis-Kahan bound of the measured
residuals (``modal_cases.eigen_rtol`` / ``assert_same_subspaces``,
:mod:`railvib_hpc.tolerances`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from modal_cases import (
    assert_same_subspaces,
    eigen_rtol,
    energy_tolerance,
    modes_from_file,
    to_scipy,
)
from mpi4py import MPI

from railvib_hpc import tolerances
from railvib_hpc.config import load_case
from railvib_hpc.petsc_env import init_petsc
from railvib_hpc.problem import Problem

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


#: A site on the coarse model: two soil layers, an EPS-filled trench and a wave-impeding block
#: (each its own part and material), a 3-storey building of 2 x 1 bays on strip footings,
#: two tracks on a 1 m fill embankment, and the three elastic interfaces (under-sleeper pads,
#: a ballast mat, bearings).
SITE = ["building.storeys=3", "building.bays_x=2", "building.foundation=strip",
        "track.count=2", "geometry.ys0=14.0", "track.embankment_height=1.0",
        "usp.modulus=1e8", "ballast_mat.modulus=5e7",
        "isolation.modulus=2e8",
        "soil.layers=[{thickness=1.5, c_s=150.0, nu=0.3, rho=1800.0}, "
        "{thickness=0.0, c_s=300.0, nu=0.3, rho=1950.0}]",
        "trench.type=filled", "trench.distance=6.0", "trench.width=1.2", "trench.depth=3.0",
        "wib.type=block", "wib.width=6.0", "wib.depth=1.0", "wib.thickness=1.2",
        "building.rotation=6.0"]


def _site_mesh(case):
    from railvib_hpc.mesh.gmsh_model import generate
    from railvib_hpc.mesh.interfaces import split_interfaces
    from railvib_hpc.mesh.layout import build_layout
    from railvib_hpc.mesh.turn import turn_building

    layout = build_layout(case)
    return turn_building(split_interfaces(generate(layout)[0], case), case, layout)


def _serial_site(folder: Path) -> None:
    """A builder of ``serial_refs`` (tests/conftest.py): the site's mesh, its K and M and
    their 20 lowest modes on ``MPI.COMM_SELF``. The test used to mesh on rank 0 and then
    assemble and solve them on every rank at once; here one rank does it beside the other
    references, and the test reads them (and the mesh)."""
    import pickle

    from railvib_hpc.modal.eigen import solve_modes
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble

    case = load_case(BASELINE, ["mesh.refinement=0.5", *SITE])
    mesh = _site_mesh(case)
    folder.mkdir(parents=True)
    (folder / "mesh.pkl").write_bytes(pickle.dumps(mesh))
    K1, M1, _ = assemble(mesh, Problem.from_case(case), build_dofmap(mesh, 1), MPI.COMM_SELF)
    serial = solve_modes(K1, M1, MPI.COMM_SELF, n_modes=20, tol=1e-10)
    Ks, Ms = to_scipy(K1), to_scipy(M1)
    np.savez(folder / "serial.npz", lam=serial.eigenvalues, phi=serial.phi,
             **{f"{n}_{a}": getattr(A, a) for n, A in (("K", Ks), ("M", Ms))
                for a in ("data", "indices", "indptr")})
    K1.destroy()
    M1.destroy()


@pytest.fixture(scope="module")
def coarse_site(serial_refs):
    """The site's case and mesh (the one its serial reference was computed on)."""
    import pickle

    case = load_case(BASELINE, ["mesh.refinement=0.5", *SITE])
    mesh = pickle.loads((serial_refs["modal_site_20_modes"] / "mesh.pkl").read_bytes())
    return case, mesh


def _serial_from(folder: Path):
    """K, M (scipy CSR) and the serial eigenpairs that :func:`_serial_site` wrote."""
    import scipy.sparse as sp

    with np.load(folder / "serial.npz") as f:
        n = len(f["K_indptr"]) - 1
        K, M = (sp.csr_matrix((f[f"{k}_data"], f[f"{k}_indices"], f[f"{k}_indptr"]),
                              shape=(n, n)) for k in ("K", "M"))
        return K, M, f["lam"], f["phi"]


@pytest.mark.slow
@pytest.mark.mpi
def test_site_with_measures_building_tracks_and_interfaces_equals_serial(coarse_site,
                                                                          serial_refs):
    """K and M (norms, preallocation) and the 20 lowest modes of the site on N ranks equal
    the serial ones. (The plain coarse model's test of the same, 12.9 s, is left out: its
    norms and mallocs are the site's checks on a subset of its parts, and its eigenvalues
    and mode subspaces are test_modal_command_writes_the_same_modes_on_all_rank_counts'
    on the same model, 20 modes, the same derived tolerances.)"""
    from railvib_hpc.schema import PART_ID

    case, mesh = coarse_site
    present = set(np.unique(mesh.hex_part).tolist())
    assert {PART_ID[p] for p in ("soil_layer_1", "soil_layer_2", "trench_fill", "wib",
                                 "fill")} <= present
    slab = mesh.points[np.unique(mesh.hexes[mesh.hex_part == PART_ID["slab"]])]
    assert len(np.unique(np.round(slab[:, 2], 6))) == 3 * 2          # three slabs' faces
    # the building turned by 6 degrees: its slab nodes no longer stand on x grid lines
    # (a straight building's 6 slab faces share a few x values; turned, nearly every
    # node of a face has its own)
    assert len(np.unique(np.round(slab[:, 0], 6))) > 0.5 * len(slab) / 6
    assert mesh.rail_nodes().shape[0] == 4                           # two tracks
    assert {PART_ID[f"{k}_z"] for k in ("usp", "ballast_mat", "isolation")} <= \
        set(np.unique(mesh.line_part).tolist())
    _assert_equal_serial(case, mesh, *_serial_from(serial_refs["modal_site_20_modes"]))


#: Products in one entry of a hexahedron's matrix: 8 Gauss points x the 6 x 6 of B^T D B.
HEX_ENTRY_TERMS = 8 * 6 * 6


def _norm_bounds(A, nu_max: float) -> dict:
    """How far the norms of an assembled SPSD matrix may move when the element kernels run
    in other batches and the sums in another order (N ranks), from the rigorous bound
    gamma(k) of a k-term sum (Higham §3.1).

    An entry is a sum over <= 8 elements of HEX_ENTRY_TERMS products each. Every element
    matrix is SPSD, so ``|c_ij| <= sqrt(c_ii c_jj)`` and, by Cauchy-Schwarz, the elements'
    terms of an entry add up in magnitude to at most ``sqrt(A_ii A_jj)`` (the diagonal sums
    have no cancellation), times the spread of the elasticity matrix D between its
    magnitudes and its energy, (1 - nu)/(1/2 - nu) at the largest Poisson's ratio. The norms
    add their own sums (the row's entries, the nnz squares). Both sides err: twice the bound.
    """
    from petsc4py import PETSc

    A = A.tocsr()
    d = np.sqrt(np.abs(A.diagonal()))
    P = A.copy()
    P.data[:] = 1.0
    g = tolerances.gamma(8 * HEX_ENTRY_TERMS) * (1 - nu_max) / (0.5 - nu_max)
    entry = g * d * (P @ d)                                   # per row: sum_j of the entry bound
    row_len = int(np.diff(A.indptr).max())
    rows = np.asarray(abs(A).sum(axis=1)).ravel()
    inf = 2 * np.max(entry + tolerances.gamma(row_len) * rows)
    coo = P.tocoo()
    e_fro = g * np.sqrt(np.sum((d[coo.row] * d[coo.col]) ** 2))
    fro = 2 * (e_fro + tolerances.gamma(A.nnz) * np.sqrt(np.sum(A.data ** 2)))
    # symmetric: the 1-norm is the infinity norm
    return {PETSc.NormType.FROBENIUS: fro, PETSc.NormType.INFINITY: inf,
            PETSc.NormType.NORM_1: inf}


def _assert_equal_serial(case, mesh, K1, M1, lam, phi_1):
    """K, M and the 20 lowest modes on all ranks equal the serial ones (``K1``, ``M1``:
    scipy CSR; ``lam``, ``phi_1``: the serial modes), to round-off."""
    init_petsc([])
    from petsc4py import PETSc

    from railvib_hpc.modal.eigen import solve_modes
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble
    from railvib_hpc.schema import PART_ID, SOLID_MATERIAL, SOLID_PARTS
    from railvib_hpc.site import solid_material

    KN, MN, _ = assemble(mesh, Problem.from_case(case), build_dofmap(mesh, comm.size), comm)
    assert KN.getSize() == K1.shape
    present = set(np.unique(mesh.hex_part).tolist())
    nu_max = max(solid_material(case, SOLID_MATERIAL[p])["nu"] for p in SOLID_PARTS
                 if PART_ID[p] in present)
    for A1, AN in ((K1, KN), (M1, MN)):
        rows = float(np.asarray(abs(A1).sum(axis=1)).max())     # (symmetric: 1 = inf)
        serial = {PETSc.NormType.FROBENIUS: float(np.sqrt(np.sum(A1.data ** 2))),
                  PETSc.NormType.INFINITY: rows, PETSc.NormType.NORM_1: rows}
        for norm, atol in _norm_bounds(A1, nu_max).items():
            assert abs(AN.norm(norm) - serial[norm]) <= atol, norm
    # exact preallocation: no mallocs during assembly
    assert KN.getInfo()["mallocs"] == 0 and MN.getInfo()["mallocs"] == 0
    parallel = solve_modes(KN, MN, comm, n_modes=20, tol=1e-10)
    rtol = eigen_rtol(K1, M1, lam, phi=phi_1)
    assert np.all(np.abs(parallel.eigenvalues / lam - 1) <= rtol)
    phi_n = np.concatenate(comm.allgather(parallel.phi))
    gram = tolerances.product_error(M1, phi_n)
    assert parallel.stats["max_orthonormality_error"] <= gram.max()
    # the mode shapes span the same subspaces, cluster by cluster (repeated pairs: any basis)
    assert assert_same_subspaces(K1, M1, lam, phi_1, phi_n, rtol) >= 15
    KN.destroy()
    MN.destroy()


def _serial_modal(folder) -> None:
    """A builder of ``serial_refs`` (tests/conftest.py): the modal stage of the command's
    case alone on ``MPI.COMM_SELF``."""
    from railvib_hpc.log import Reporter
    from railvib_hpc.modal.stage import run_modal_stage

    case = load_case(BASELINE, ["mesh.refinement=0.5", "modal.n_modes=20"])
    run_modal_stage(case, folder, MPI.COMM_SELF, Reporter(1))


#: The serial run test_modal_command_writes_the_same_modes_on_all_rank_counts compares with
#: (tests/conftest.py: ``serial_refs``, computed side by side with the other modules'
#: references): seconds on one rank, builder.
SERIAL_REFERENCES = {"modal_coarse_20_modes": (12.0, _serial_modal),
                     "modal_site_20_modes": (43.0, _serial_site)}


@pytest.mark.slow
@pytest.mark.mpi
def test_modal_command_writes_the_same_modes_on_all_rank_counts(shared_tmp, coarse,
                                                                serial_refs):
    import h5py

    from railvib_hpc.cli import run

    out = shared_tmp / "res"
    args = ["modal", str(BASELINE), "--set", "mesh.refinement=0.5", "--set",
            "modal.n_modes=20", "--out", str(out)]
    assert run(args) == 0
    comm.Barrier()
    with h5py.File(out / "modes.h5", "r") as f:
        freq = f["modes/frequency_hz"][()]
        assert int(f.attrs["complete"]) == 1
        assert f["mesh/nodal_mass"][()].min() >= 0
    comm.Barrier()                                  # every rank has read it before the rename
    if comm.rank == 0:
        (out / "modes.h5").rename(out / "modes_parallel.h5")
    comm.Barrier()
    # against the serial run (serial_refs), checked on rank 0; a failed check there is
    # broadcast so that the other ranks fail too instead of waiting at the barrier
    failure = None
    if comm.rank == 0:
        try:
            _compare_with_serial(coarse, serial_refs["modal_coarse_20_modes"], out, freq)
        except Exception as exc:                        # re-raised below on every rank
            failure = exc
    failure = comm.bcast(failure, root=0)
    if failure is not None:
        raise failure


def _compare_with_serial(coarse, serial, out, freq):
    """The serial run of the same case (in ``serial``): frequencies, mode subspaces and
    strain energies agree."""
    import h5py

    from railvib_hpc.modal.energy import material_groups
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble

    case = load_case(BASELINE, ["mesh.refinement=0.5", "modal.n_modes=20"])
    _, mesh = coarse
    dofmap = build_dofmap(mesh, 1)
    lam, phi_1, e_1 = modes_from_file(serial / "modes.h5", dofmap)
    lam_n, phi_n, e_n = modes_from_file(out / "modes_parallel.h5", dofmap)
    K, M, _ = assemble(mesh, Problem.from_case(case), dofmap, MPI.COMM_SELF)
    rtol = eigen_rtol(K, M, lam, solver_tol=case["modal.tol"], phi=phi_1)
    assert np.all(np.abs(lam_n / lam - 1) <= rtol)
    with h5py.File(serial / "modes.h5", "r") as f:
        assert np.all(np.abs(freq / f["modes/frequency_hz"][()] - 1) <= rtol)
    # mode shapes: the same subspace for every cluster of eigenvalues
    assert assert_same_subspaces(K, M, lam, phi_1, phi_n, rtol) >= 15
    # per-material strain energies: the same per mode (their sum is omega^2) and, summed
    # over each cluster, per material
    groups = [assemble(mesh, Problem.from_case(case), dofmap, MPI.COMM_SELF, parts=p, mass=False)[0]
              for p in material_groups(mesh).values()]
    assert np.all(np.abs(e_n.sum(axis=1) / e_1.sum(axis=1) - 1) <= rtol + 2 * (
        np.diag(tolerances.product_error(to_scipy(K), phi_1)) / lam))
    energy_tolerance(groups, K, M, lam, phi_1, phi_n, e_1, e_n, rtol)


@pytest.mark.slow
@pytest.mark.mpi
def test_incompatible_modes_and_out_of_core_equal_serial(coarse, monkeypatch):
    """Incompatible-modes hexahedra assembled on N ranks give the serial matrices and
    eigenvalues; with too little memory for the in-core factor (simulated), 'auto' factors
    out of core on every rank and still finds the serial eigenvalues."""
    init_petsc([])
    from petsc4py import PETSc

    from railvib_hpc.config import load_case
    from railvib_hpc.modal.eigen import solve_modes
    from railvib_hpc.model import factor
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble

    _, mesh = coarse
    case = load_case(BASELINE, ["mesh.refinement=0.5", "modal.hex_formulation=incompatible"])
    K1, M1, _ = assemble(mesh, Problem.from_case(case), build_dofmap(mesh, 1), MPI.COMM_SELF)
    KN, MN, _ = assemble(mesh, Problem.from_case(case), build_dofmap(mesh, comm.size), comm)
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

    monkeypatch.setattr(factor, "available_memory_gb", lambda c: 1.0)
    monkeypatch.setattr(factor.ShiftInvertFactor, "_estimate_factor_memory", estimate)
    parallel = solve_modes(KN, MN, comm, n_modes=10, tol=1e-10, out_of_core="auto")
    assert parallel.stats["out_of_core"] is True
    rtol = eigen_rtol(K1, M1, serial.eigenvalues, phi=serial.phi)
    assert np.all(np.abs(parallel.eigenvalues / serial.eigenvalues - 1) <= rtol)
    assert not PETSc.Options().hasName("railvib_eig_st_mat_mumps_icntl_22")
