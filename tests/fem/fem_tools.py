"""Mesh builders and small solvers shared by the FEM tests."""

from __future__ import annotations

import numpy as np

from railvib_hpc.fem import (
    assemble_matrix,
    beam_mass,
    beam_stiffness,
    element_dofs,
    hex8_mass,
    hex8_stiffness,
    shear_deformation_factors,
)

#: Corner offsets of a VTK hexahedron in (i, j, k) lattice steps.
HEX_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                        [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])


def box_mesh(nx: int, ny: int, nz: int, lx: float = 1.0, ly: float = 1.0, lz: float = 1.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """Structured hex mesh of [0, lx] x [0, ly] x [0, lz]; returns (points, hexes)."""
    gx, gy, gz = (np.linspace(0.0, ln, n + 1) for ln, n in ((lx, nx), (ly, ny), (lz, nz)))
    Z, Y, X = np.meshgrid(gz, gy, gx, indexing="ij")
    points = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)

    def node(i, j, k):
        return (k * (ny + 1) + j) * (nx + 1) + i

    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    ijk = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)
    c = ijk[:, None, :] + HEX_CORNERS[None]
    return points, node(c[..., 0], c[..., 1], c[..., 2])


def solid_matrices(points, hexes, E, nu, rho, bbar=True, lumped=False, formulation=None):
    """Assembled (K, M) of a hex mesh with 3 DOFs per node (``formulation`` overrides
    ``bbar``, see :func:`railvib_hpc.fem.hex8.hex8_stiffness`)."""
    x = points[hexes]
    dofs = element_dofs(hexes, 3)
    n = 3 * len(points)
    K = assemble_matrix(dofs, hex8_stiffness(x, E, nu, bbar=bbar, formulation=formulation), n)
    M = assemble_matrix(dofs, hex8_mass(x, rho, lumped=lumped), n)
    return K, M


def line_mesh(p0, p1, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n 2-node elements from p0 to p1; returns (points, lines)."""
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    points = (1 - t) * np.asarray(p0, float) + t * np.asarray(p1, float)
    return points, np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)


def beam_matrices(points, lines, sec, up=(0.0, 0.0, 1.0), rotary_inertia=True):
    """Assembled (K, M) of a beam line with 6 DOFs per node.

    ``sec`` holds E, G, A, Iyy, Izz, J, ky, kz, rho.
    """
    x = points[lines]
    s = sec
    K = beam_stiffness(x, s["E"], s["G"], s["A"], s["Iyy"], s["Izz"], s["J"], s["ky"], s["kz"],
                       up)
    py, pz = shear_deformation_factors(x, s["E"], s["G"], s["A"], s["Iyy"], s["Izz"], s["ky"],
                                       s["kz"])
    M = beam_mass(x, s["rho"], s["A"], s["Iyy"], s["Izz"], up, rotary_inertia, phi_y=py,
                  phi_z=pz)
    dofs = element_dofs(lines, 6)
    n = 6 * len(points)
    return assemble_matrix(dofs, K, n), assemble_matrix(dofs, M, n)


def node_dofs(nodes, comps, per_node: int) -> np.ndarray:
    """Global DOF indices of components ``comps`` of ``nodes``."""
    nodes = np.atleast_1d(nodes)
    return (per_node * nodes[:, None] + np.asarray(comps)[None, :]).ravel()


def frequency_rtol(K, M, f, computations: int = 2, solver_tol: float = 0.0,
                   rel_gap=np.inf) -> np.ndarray:
    """Relative tolerance for frequencies ``f`` (Hz) of the pencil (K, M).

    :func:`railvib_hpc.tolerances.eigenvalue_rtol` with the normwise condition
    ``lambda_max / lambda`` (round-off of a backward-stable solver). A frequency's relative
    error is half its eigenvalue's; the eigenvalue tolerance is used as it is (factor 2 of
    margin)."""
    from railvib_hpc import tolerances

    lam = (2 * np.pi * np.asarray(f, dtype=float)) ** 2
    cond = tolerances.normwise_condition(lam, tolerances.lambda_max(K, M))
    return tolerances.eigenvalue_rtol(cond, K.shape[0], solver_tol, rel_gap, computations)
