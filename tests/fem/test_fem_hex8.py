"""Hexahedron kernels: elasticity matrix, patch test, rigid modes, mass, locking."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse.linalg as spla
from fem_tools import box_mesh, node_dofs, solid_matrices

from railvib_hpc.errors import UserError
from railvib_hpc.fem import (
    ElementGeometryError,
    assemble_vector,
    element_dofs,
    eliminate_dofs,
    hex8_lumped_mass_diagonal,
    hex8_mass,
    hex8_stiffness,
    hex8_strain_displacement,
    hex8_volume,
    isotropic_elasticity,
    isotropic_elasticity_batch,
)
from railvib_hpc.fem.hex8 import FORMULATIONS

EPS = np.finfo(float).eps


def distorted_box(n: int, amp: float, seed: int = 0):
    """n^3 hexes filling the unit cube; interior nodes moved randomly, face nodes moved
    within their faces (so the union is still exactly the unit cube)."""
    pts, hexes = box_mesh(n, n, n)
    rng = np.random.default_rng(seed)
    move = rng.uniform(-amp / n, amp / n, pts.shape)
    on_face = np.isclose(pts, 0.0) | np.isclose(pts, 1.0)
    move[on_face] = 0.0
    return pts + move, hexes


def test_isotropic_elasticity_inverse_is_compliance():
    E, nu = 3.0e7, 0.27
    G = E / (2 * (1 + nu))
    C = np.zeros((6, 6))
    C[:3, :3] = -nu / E
    C[np.arange(3), np.arange(3)] = 1 / E
    C[np.arange(3, 6), np.arange(3, 6)] = 1 / G
    D = isotropic_elasticity(E, nu)
    assert np.allclose(D @ C, np.eye(6), rtol=0, atol=100 * EPS)
    Db = isotropic_elasticity_batch(np.array([E, 2 * E]), np.array([nu, 0.1]))
    assert Db.shape == (2, 6, 6)
    assert np.array_equal(Db[0], D)
    assert np.allclose(Db[1], isotropic_elasticity(2 * E, 0.1))
    with pytest.raises(ValueError):
        isotropic_elasticity(E, 0.5)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_patch_test_distorted(formulation):
    """A linear displacement field gives constant strain and zero interior residual (for
    incompatible modes: the bubbles stay unloaded, thanks to Taylor's correction)."""
    bbar = formulation == "bbar"
    pts, hexes = distorted_box(3, amp=0.3)
    x = pts[hexes]
    # the patch is genuinely distorted: element Jacobians vary over the element
    _, wdet = hex8_strain_displacement(x, bbar)
    assert np.ptp(wdet, axis=1).max() > 0.1 * wdet.mean()
    rng = np.random.default_rng(1)
    grad_u = rng.normal(size=(3, 3)) * 1e-3
    u = (pts @ grad_u.T + rng.normal(size=3)).ravel()
    eps = np.array([grad_u[0, 0], grad_u[1, 1], grad_u[2, 2], grad_u[1, 2] + grad_u[2, 1],
                    grad_u[0, 2] + grad_u[2, 0], grad_u[0, 1] + grad_u[1, 0]])
    dofs = element_dofs(hexes, 3)
    B, _ = hex8_strain_displacement(x, bbar)
    strain = np.einsum("eqij,ej->eqi", B, u[dofs])
    assert np.allclose(strain, eps, rtol=0, atol=100 * EPS * np.abs(u).max() * 3 * 3)

    E, nu = 2.0e8, 0.3
    K, _ = solid_matrices(pts, hexes, E, nu, 1.0, formulation=formulation)
    r = K @ u
    interior = np.flatnonzero(np.all((pts > 1e-12) & (pts < 1 - 1e-12), axis=1))
    assert interior.size == 8
    # round-off of a sum over the 81 neighbour DOFs of each row
    tol = 81 * 10 * EPS * abs(K).max() * np.abs(u).max()
    assert np.abs(r[node_dofs(interior, [0, 1, 2], 3)]).max() < tol
    # strain energy = V eps^T D eps exactly (V = 1, the patch fills the unit cube); the
    # rigid translation is left out to avoid cancellation in u^T K u
    u_lin = (pts @ grad_u.T).ravel()
    energy = u_lin @ (K @ u_lin)
    exact = eps @ isotropic_elasticity(E, nu) @ eps
    assert energy == pytest.approx(exact, rel=1e-10)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_free_block_has_six_rigid_body_modes(formulation):
    pts, hexes = distorted_box(2, amp=0.2, seed=3)
    K, _ = solid_matrices(pts, hexes, 2.0e8, 0.3, 1850.0, formulation=formulation)
    Kd = K.toarray()
    # element matrices are exactly symmetric; assembly sums up to 8 of them per entry
    assert np.abs(Kd - Kd.T).max() <= 8 * EPS * abs(Kd).max()
    lam = la.eigvalsh(Kd)
    tol = Kd.shape[0] * EPS * lam[-1]          # round-off level of a dense eigensolver
    assert np.all(np.abs(lam[:6]) < tol)
    assert lam[6] > 1e6 * tol
    # the null space is spanned by the 3 translations and 3 infinitesimal rotations
    rigid = np.zeros((len(pts), 3, 6))
    rigid[:, [0, 1, 2], [0, 1, 2]] = 1.0
    for j, (a, b) in enumerate(((1, 2), (2, 0), (0, 1))):
        rigid[:, a, 3 + j] = -pts[:, b]
        rigid[:, b, 3 + j] = pts[:, a]
    rigid = rigid.reshape(-1, 6)
    assert np.abs(Kd @ rigid).max() < 10 * tol * np.abs(rigid).max()


def test_element_stiffness_symmetric_psd_and_batched():
    pts, hexes = distorted_box(2, amp=0.3, seed=5)
    x = pts[hexes]
    E = np.linspace(1e8, 3e8, len(x))
    nu = np.linspace(0.1, 0.45, len(x))
    for form in FORMULATIONS:
        Ke = hex8_stiffness(x, E, nu, formulation=form)
        assert Ke.shape == (8, 24, 24)
        assert np.array_equal(Ke, Ke.transpose(0, 2, 1))
        lam = np.linalg.eigvalsh(Ke)
        assert np.all(lam[:, :6] > -24 * EPS * lam[:, -1:])
        assert np.all(lam[:, 6] > 1e-6 * lam[:, -1])           # rank 18, no hourglass modes
        single = hex8_stiffness(x[3:4], E[3], nu[3], formulation=form)[0]
        assert np.allclose(single, Ke[3], rtol=0, atol=1e-12 * abs(single).max())


@pytest.mark.parametrize("bbar", [True, False])
def test_stiffness_equals_quadrature_of_btdb(bbar):
    """The gradient-form kernel equals sum_q w det J B^T D B with explicit (B-bar) B."""
    pts, hexes = distorted_box(2, amp=0.3, seed=11)
    x = pts[hexes]
    E = np.linspace(1e8, 3e8, len(x))
    nu = np.linspace(0.0, 0.4999, len(x))
    B, wdet = hex8_strain_displacement(x, bbar)
    D = isotropic_elasticity_batch(E, nu)
    ref = np.einsum("eq,eqki,ekl,eqlj->eij", wdet, B, D, B)
    K = hex8_stiffness(x, E, nu, bbar=bbar)
    assert np.allclose(K, ref, rtol=0, atol=100 * EPS * np.abs(ref).max(axis=(1, 2))[:, None, None])
    if bbar:   # B-bar: the dilatation is constant over each element
        vol = (B[:, :, 0] + B[:, :, 1] + B[:, :, 2])
        assert np.allclose(vol, vol[:, :1], rtol=0, atol=1e-12 * np.abs(vol).max())


def test_mass_totals_and_lumping():
    pts, hexes = distorted_box(3, amp=0.3, seed=7)
    x = pts[hexes]
    rho = 1850.0
    assert hex8_volume(x).sum() == pytest.approx(1.0, rel=1e-13)
    n = 3 * len(pts)
    _, M = solid_matrices(pts, hexes, 2e8, 0.3, rho)
    for d in range(3):
        ones = np.zeros(n)
        ones[d::3] = 1.0
        assert ones @ M @ ones == pytest.approx(rho, rel=1e-13)
        other = np.zeros(n)
        other[(d + 1) % 3::3] = 1.0
        assert abs(other @ M @ ones) < 1e-13 * rho
    Me = hex8_mass(x, rho)
    Ml = hex8_mass(x, rho, lumped=True)
    diag = hex8_lumped_mass_diagonal(x, rho)
    assert np.allclose(Me.sum(axis=2), diag, rtol=1e-14, atol=0)
    assert np.allclose(np.diagonal(Ml, axis1=1, axis2=2), diag, rtol=0, atol=0)
    assert np.count_nonzero(Ml) == diag.size
    assert np.all(diag > 0)
    total = assemble_vector(element_dofs(hexes, 3), diag, n)
    assert total[0::3].sum() == pytest.approx(rho, rel=1e-13)
    assert np.all(np.linalg.eigvalsh(Me) > 0)


def test_consistent_mass_exact_on_parallelepiped():
    """int N_a N_b dV = V/64 prod_i (1 + a_i b_i / 3) on a (sheared) parallelepiped."""
    ref = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                    [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)
    F = np.array([[2.0, 0.3, 0.1], [0.0, 1.5, 0.4], [0.2, 0.0, 0.7]])   # affine map
    x = ((ref + 1) / 2 @ F.T + np.array([5.0, -2.0, 1.0]))[None]
    V = np.linalg.det(F)
    assert hex8_volume(x)[0] == pytest.approx(V, rel=1e-14)
    rho = 7.0
    m_exact = rho * V / 64 * np.prod(1 + ref[:, None, :] * ref[None, :, :] / 3, axis=2)
    Me = hex8_mass(x, rho)[0]
    assert np.allclose(Me[0::3, 0::3], m_exact, rtol=1e-14, atol=0)
    assert np.allclose(Me[1::3, 2::3], 0.0, atol=0)


def test_inverted_element_raises_value_error_not_user_error():
    """Kernels raise a ValueError (ElementGeometryError); the stages make it a MeshError."""
    pts, hexes = box_mesh(1, 1, 1)
    inverted = pts[hexes[:, [4, 5, 6, 7, 0, 1, 2, 3]]]
    for kernel in (lambda x: hex8_stiffness(x, 1e8, 0.3), hex8_volume):
        with pytest.raises(ElementGeometryError, match="non-positive") as info:
            kernel(inverted)
        assert isinstance(info.value, ValueError)
        assert not isinstance(info.value, UserError)


def _cantilever_tip_ratio(nu: float, formulation: str, shape=(20, 2, 2)) -> float:
    """Clamped hex cantilever (10 x 1 x 1) with a uniform tip shear traction: tip
    deflection divided by Timoshenko beam theory PL^3/(3EI) + PL/(kGA), k = 5/6."""
    L, b, h = 10.0, 1.0, 1.0
    nx, ny, nz = shape
    pts, hexes = box_mesh(nx, ny, nz, L, b, h)
    E, P = 1.0e9, 1.0e3
    K, _ = solid_matrices(pts, hexes, E, nu, 1.0, formulation=formulation)
    root = np.flatnonzero(np.isclose(pts[:, 0], 0.0))
    tip = np.flatnonzero(np.isclose(pts[:, 0], L))
    # consistent nodal forces of a uniform traction on a bilinear face = tributary area
    y, z = pts[tip, 1], pts[tip, 2]
    wy = np.where(np.isclose(y, 0) | np.isclose(y, b), 0.5, 1.0) * b / ny
    wz = np.where(np.isclose(z, 0) | np.isclose(z, h), 0.5, 1.0) * h / nz
    f = np.zeros(K.shape[0])
    f[3 * tip + 2] = P * wy * wz / (b * h)
    Kr, _, free = eliminate_dofs(K, None, node_dofs(root, [0, 1, 2], 3))
    u = np.zeros(K.shape[0])
    u[free] = spla.spsolve(Kr.tocsc(), f[free])
    G, I = E / (2 * (1 + nu)), b * h**3 / 12
    return u[3 * tip + 2].mean() / (P * L**3 / (3 * E * I) + P * L / (5 / 6 * G * b * h))


def _pure_bending_ratio(nu: float, formulation: str, shape=(20, 2, 2)) -> float:
    """Hex beam (10 x 1 x 1) under a tip couple, root face a symmetry plane: tip
    deflection over the exact 3D (Saint-Venant) value M L^2 / (2 E I), independent of nu."""
    L, b, h = 10.0, 1.0, 1.0
    nx, ny, nz = shape
    pts, hexes = box_mesh(nx, ny, nz, L, b, h)
    E, Mo = 1.0e9, 1.0e3
    I = b * h**3 / 12
    K, _ = solid_matrices(pts, hexes, E, nu, 1.0, formulation=formulation)
    root = np.flatnonzero(np.isclose(pts[:, 0], 0.0))
    tip = np.flatnonzero(np.isclose(pts[:, 0], L))
    mid = root[np.isclose(pts[root, 2], h / 2)]
    a, c = mid[np.argmin(pts[mid, 1])], mid[np.argmax(pts[mid, 1])]
    fixed = np.r_[3 * root, 3 * a + 1, 3 * a + 2, 3 * c + 2]    # compatible with exact field
    # consistent nodal forces of sigma_xx = M (z - h/2) / I (linear in z, exact)
    z, y = pts[tip, 2], pts[tip, 1]
    hz = h / nz
    fz = np.zeros(len(tip))
    for k in range(nz):
        z0, z1 = k * hz, (k + 1) * hz
        s0, s1 = Mo * (z0 - h / 2) / I, Mo * (z1 - h / 2) / I
        fz += np.where(np.isclose(z, z0), hz * (2 * s0 + s1) / 6, 0.0)
        fz += np.where(np.isclose(z, z1), hz * (s0 + 2 * s1) / 6, 0.0)
    wy = np.where(np.isclose(y, 0) | np.isclose(y, b), 0.5, 1.0) * b / ny
    f = np.zeros(K.shape[0])
    f[3 * tip] = fz * wy
    Kr, _, free = eliminate_dofs(K, None, fixed)
    u = np.zeros(K.shape[0])
    u[free] = spla.spsolve(Kr.tocsc(), f[free])
    axis = tip[np.isclose(pts[tip, 2], h / 2)]
    return -u[3 * axis + 2].mean() / (Mo * L**2 / (2 * E * I))


def test_bbar_removes_volumetric_locking_pure_bending():
    """The exact pure-bending deflection does not depend on nu, so a locking-free element
    must give (nearly) the same answer at nu = 0.4999 as at nu = 0 on the same mesh:
    the change may not exceed the mesh's own discretisation error at nu = 0."""
    r0 = _pure_bending_ratio(0.0, "bbar")
    r5 = _pure_bending_ratio(0.4999, "bbar")
    assert abs(r5 - r0) <= abs(1 - r0)
    f0 = _pure_bending_ratio(0.0, "full")
    f5 = _pure_bending_ratio(0.4999, "full")
    assert abs(f5 - f0) > abs(1 - f0)      # full integration fails the same criterion


def test_bbar_cantilever_nearly_incompressible():
    """nu = 0.4999 tip-loaded clamped cantilever (20 x 2 x 2 hexes, L/h = 10).

    B-bar must stay close to beam theory: allowed deviation = this mesh's own error at
    nu = 0.3 (parasitic shear, measured) plus an allowance nu h / L (5 %) for the fully
    clamped root, whose restraint of the Poisson contraction beam theory ignores (an
    order-of-magnitude estimate, not a bound). Full integration must be stiffer by more
    than a factor 4 (its volumetric penalty scales with lambda / mu ~ 5000)."""
    rb = _cantilever_tip_ratio(0.4999, "bbar")
    rf = _cantilever_tip_ratio(0.4999, "full")
    r3 = _cantilever_tip_ratio(0.3, "bbar")
    assert 1 - rb <= (1 - r3) + 0.4999 * 1.0 / 10.0
    assert rf < rb / 4


@pytest.mark.parametrize("nu", [0.0, 0.25, 0.4999])
def test_incompatible_modes_bend_exactly(nu):
    """Pure bending of rectangular hexes is represented exactly by the incompatible-modes
    element (Wilson's bubbles carry the quadratic part of the deflection), so the tip
    deflection does not depend on the mesh: 5 and 20 elements along the beam agree to
    round-off, and at nu = 0 it is the exact M L^2 / (2 E I). The difference from it at
    nu > 0 (4e-4 at nu = 0.4999) is the Poisson (anticlastic) restraint of the
    symmetry-plane supports, the same for every mesh. Round-off grows with the
    conditioning lambda / mu."""
    coarse = _pure_bending_ratio(nu, "incompatible", shape=(5, 2, 2))
    fine = _pure_bending_ratio(nu, "incompatible", shape=(20, 2, 2))
    assert coarse == pytest.approx(fine, rel=1e-11 * (1 + 2 * nu / (1 - 2 * nu)))
    # round-off: the bending stiffness matrix of 20 elements has a condition number
    # ~ (L / h)^4 = 1e4 times the element one, times eps -> ~1e-11
    assert fine == pytest.approx(1.0, abs=1e-10 if nu == 0.0 else 1e-3)
    # B-bar needs the fine mesh and is still 2-3 % off (the coarse one 60 %)
    assert abs(1 - _pure_bending_ratio(nu, "bbar", shape=(5, 2, 2))) > 0.5


@pytest.mark.parametrize("n_along", [10, 20, 40])
def test_one_element_thick_cantilever(n_along):
    """A slab modelled one hexahedron thick (a 10 x 1 x 1 cantilever, 1 x 1 elements in
    the section): the incompatible-modes element stays within the shear-deflection
    discretisation error of Timoshenko theory (the tip load is a uniform traction, the
    root fully clamped: 1.5 %); B-bar, which averages the bending strain's dilatational
    part away, is far too soft (x1.2 - x2.1) and gets worse with finer meshes along the
    beam; full integration locks (x0.6 - x0.85)."""
    shape = (n_along, 1, 1)
    inc = _cantilever_tip_ratio(0.3, "incompatible", shape)
    assert abs(1 - inc) < 0.015
    assert _cantilever_tip_ratio(0.3, "bbar", shape) > 1.15
    assert _cantilever_tip_ratio(0.3, "full", shape) < 0.9
