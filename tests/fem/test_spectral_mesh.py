"""The spectral node set (:mod:`railvib_hpc.fem.spectral_mesh`): topological sharing, the
original nodes kept, and the coupling to trilinear hexahedra (consistency: the patch test
across the interface; stability: a conserved energy on a mixed mesh)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from fem_tools import box_mesh
from spectral_cases import LAM, MU, RHO, distorted_box

from railvib_hpc.fem import element_dofs, hex8_lumped_mass_diagonal, hex8_stiffness
from railvib_hpc.fem.gll import gll_points
from railvib_hpc.fem.reference import hex_shape_values
from railvib_hpc.fem.spectral_kernel import max_frequency_squared, spectral_elasticity
from railvib_hpc.fem.spectral_mesh import (
    condense_mass,
    corner_positions,
    prolongate,
    restrict,
    spectral_mesh,
)

E_HEX, NU_HEX = MU * (3 * LAM + 2 * MU) / (LAM + MU), LAM / (2 * (LAM + MU))


def _relabelled(points, hexes, seed=0):
    """The same mesh with its nodes numbered at random (the orientation of every edge and
    face changes)."""
    perm = np.random.default_rng(seed).permutation(len(points))
    return points[perm], np.argsort(perm)[hexes]


@pytest.mark.parametrize("order", (2, 3, 5))
def test_nodes_are_shared_by_topology_and_placed_by_the_trilinear_map(order):
    points, hexes = _relabelled(*distorted_box(3, amount=0.2))
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), order)
    assert sm.n_nodes == (3 * order + 1) ** 3                  # a structured grid's count
    assert np.array_equal(sm.points[:len(points)], points)     # originals kept
    assert np.array_equal(sm.elements[:, corner_positions(order)], hexes)
    x, _ = gll_points(order)
    n1 = order + 1
    a = np.arange(n1**3)
    ref = np.stack([x[a % n1], x[(a // n1) % n1], x[a // n1**2]], axis=1)
    mapped = np.einsum("qc,ecd->eqd", hex_shape_values(ref), points[hexes])
    assert np.abs(sm.points[sm.elements] - mapped).max() < 1e-14
    # no two nodes at one place: every shared GLL point got one number
    assert len(np.unique(np.round(sm.points, 9), axis=0)) == sm.n_nodes


def test_coincident_but_distinct_nodes_stay_apart():
    """Two blocks whose touching faces carry their own (coincident) nodes, as at the site
    mesh's ties: no spectral node is shared across them."""
    lower, hl = box_mesh(2, 2, 1)
    upper = lower + [0.0, 0.0, 1.0]
    points = np.vstack([lower, upper])
    hexes = np.vstack([hl, hl + len(lower)])
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), 3)
    first, second = sm.elements[:4].ravel(), sm.elements[4:].ravel()
    assert not set(first) & set(second)
    assert sm.n_nodes == 2 * 7 * 7 * 4


def test_mask_promotes_only_the_chosen_hexahedra_and_constrains_the_interface():
    points, hexes = box_mesh(2, 1, 1)
    sm = spectral_mesh(points, hexes, np.array([True, False]), 4)
    assert sm.hex_ids.tolist() == [0]
    # the shared face: 4 edges x 3 inner nodes + 9 face nodes
    assert len(sm.slaves) == 4 * 3 + 9
    assert np.allclose(sm.points[sm.slaves][:, 0], 0.5)      # the face between them
    assert np.allclose(sm.weights.sum(axis=1), 1.0)
    assert sm.weights.min() >= 0.0
    positions = np.einsum("sm,smd->sd", sm.weights, sm.points[sm.masters])
    assert np.abs(positions - sm.points[sm.slaves]).max() < 1e-15


def test_prolongation_and_restriction_are_adjoint():
    points, hexes = _relabelled(*distorted_box(2))
    promote = np.array([True, False] * 4)
    sm = spectral_mesh(points, hexes, promote, 3)
    rng = np.random.default_rng(3)
    u, f = rng.standard_normal((sm.n_nodes, 3)), rng.standard_normal((sm.n_nodes, 3))
    free = np.ones(sm.n_nodes, bool)
    free[sm.slaves] = False
    u[~free] = 0.0
    pu = prolongate(u.copy(), sm.slaves, sm.masters, sm.weights)
    rf = restrict(f.copy(), sm.slaves, sm.masters, sm.weights)
    assert np.isclose(np.vdot(pu, f), np.vdot(u, rf), rtol=1e-13)


