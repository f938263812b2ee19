"""Small models for the modal tests, run through the real PETSc/SLEPc path."""

from __future__ import annotations

import numpy as np

from railvib_hpc.config import load_case
from railvib_hpc.mesh.model import Mesh
from railvib_hpc.problem import Problem
from railvib_hpc.schema import PART_ID


def column_mesh(nz: int, height: float = 5.8, width: float = 0.1) -> Mesh:
    """A 1 x 1 x nz column of subgrade hexes, node sets 'bottom' and 'all'."""
    z = np.linspace(0.0, height, nz + 1)
    xy = np.array([[0, 0], [width, 0], [width, width], [0, width]], float)
    pts = np.concatenate([np.c_[xy, np.full(4, zk)] for zk in z])
    k = np.arange(nz)[:, None]
    hexes = np.hstack([4 * k + np.arange(4), 4 * (k + 1) + np.arange(4)])
    return Mesh(points=pts, hexes=hexes, hex_part=np.full(nz, PART_ID["subgrade"], np.int32),
                lines=np.zeros((0, 2), np.int64), line_part=np.zeros(0, np.int32),
                node_sets={"bottom": np.arange(4)})


def block_mesh(n: int, height: float = 8.0, width: float = 2.0) -> Mesh:
    """An n x n x 2n block of subgrade hexes, node set 'bottom' (its base)."""
    from fem_tools import box_mesh

    pts, hexes = box_mesh(n, n, 2 * n, width, width, height)
    return Mesh(points=pts, hexes=hexes, hex_part=np.full(len(hexes), PART_ID["subgrade"],
                                                          np.int32),
                lines=np.zeros((0, 2), np.int64), line_part=np.zeros(0, np.int32),
                node_sets={"bottom": np.flatnonzero(pts[:, 2] == 0.0)})


def beam_mesh(n: int, length: float, part: str = "rail") -> Mesh:
    """A straight beam along x, n elements, node sets 'start', 'end'."""
    pts = np.c_[np.linspace(0.0, length, n + 1), np.zeros(n + 1), np.zeros(n + 1)]
    lines = np.c_[np.arange(n), np.arange(1, n + 1)]
    return Mesh(points=pts, hexes=np.zeros((0, 8), np.int64), hex_part=np.zeros(0, np.int32),
                lines=lines, line_part=np.full(n, PART_ID[part], np.int32),
                node_sets={"start": np.array([0]), "end": np.array([n])})


def soil_case(**extra):
    """Thesis case (soil E 200 MPa, nu 0.2, rho 1850) with extra overrides."""
    return load_case(None, [f"{k}={v}" for k, v in extra.items()])


def solve(mesh: Mesh, case, rules, n_modes: int, comm=None, method="block_lanczos",
          f_max: float = 0.0, block_size: int = 8, out_of_core: str = "auto"):
    """Assemble with PETSc on ``comm`` and extract modes; returns (result, K, M, dofmap)."""
    from mpi4py import MPI

    from railvib_hpc.petsc_env import init_petsc

    init_petsc([])
    from railvib_hpc.modal.eigen import solve_modes
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble

    comm = comm or MPI.COMM_SELF
    dofmap = build_dofmap(mesh, comm.size, rules=rules)
    K, M, _ = assemble(mesh, Problem.from_case(case), dofmap, comm)
    result = solve_modes(K, M, comm, n_modes=n_modes, f_max=f_max, method=method,
                         block_size=block_size, tol=1e-10, out_of_core=out_of_core)
    return result, K, M, dofmap


def strip_mesh(nx: int, length: float, width: float, thickness: float,
               part: str = "slab") -> Mesh:
    """A concrete strip of nx x 1 x 1 hexahedra (one element across and through the
    thickness) along x; node sets 'root' (x = 0) and 'all'."""
    from fem_tools import box_mesh

    pts, hexes = box_mesh(nx, 1, 1, length, width, thickness)
    return Mesh(points=pts, hexes=hexes, hex_part=np.full(nx, PART_ID[part], np.int32),
                lines=np.zeros((0, 2), np.int64), line_part=np.zeros(0, np.int32),
                node_sets={"root": np.flatnonzero(np.isclose(pts[:, 0], 0.0))})


