"""The elastic operator of spectral hexahedra (:mod:`railvib_hpc.fem.spectral_kernel`): one
element against closed forms and independent constructions, the compiled kernel against
the array one, and the helpers (diagonal, energy, largest frequency, the update)."""

from __future__ import annotations

import numpy as np
import pytest
from fem_tools import box_mesh
from spectral_cases import LAM, MU, RHO, distorted_box

from railvib_hpc.fem.gll import derivative_matrix, gll_points, hex_interpolation
from railvib_hpc.fem.reference import ElementGeometryError
from railvib_hpc.fem.spectral_kernel import (
    LANES,
    add_forces_array,
    box_element_matrix,
    central_difference_update,
    element_matrices,
    energy,
    max_frequency_squared,
    spectral_elasticity,
    stiffness_diagonal,
)
from railvib_hpc.fem.spectral_mesh import corner_positions, spectral_mesh

#: Edges of the test box element (distinct, so that a swapped axis shows).
EDGES = (2.0, 1.0, 0.5)
#: The 1-D GLL matrices of an element of length h in closed form (exact integration of
#: the derivatives' products, the lumped mass on the nodes): N = 1 the linear element,
#: N = 2 the quadratic one with Simpson's weights.
CLOSED_FORM_1D = {
    1: (lambda h: np.array([[1.0, -1.0], [-1.0, 1.0]]) / h,
        lambda h: np.diag([1.0, 1.0]) * h / 2.0,
        np.array([[-0.5, 0.5], [-0.5, 0.5]])),
    2: (lambda h: np.array([[7.0, -8.0, 1.0], [-8.0, 16.0, -8.0], [1.0, -8.0, 7.0]]) / (3 * h),
        lambda h: np.diag([1.0, 4.0, 1.0]) * h / 6.0,
        np.diag([1 / 3, 4 / 3, 1 / 3]) @ np.array([[-1.5, 2, -0.5], [-0.5, 0, 0.5],
                                                   [0.5, -2, 1.5]])),
}


def _one_element(order, corners, geometry="auto"):
    sm = spectral_mesh(corners, np.arange(8)[None], [True], order)
    return sm, spectral_elasticity(order, sm.points, sm.elements, LAM, MU, RHO,
                                   geometry=geometry)


def _box_corners(edges=EDGES):
    points, hexes = box_mesh(1, 1, 1, *edges)
    return points[hexes[0]]


@pytest.mark.parametrize("order", (1, 2))
def test_element_matrix_is_the_kronecker_construction_of_closed_form_1d_matrices(order):
    stiff, mass, mixed = CLOSED_FORM_1D[order]
    _, w = gll_points(order)
    d = derivative_matrix(order)
    for h in EDGES:                         # the 1-D matrices themselves
        assert np.allclose(d.T @ np.diag(w) @ d * 2 / h, stiff(h), rtol=1e-14)
        assert np.allclose(np.diag(w) * h / 2, mass(h), rtol=1e-14)
    assert np.allclose(np.diag(w) @ d, mixed)
    k1, m1 = [stiff(h) for h in EDGES], [mass(h) for h in EDGES]

    def kron3(mats):
        return np.kron(mats[2], np.kron(mats[1], mats[0]))

    nq = (order + 1) ** 3
    s = np.empty((3, 3, nq, nq))
    for c in range(3):
        for e in range(3):
            mats = list(m1)
            mats[c], mats[e] = (k1[c], k1[c]) if c == e else (mixed.T, mixed)
            s[c, e] = kron3(mats)
    ref = np.zeros((nq, 3, nq, 3))
    for c in range(3):
        for e in range(3):
            ref[:, c, :, e] = LAM * s[c, e] + MU * s[e, c] + (MU * np.trace(s) if c == e else 0)
    ref = ref.reshape(3 * nq, 3 * nq)
    for geometry in ("box", "general"):
        _, op = _one_element(order, _box_corners(), geometry)
        kernel = element_matrices(op, geometry)[0]
        assert np.abs(kernel - ref).max() < 1e-13 * np.abs(ref).max()