def _mixed_system(order, seed=0, amount=0.15):
    """A 3 x 3 x 3 distorted box, the elements with centre x < 0.5 promoted: the reduced
    force ``f(u)`` (spectral kernel + assembled B-bar hex8, the constraints applied), the
    reduced lumped mass and the mesh."""
    points, hexes = _relabelled(*distorted_box(3, amount=amount, seed=seed), seed)
    promote = points[hexes].mean(axis=1)[:, 0] < 0.5
    sm = spectral_mesh(points, hexes, promote, order)
    op = spectral_elasticity(order, sm.points, sm.elements, LAM, MU, RHO)
    rest = hexes[~promote]
    ke = hex8_stiffness(points[rest], E_HEX, NU_HEX)
    dofs = element_dofs(rest, 3)
    rows = np.broadcast_to(dofs[:, :, None], ke.shape).ravel()
    cols = np.broadcast_to(dofs[:, None, :], ke.shape).ravel()
    k_hex = sp.coo_matrix((ke.ravel(), (rows, cols)), shape=(3 * sm.n_nodes,) * 2).tocsr()
    mass = op.mass.copy()
    np.add.at(mass, rest.ravel(), hex8_lumped_mass_diagonal(points[rest], RHO)[:, ::3].ravel())
    m_r = condense_mass(mass, sm.slaves, sm.masters, sm.weights)
    con = (sm.slaves, sm.masters, sm.weights)

    def forces(u):
        u = prolongate(u.copy(), *con)
        f = op.forces(u) + (k_hex @ u.ravel()).reshape(-1, 3)
        return restrict(f, *con)

    return sm, forces, m_r, mass


@pytest.mark.parametrize("order", (2, 4))
def test_patch_test_across_the_interface(order):
    """A linear field on a mixed order-N / trilinear mesh (distorted): zero force at every
    free node inside the box, on both sides and on the interface."""
    sm, forces, _, _ = _mixed_system(order)
    grad = np.array([[1.0, 0.3, -0.2], [0.1, -0.5, 0.4], [0.25, 0.2, 0.7]]) * 1e-3
    u = sm.points @ grad.T + [1e-3, 0.0, 2e-3]
    f = forces(u)
    inside = np.all((sm.points > 1e-9) & (sm.points < 1 - 1e-9), axis=1)
    inside[sm.slaves] = False
    scale = np.abs(f).max()                       # the boundary tractions
    assert scale > 0
    assert np.abs(f[inside]).max() < 1e-11 * scale


def test_the_reduced_mass_keeps_the_total_and_is_positive():
    sm, _, m_r, mass = _mixed_system(3)
    free = np.ones(sm.n_nodes, bool)
    free[sm.slaves] = False
    assert np.isclose(m_r[free].sum(), mass.sum(), rtol=1e-13)
    assert np.isclose(mass.sum(), RHO * 1.0, rtol=1e-12)      # the unit cube
    assert m_r[free].min() > 0


def test_mixed_mesh_conserves_the_discrete_energy():
    """Central differences on the reduced system of a mixed order-3 / trilinear mesh, free
    floating, from a random start: the discrete energy ``1/2 v.M v + 1/2 u_n.K u_(n+1)``
    holds to round-off over 600 steps at 0.8 of the stable step."""
    sm, forces, m_r, _ = _mixed_system(3)
    free = np.ones(sm.n_nodes, bool)
    free[sm.slaves] = False
    inv = np.where(free, 1.0 / m_r, 0.0)[:, None] * np.ones(3)

    class Reduced:                         # the operator interface of the power iteration
        n_nodes = sm.n_nodes

        @staticmethod
        def forces(u):
            return forces(u)

    top = max_frequency_squared(Reduced, inv_mass=inv)
    dt = 0.8 * 2.0 / np.sqrt(top)
    rng = np.random.default_rng(5)
    u = rng.standard_normal((sm.n_nodes, 3)) * 1e-4 * free[:, None]
    v = np.zeros_like(u)
    f = forces(u)
    energies = []
    for _ in range(600):
        v -= dt * inv * f
        u_new = u + dt * v
        f_new = forces(u_new)
        energies.append(0.5 * np.vdot(v, m_r[:, None] * v * free[:, None])
                        + 0.5 * np.vdot(u, f_new))
        u, f = u_new, f_new
    energies = np.array(energies)
    assert np.abs(energies / energies[0] - 1).max() < 1e-11