def to_scipy(A):
    """A serial PETSc AIJ matrix as scipy CSR (for reference computations); a scipy sparse
    matrix as it is (CSR)."""
    import scipy.sparse as sp

    if sp.issparse(A):
        return sp.csr_matrix(A)
    ip, ix, v = A.getValuesCSR()
    n, m = A.getSize()
    return sp.csr_matrix((v, ix, ip), shape=(n, m))


def eigen_rtol(K, M, lam, solver_tol: float = 1e-10, computations: int = 2, phi=None):
    """Relative tolerance for comparing the eigenvalues ``lam`` of the serial PETSc pencil
    (K, M) computed ``computations`` times (:mod:`railvib_hpc.tolerances`).

    Round-off ``sqrt(n) u cond_i`` plus the Kato-Temple term ``tol^2 / relgap`` of a solver
    stopped at the relative residual ``solver_tol``, with the gap of each eigenvalue's
    cluster (eigenvalues closer than their round-off form one cluster). ``cond``: normwise
    ``lambda_max / lambda`` (any backward-stable solver), or, given the M-normalised modes
    ``phi``, componentwise (eigenvalues that are Rayleigh quotients of the computed vectors,
    as block Lanczos's final Rayleigh-Ritz step makes them, of matrices that differ
    componentwise, as on 1 and N ranks) plus ``max(lam) / lam`` for the dense projected
    eigenproblem.
    """
    from railvib_hpc import tolerances

    lam = np.asarray(lam, dtype=float)
    Ks, Ms = to_scipy(K), to_scipy(M)
    if phi is None:
        cond = tolerances.normwise_condition(lam, tolerances.lambda_max(Ks, Ms))
    else:
        cond = tolerances.componentwise_condition(Ks, phi, lam) + lam.max() / np.abs(lam)
    n = Ks.shape[0]
    roundoff = tolerances.eigenvalue_rtol(cond, n, computations=computations)
    gaps = tolerances.cluster_gaps(lam, roundoff)
    return tolerances.eigenvalue_rtol(cond, n, solver_tol, gaps, computations)


def residual_floors(K, M, phi: np.ndarray, lam) -> np.ndarray:
    """The round-off floor of every mode's relative residual, as
    :func:`railvib_hpc.modal.ritz.normalise_and_check` defines it (which forms it only for
    the modes above the tolerance): ``gamma_k || |K| |phi| + |lambda| |M| |phi| || /
    ||K phi||``, k = longest row + 1 (the error bound of evaluating ``K phi - lambda M phi``
    in double precision; Higham 2002, §3.5). Serial PETSc K, M."""
    from railvib_hpc import tolerances

    Ks, Ms = to_scipy(K), to_scipy(M)
    lam = np.asarray(lam, dtype=float)
    k = max(int(np.diff(A.indptr).max(initial=0)) for A in (Ks, Ms)) + 1
    P = np.abs(phi)
    bound = abs(Ks) @ P + (abs(Ms) @ P) * np.abs(lam)
    return tolerances.gamma(k) * np.linalg.norm(bound, axis=0) / np.linalg.norm(Ks @ phi,
                                                                                 axis=0)