def _dense_reference(order, x8):
    """``sum_q w_q det J_q B_q^T C B_q`` at the GLL points with the gradients of
    :func:`~railvib_hpc.fem.gll.hex_interpolation` (no sum factorisation)."""
    x, w = gll_points(order)
    n1 = order + 1
    a = np.arange(n1**3)
    ref = np.stack([x[a % n1], x[(a // n1) % n1], x[a // n1**2]], axis=1)
    wq = w[a % n1] * w[(a // n1) % n1] * w[a // n1**2]
    _, grad_ref = hex_interpolation(order, ref, derivatives=True)     # (q, a, 3)
    _, corner_grad = hex_interpolation(1, ref, derivatives=True)
    vtk = [0, 1, 3, 2, 4, 5, 7, 6]
    J = np.einsum("qci,cj->qij", corner_grad, x8[vtk])                # dx_j / dxi_i
    g = np.einsum("qji,qai->qaj", np.linalg.inv(J), grad_ref)
    wd = wq * np.linalg.det(J)
    k = (LAM * np.einsum("q,qac,qbd->acbd", wd, g, g)
         + MU * np.einsum("q,qad,qbc->acbd", wd, g, g)
         + MU * np.einsum("q,qak,qbk->ab", wd, g, g)[:, None, :, None] * np.eye(3)[None, :,
                                                                                   None, :])
    return k.reshape(3 * n1**3, 3 * n1**3)


@pytest.mark.parametrize("order", (1, 2, 3, 5))
def test_general_element_matches_dense_quadrature_and_box_the_tensor_form(order):
    rng = np.random.default_rng(order)
    corners = _box_corners() + rng.uniform(-0.1, 0.1, (8, 3))
    _, op = _one_element(order, corners)
    assert len(op.general_elements) == 1
    ref = _dense_reference(order, corners)
    assert np.abs(element_matrices(op, "general")[0] - ref).max() < 1e-13 * np.abs(ref).max()
    _, box = _one_element(order, _box_corners())
    tensor = box_element_matrix(order, EDGES, LAM, MU)
    assert np.abs(element_matrices(box, "box")[0] - tensor).max() < 1e-13 * np.abs(tensor).max()


@pytest.mark.parametrize("order", (1, 2, 4))
def test_six_rigid_body_modes_and_the_total_mass(order):
    """The mass is ``rho V`` exactly from order 2 on (the rule integrates ``det J``, of
    degree 2 per direction, exactly from ``2 N - 1 >= 2``); order 1 on a box."""
    rng = np.random.default_rng(10 + order)
    corners = _box_corners() + (rng.uniform(-0.1, 0.1, (8, 3)) if order > 1 else 0.0)
    _, op = _one_element(order, corners)
    k = element_matrices(op, "general" if order > 1 else "box")[0]
    eig = np.linalg.eigvalsh(k)
    assert np.sum(np.abs(eig) < 1e-10 * eig.max()) == 6
    assert eig[6] > 1e-6 * eig.max()
    from railvib_hpc.fem.reference import hex_volumes
    assert np.isclose(op.mass.sum(), RHO * hex_volumes(corners[None])[0], rtol=1e-13)
    assert op.mass.min() > 0


@pytest.mark.parametrize("order, amount", ((1, 0.0), (2, 0.2), (4, 0.2), (8, 0.2)))
def test_patch_test_linear_field_gives_no_inner_force(order, amount):
    """Order >= 2 on distorted hexahedra; order 1 (nodal quadrature, which does not integrate
    the trilinear map's cofactors exactly) on parallelepipeds (here boxes). The residual is
    round-off of the boundary forces (it grows with the order's conditioning). The orders
    of the compiled tests are 1, 2, 4, 8 (each order and geometry compiles once, ~1 s)."""
    points, hexes = distorted_box(3, amount=amount, seed=order)
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), order)
    op = spectral_elasticity(order, sm.points, sm.elements, LAM, MU, RHO)
    grad = np.array([[1.0, 0.3, -0.2], [0.1, -0.5, 0.4], [0.25, 0.2, 0.7]]) * 1e-3
    f = op.forces(sm.points @ grad.T + [0.1, 0.2, 0.3])
    inside = np.all((sm.points > 1e-9) & (sm.points < 1 - 1e-9), axis=1)
    assert np.abs(f[inside]).max() < 1e-10 * np.abs(f).max()


@pytest.mark.parametrize("order", (1, 4, 8))
def test_compiled_and_array_kernels_agree_to_round_off(order):
    """Box and general elements (a count that leaves the last SIMD block part-filled)."""
    points, hexes = distorted_box(3, amount=0.1, seed=order)
    keep = hexes[:LANES + 3] if len(hexes) > LANES + 3 else hexes
    sm = spectral_mesh(points, keep, np.ones(len(keep), bool), order)
    rng = np.random.default_rng(order)
    lam, mu = rng.uniform(1e7, 1e8, len(keep)), rng.uniform(1e7, 1e8, len(keep))
    u = rng.standard_normal((sm.n_nodes, 3))
    for geometry in ("auto", "general"):
        op = spectral_elasticity(order, sm.points, sm.elements, lam, mu, RHO,
                                 geometry=geometry)
        f1 = op.forces(u)
        f2 = np.zeros_like(u)
        add_forces_array(op, u, f2)
        assert np.abs(f1 - f2).max() <= 1e-13 * np.abs(f2).max()
    box_points, box_hexes = box_mesh(4, 3, 2, 2.0, 1.5, 1.0)
    sm = spectral_mesh(box_points, box_hexes, np.ones(len(box_hexes), bool), order)
    op = spectral_elasticity(order, sm.points, sm.elements, LAM, MU, RHO)
    assert len(op.general_elements) == 0 and len(op.box_table) == 1
    u = rng.standard_normal((sm.n_nodes, 3))
    f2 = np.zeros_like(u)
    add_forces_array(op, u, f2)
    assert np.abs(op.forces(u) - f2).max() <= 1e-13 * np.abs(f2).max()


def test_diagonal_energy_and_largest_frequency():
    points, hexes = distorted_box(2, amount=0.15)
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), 2)
    op = spectral_elasticity(2, sm.points, sm.elements, LAM, MU, RHO)
    size = 3 * sm.n_nodes
    K = np.stack([op.forces(np.eye(size)[i].reshape(-1, 3)).ravel() for i in range(size)])
    assert np.allclose(stiffness_diagonal(op).ravel(), np.diag(K), rtol=1e-12)
    rng = np.random.default_rng(0)
    u, v = rng.standard_normal((sm.n_nodes, 3)), rng.standard_normal((sm.n_nodes, 3))
    m = np.repeat(op.mass, 3)
    assert np.isclose(energy(op, u, v), 0.5 * u.ravel() @ K @ u.ravel()
                      + 0.5 * v.ravel() @ (m * v.ravel()), rtol=1e-12)
    exact = np.linalg.eigvalsh(K / np.sqrt(np.outer(m, m))).max()
    estimate = max_frequency_squared(op)
    assert 0.99 * exact <= estimate <= exact * (1 + 1e-12)


def test_closed_box_conserves_energy_over_many_steps():
    """Order 4, rollers on every face, 2000 central-difference steps at 0.9 of the stable
    step: the discrete energy ``1/2 v_(n+1/2).M v_(n+1/2) + 1/2 u_n.K u_(n+1)`` drifts at
    round-off."""
    points, hexes = box_mesh(2, 2, 2, 1.0, 0.8, 0.6)
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), 4)
    op = spectral_elasticity(4, sm.points, sm.elements, LAM, MU, RHO)
    free = np.ones((sm.n_nodes, 3))
    for d, length in enumerate((1.0, 0.8, 0.6)):
        free[(np.abs(sm.points[:, d]) < 1e-9) | (np.abs(sm.points[:, d] - length) < 1e-9), d] = 0
    inv = free / op.mass[:, None]
    dt = 0.9 * 2.0 / np.sqrt(max_frequency_squared(op, inv_mass=inv))
    rng = np.random.default_rng(2)
    u = 1e-4 * rng.standard_normal((sm.n_nodes, 3)) * free
    v = np.zeros_like(u)
    f = op.forces(u)
    mass = op.mass[:, None]
    energies = []
    for _ in range(2000):
        v_half = v - dt * inv * f                          # what the update does to v
        central_difference_update(u, v, f, inv, dt)        # f = 0 after
        assert np.abs(v - v_half).max() <= 1e-14 * np.abs(v_half).max()
        op.add_forces(u, f)                                 # K u_(n+1)
        energies.append(0.5 * np.vdot(v, mass * v) + 0.5 * np.vdot(u - dt * v, f))
    energies = np.array(energies)
    assert np.abs(energies / energies[0] - 1).max() < 1e-11


def test_bad_input_is_refused():
    sm, _ = _one_element(2, _box_corners())
    with pytest.raises(ValueError, match=r"must have shape \(ne, 64\)"):
        spectral_elasticity(3, sm.points, sm.elements, LAM, MU, RHO)
    inverted = _box_corners()[[4, 5, 6, 7, 0, 1, 2, 3]]
    s2 = spectral_mesh(inverted, np.arange(8)[None], [True], 2)
    with pytest.raises(ElementGeometryError, match="non-positive Jacobian"):
        spectral_elasticity(2, s2.points, s2.elements, LAM, MU, RHO)
    with pytest.raises(ValueError, match="not axis-aligned"):
        corners = _box_corners() + 0.05 * np.eye(8, 3)
        s3 = spectral_mesh(corners, np.arange(8)[None], [True], 2)
        spectral_elasticity(2, s3.points, s3.elements, LAM, MU, RHO, geometry="box")
    assert corner_positions(2).tolist() == [0, 2, 8, 6, 18, 20, 26, 24]
