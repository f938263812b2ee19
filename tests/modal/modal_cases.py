"""Small models for the modal tests, run through the real PETSc/SLEPc path."""

from __future__ import annotations

import numpy as np

from railvib_hpc.config import load_case
from railvib_hpc.mesh.model import Mesh
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
    from railvib_hpc.modal.dofmap import build_dofmap
    from railvib_hpc.modal.eigen import solve_modes
    from railvib_hpc.modal.petsc import assemble

    comm = comm or MPI.COMM_SELF
    dofmap = build_dofmap(mesh, comm.size, rules=rules)
    K, M, _ = assemble(mesh, case, dofmap, comm)
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