def assert_accepted_by_the_verdict(res, tol: float = 1e-10) -> None:
    """Every mode of ``res`` is in a class that :func:`railvib_hpc.modal.ritz.convergence_verdict`
    accepts (converged; limited by round-off, ``rho <= tol + floor``; or, after the retry,
    ``rho <= RETRY_TOL_FACTOR * tol``), and every mode above ``tol`` is reported in the
    result's warnings, the last class by its own warning.

    Which accepted class a pair falls in is not pinned: the solver's stopping test is on the
    shift-inverted operator, so the true residual of a pair it returns moves with the
    rounding of the whole Lanczos run, not only of the residual's evaluation. Measured on the
    60-element column's two-band merge at ``tol = 1e-10``: 1.549e-10 against ``tol + floor``
    = 1.41e-10 with OpenBLAS on two threads (native and SkylakeX kernels), within ``tol +
    floor`` on one thread and with Haswell's kernel. (Was ``rho <= tol + floor``, which
    passed or failed by the BLAS thread count; before that ``max(tol, floor)``, which
    passed or failed by the OpenBLAS kernel.)"""
    from railvib_hpc.modal.ritz import hopeless

    res_, floors = res.residuals, res.residual_floors
    bad = hopeless(res, tol)
    assert not bad.any(), (np.flatnonzero(bad), res_[bad], floors[bad])
    if (res_ > tol).any():
        assert res.warnings, (res_.max(), "a mode above tol with no warning")
    if (res_ > tol + floors).any():
        assert any("end with a relative residual above" in w for w in res.warnings), \
            res.warnings


def assert_same_subspaces(K, M, lam, phi_a, phi_b, rtol) -> int:
    """Each cluster of eigenvalues (closer than ``rtol``) spans the same subspace in both
    solutions: the principal angles are at most the sum of their Davis-Kahan bounds
    (measured residuals / gap to the neighbouring clusters). The last cluster is skipped
    (its gap to the next, uncomputed eigenvalue is unknown). Returns the clusters checked.
    """
    from railvib_hpc import tolerances

    Ks, Ms = to_scipy(K), to_scipy(M)
    lam = np.asarray(lam, dtype=float)
    res_a = tolerances.residual_norms(Ks, Ms, phi_a, lam)
    res_b = tolerances.residual_norms(Ks, Ms, phi_b, lam)
    labels = tolerances.clusters(lam, rtol)
    checked = 0
    for c in np.unique(labels)[:-1]:
        idx = np.flatnonzero(labels == c)
        lo = lam[idx[0] - 1] if idx[0] > 0 else -np.inf
        gap = min(lam[idx[0]] - lo, lam[idx[-1] + 1] - lam[idx[-1]])
        bound = tolerances.davis_kahan(res_a[idx], gap) + tolerances.davis_kahan(res_b[idx], gap)
        sines = tolerances.subspace_sines(phi_a[:, idx], phi_b[:, idx], Ms)
        assert sines.max() <= bound, (c, sines.max(), bound)
        checked += 1
    return checked


def modes_from_file(path, dofmap) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eigenvalues, the (n_dofs, m) mode matrix in ``dofmap``'s numbering and the strain
    energies (m, groups) read back from ``modes.h5``."""
    import h5py

    with h5py.File(path, "r") as f:
        lam = f["modes/eigenvalue"][()]
        trans = f["modes/translation"][()]
        rot = f["modes/rotation"][()]
        rot_nodes = f["mesh/rotation_nodes"][()]
        energy = f["modes/strain_energy"][()]
    phi = np.zeros((dofmap.n_dofs, len(lam)))
    for comps, values, nodes in ((slice(0, 3), trans, np.arange(trans.shape[1])),
                                 (slice(3, 6), rot, rot_nodes)):
        idx = dofmap.index[nodes, comps]
        ok = idx >= 0
        phi[idx[ok]] = values[:, ok].T
    return lam, phi, energy


def energy_tolerance(groups, K, M, lam, phi_a, phi_b, e_a, e_b, rtol) -> np.ndarray:
    """Allowed difference of per-material strain energies ``e = phi^T K_g phi`` (m, g) of
    two solutions, per cluster of eigenvalues (``rtol``), excluding the last cluster.

    Within a cluster only the sum over its modes is defined (a trace over the invariant
    subspace). For bases whose principal angles to the exact subspace have ``||sin||_F <=
    s`` (Davis-Kahan, measured residuals), ``|trace(Phi~^T A Phi~) - trace(Phi^T A Phi)| <=
    2 sqrt(T a) s + 2 a s^2`` with ``T`` the trace and ``a = lambda_max(K_g, M) <=
    lambda_max(K, M)`` (K_g <= K), plus the round-off of the products, ``gamma_k |phi|^T
    |K_g| |phi|``. Returns (n_clusters - 1, g) bounds and asserts them.
    """
    from railvib_hpc import tolerances

    Ks, Ms = to_scipy(K), to_scipy(M)
    a = tolerances.lambda_max(Ks, Ms)
    res = [tolerances.residual_norms(Ks, Ms, p, lam) for p in (phi_a, phi_b)]
    labels = tolerances.clusters(lam, rtol)
    rounds = [np.stack([np.diag(tolerances.product_error(to_scipy(Kg), p, computations=1))
                        for Kg in groups], axis=1) for p in (phi_a, phi_b)]
    out = []
    for c in np.unique(labels)[:-1]:
        idx = np.flatnonzero(labels == c)
        lo = lam[idx[0] - 1] if idx[0] > 0 else -np.inf
        gap = min(lam[idx[0]] - lo, lam[idx[-1] + 1] - lam[idx[-1]])
        bound = 0.0
        for r, e, ro in zip(res, (e_a, e_b), rounds):
            s = tolerances.davis_kahan(r[idx], gap)
            T = e[idx].sum(axis=0)
            bound = bound + 2 * np.sqrt(np.abs(T) * a) * s + 2 * a * s**2 + ro[idx].sum(axis=0)
        diff = np.abs(e_a[idx].sum(axis=0) - e_b[idx].sum(axis=0))
        assert np.all(diff <= bound), (c, diff, bound)
        out.append(bound)
    return np.array(out)


def energy_sum_allowance(mesh, case, dofmap, phi, comm=None):
    """Round-off allowances of the per-material strain energies ``E_ig = phi_i^T K_g phi_i``
    (:mod:`railvib_hpc.tolerances`, ``product_error``).

    Returns ``(per_group, total)``: (m, g) allowances of each group's energy (how far below
    0 a PSD group may appear) and (m,) of ``sum_g E_ig - lambda_i`` — the groups' products
    and the Rayleigh quotient ``phi^T K phi`` that makes ``lambda`` (two computations).
    """
    from mpi4py import MPI

    from railvib_hpc import tolerances
    from railvib_hpc.modal.energy import material_groups
    from railvib_hpc.model.petsc import assemble

    comm = comm or MPI.COMM_SELF
    per_group = []
    for parts in material_groups(mesh).values():
        Kg = assemble(mesh, Problem.from_case(case), dofmap, comm, parts=parts, mass=False)[0]
        per_group.append(np.diag(tolerances.product_error(to_scipy(Kg), phi, computations=1)))
        Kg.destroy()
    K = assemble(mesh, Problem.from_case(case), dofmap, comm, mass=False)[0]
    whole = np.diag(tolerances.product_error(to_scipy(K), phi))
    per_group = np.stack(per_group, axis=1)
    return per_group, per_group.sum(axis=1) + whole


def write_msh(mesh: Mesh, path, node_sets: bool = False) -> None:
    """Write ``mesh`` as a gmsh .msh with one physical group per part present (and the node
    sets as physical groups of points when ``node_sets``), like a user's own mesh."""
    from railvib_hpc.mesh.gmsh_model import gmsh_session
    from railvib_hpc.schema import PARTS

    with gmsh_session() as gmsh:
        gmsh.model.add("user")
        gmsh.model.addDiscreteEntity(0, 1)
        tags = np.arange(1, mesh.n_nodes + 1)
        gmsh.model.mesh.addNodes(0, 1, tags.tolist(), mesh.points.ravel().tolist())
        first = 1
        for part in PARTS:
            for conn, etype, dim in ((mesh.hexes[mesh.hex_part == PART_ID[part]], 5, 3),
                                     (mesh.lines[mesh.line_part == PART_ID[part]], 1, 1)):
                if len(conn) == 0:
                    continue
                ent = gmsh.model.addDiscreteEntity(dim)
                gmsh.model.mesh.addElementsByType(
                    ent, etype, list(range(first, first + len(conn))), (conn + 1).ravel().tolist())
                first += len(conn)
                gmsh.model.addPhysicalGroup(dim, [ent], PART_ID[part], name=part)
        if node_sets:
            for k, (name, nodes) in enumerate(mesh.node_sets.items()):
                ent = gmsh.model.addDiscreteEntity(0)
                gmsh.model.mesh.addElementsByType(ent, 15, list(range(first, first + len(nodes))),
                                                  (np.asarray(nodes) + 1).tolist())
                first += len(nodes)
                gmsh.model.addPhysicalGroup(0, [ent], 100 + k, name=name)
        gmsh.write(str(path))


def solve_banded(mesh: Mesh, case, rules, f_max: float, cache_dir, comm=None, edges=(),
                 band_modes: int = 250, groups: int = 1, band_only: int = 0,
                 block_size: int = 8, tol: float = 1e-10, log=None):
    """Band-sliced solve of the model on ``comm`` (cache in ``cache_dir``; ``log`` gets a
    line per band); returns (result, K, M, dofmap)."""
    from pathlib import Path

    from mpi4py import MPI

    from railvib_hpc.petsc_env import init_petsc

    init_petsc([])
    from railvib_hpc.modal.band_solve import BandSettings
    from railvib_hpc.modal.eigen import solve_modes
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble

    comm = comm or MPI.COMM_SELF
    dofmap = build_dofmap(mesh, comm.size, rules=rules)
    problem = Problem.from_case(case)
    K, M, _ = assemble(mesh, problem, dofmap, comm)

    def on(sub):
        return assemble(mesh, problem, build_dofmap(mesh, sub.size, rules=rules), sub)[:2]

    index, prov = _band_cache(Path(cache_dir), comm)
    s = BandSettings(f_max=f_max, edges=list(edges), band_modes=band_modes, groups=groups,
                     band_only=band_only, tol=tol, block_size=block_size, max_restarts=100,
                     out_of_core="auto", cache_dir=Path(cache_dir), index=index,
                     provenance=prov)
    result = solve_modes(K, M, comm, f_max=f_max, tol=tol, block_size=block_size, bands=s,
                         assemble=on, log=log)
    return result, K, M, dofmap


def _band_cache(cache_dir, comm) -> tuple[dict | None, dict]:
    """The band cache in ``cache_dir`` as the modal stage reuses it (the product layer, with
    the inputs digest "test" instead of a case's), and the provenance to write it with."""
    from railvib_hpc.io.files import BAND_CACHE
    from railvib_hpc.io.formats.bands import index_path, read_index
    from railvib_hpc.io.stage_protocol import StageContext

    index = prov = None
    if comm.rank == 0:
        ctx, path = StageContext(None, cache_dir.parent), index_path(cache_dir)
        index = ctx.reuse(BAND_CACHE, path=path, inputs_sha256="test",
                          accept=lambda verdict: read_index(path)).value
        prov = ctx.provenance(BAND_CACHE, {}, inputs_sha256="test")
    return comm.bcast((index, prov), root=0)


def copies(mesh: Mesh, n: int, dx: float) -> Mesh:
    """``n`` disconnected copies of ``mesh`` side by side along x: every eigenvalue of the
    mesh becomes an n-fold one (a planted cluster)."""
    pts = np.concatenate([mesh.points + [k * dx, 0.0, 0.0] for k in range(n)])
    off = mesh.n_nodes
    return Mesh(points=pts, hexes=np.concatenate([mesh.hexes + k * off for k in range(n)]),
                hex_part=np.tile(mesh.hex_part, n),
                lines=np.concatenate([mesh.lines + k * off for k in range(n)]),
                line_part=np.tile(mesh.line_part, n),
                node_sets={k: np.concatenate([v + j * off for j in range(n)])
                           for k, v in mesh.node_sets.items()})
