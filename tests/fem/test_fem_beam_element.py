"""Timoshenko beam element: static exactness, shape functions, mass, frames."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import polynomial as P

from railvib_hpc.fem import (
    beam_frames,
    beam_mass,
    beam_stiffness,
    beam_transformation,
    shear_deformation_factors,
)
from railvib_hpc.fem.beam import (
    beam_mass_local,
    beam_stiffness_local,
    timoshenko_shape_functions,
)
from railvib_hpc.fem.quadrature import gauss_legendre

EPS = np.finfo(float).eps
# UIC-like rail with deliberately different properties in the two planes
SEC = dict(E=210e9, G=210e9 / 2.6, A=64.5e-4, Iyy=2010e-8, Izz=326e-8, J=2.59e-6,
           ky=0.34, kz=0.5, rho=7700.0)
P0 = np.array([1.0, -2.0, 0.5])
AXIS = np.array([0.6, 0.48, 0.64])          # unit vector, skew element
UP = np.array([0.1, -0.3, 1.0])


def skew_element(L: float):
    x = np.stack([P0, P0 + L * AXIS])[None]
    _, R = beam_frames(x, UP)
    return x, R[0]


def tip_response(L: float, load_local: np.ndarray) -> np.ndarray:
    """Local tip DOFs of a single cantilever element under a local tip load (6,)."""
    x, R = skew_element(L)
    s = SEC
    K = beam_stiffness(x, s["E"], s["G"], s["A"], s["Iyy"], s["Izz"], s["J"], s["ky"],
                       s["kz"], UP)[0]
    f = np.r_[R.T @ load_local[:3], R.T @ load_local[3:]]
    u = np.linalg.solve(K[6:, 6:], f)
    return np.r_[R @ u[:3], R @ u[3:]]


def test_frames_are_orthonormal_and_follow_up():
    x, R = skew_element(2.0)
    assert np.allclose(R @ R.T, np.eye(3), atol=10 * EPS)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert np.allclose(R[0], AXIS)
    assert R[1] @ UP > 0 and abs(R[2] @ UP) < 10 * EPS
    with pytest.raises(ValueError):
        beam_frames(x, AXIS)


@pytest.mark.parametrize("L", [0.3, 2.0])
def test_single_element_cantilever_is_exact(L):
    """One element, clamped at node 0: exact Timoshenko tip response to end loads."""
    s = SEC
    E, G, A = s["E"], s["G"], s["A"]
    Pf, T = 1.0e4, 3.0e2
    # shear force along y' (bending with Iyy, ky): rotation about +z'
    u = tip_response(L, np.array([0, Pf, 0, 0, 0, 0.0]))
    exact = Pf * L**3 / (3 * E * s["Iyy"]) + Pf * L / (s["ky"] * G * A)
    assert u[1] == pytest.approx(exact, rel=1e-11)
    assert u[5] == pytest.approx(Pf * L**2 / (2 * E * s["Iyy"]), rel=1e-11)
    assert np.allclose(u[[0, 2, 3, 4]], 0.0, atol=1e-11 * exact)
    # shear force along z' (Izz, kz): rotation about -y'
    u = tip_response(L, np.array([0, 0, Pf, 0, 0, 0.0]))
    exact = Pf * L**3 / (3 * E * s["Izz"]) + Pf * L / (s["kz"] * G * A)
    assert u[2] == pytest.approx(exact, rel=1e-11)
    assert u[4] == pytest.approx(-Pf * L**2 / (2 * E * s["Izz"]), rel=1e-11)
    # axial force, torque, end moment
    u = tip_response(L, np.array([Pf, 0, 0, T, 0, T]))
    assert u[0] == pytest.approx(Pf * L / (E * A), rel=1e-11)
    assert u[3] == pytest.approx(T * L / (G * s["J"]), rel=1e-11)
    assert u[5] == pytest.approx(T * L / (E * s["Iyy"]), rel=1e-11)
    assert u[1] == pytest.approx(T * L**2 / (2 * E * s["Iyy"]), rel=1e-11)


def _cubic_derivative(values: np.ndarray, s: np.ndarray, L: float) -> np.ndarray:
    """d/dx of cubic shape functions sampled at >= 4 points s (values (q, 4))."""
    c = P.polyfit(s, values, 3)
    return P.polyval(s, P.polyder(c)).T / L


def test_shape_functions_reproduce_stiffness_and_mass():
    """Energy of the interdependent shape functions = closed-form stiffness; their
    consistent mass = the closed form of Friedman & Kosmatka (1993)."""
    L, EI, phi = 0.7, 3.0, 0.8
    kGA = 12 * EI / (phi * L**2)
    p, w = gauss_legendre(6)
    s, w = (p + 1) / 2, w / 2
    Nv, Np = (a[0] for a in timoshenko_shape_functions(s, [L], [phi]))
    dNv, dNp = _cubic_derivative(Nv, s, L), _cubic_derivative(Np, s, L)
    gamma = dNv - Np
    assert np.allclose(gamma, gamma[0], atol=1e-12)       # constant shear strain
    K = L * (EI * np.einsum("q,qa,qb->ab", w, dNp, dNp)
             + kGA * np.einsum("q,qa,qb->ab", w, gamma, gamma))
    Kl = beam_stiffness_local([L], 1.0, 1.0, 1.0, EI, 1.0, 1.0, 12 * EI / (phi * L**2), 1.0)
    idx = np.array([1, 5, 7, 11])
    assert np.allclose(K, Kl[0][np.ix_(idx, idx)], rtol=0, atol=1e-11 * abs(K).max())

    f = phi
    ma = np.array([[70 * f * f + 147 * f + 78, (35 * f * f + 77 * f + 44) * L / 4,
                    35 * f * f + 63 * f + 27, -(35 * f * f + 63 * f + 26) * L / 4],
                   [0, (7 * f * f + 14 * f + 8) * L**2 / 4, (35 * f * f + 63 * f + 26) * L / 4,
                    -(7 * f * f + 14 * f + 6) * L**2 / 4],
                   [0, 0, 70 * f * f + 147 * f + 78, -(35 * f * f + 77 * f + 44) * L / 4],
                   [0, 0, 0, (7 * f * f + 14 * f + 8) * L**2 / 4]]) * L / (210 * (1 + f) ** 2)
    mi = np.array([[36, -(15 * f - 3) * L, -36, -(15 * f - 3) * L],
                   [0, (10 * f * f + 5 * f + 4) * L**2, (15 * f - 3) * L,
                    (5 * f * f - 5 * f - 1) * L**2],
                   [0, 0, 36, (15 * f - 3) * L],
                   [0, 0, 0, (10 * f * f + 5 * f + 4) * L**2]]) / (30 * (1 + f) ** 2 * L)
    ma, mi = (np.triu(m) + np.triu(m, 1).T for m in (ma, mi))
    rhoA, rhoI = 2.0, 0.3
    Ml = beam_mass_local([L], 1.0, rhoA, rhoI, 1.0, True, phi_y=phi)[0]
    assert np.allclose(Ml[np.ix_(idx, idx)], rhoA * ma + rhoI * mi, rtol=0, atol=1e-14)
    # phi = 0: classical Hermite mass rho A L / 420 [156, 22L, 54, -13L; ...]
    M0 = beam_mass_local([L], 1.0, 1.0, 0.0, 0.0, False)[0][np.ix_(idx, idx)]
    assert M0[0, 0] == pytest.approx(156 * L / 420)
    assert M0[0, 1] == pytest.approx(22 * L**2 / 420)
    assert M0[0, 3] == pytest.approx(-13 * L**2 / 420)
    assert M0[1, 3] == pytest.approx(-3 * L**3 / 420)


def rigid_fields(x: np.ndarray) -> np.ndarray:
    """The 6 rigid-body motions of a 2-node element, (12, 6)."""
    r = np.zeros((2, 6, 6))
    for a in range(2):
        r[a, :3, :3] = np.eye(3)
        r[a, 3:, 3:] = np.eye(3)
        px, py, pz = x[a]
        r[a, :3, 3:] = np.array([[0, pz, -py], [-pz, 0, px], [py, -px, 0]])
    return r.reshape(12, 6)


def test_rigid_modes_mass_and_symmetry():
    L = 1.3
    x, R = skew_element(L)
    s = SEC
    K = beam_stiffness(x, s["E"], s["G"], s["A"], s["Iyy"], s["Izz"], s["J"], s["ky"],
                       s["kz"], UP)[0]
    py, pz = shear_deformation_factors(x, s["E"], s["G"], s["A"], s["Iyy"], s["Izz"],
                                       s["ky"], s["kz"])
    M = beam_mass(x, s["rho"], s["A"], s["Iyy"], s["Izz"], UP, phi_y=py, phi_z=pz)[0]
    for A_ in (K, M):
        assert np.array_equal(A_, A_.T)
    lam = np.linalg.eigvalsh(K)
    assert np.all(np.abs(lam[:6]) < 12 * EPS * lam[-1] * 10)
    assert lam[6] > 1e-8 * lam[-1]
    r = rigid_fields(x[0] - x[0, 0])
    assert np.abs(K @ r).max() < 1e-12 * abs(K).max()
    assert np.all(np.linalg.eigvalsh(M) > 0)
    rho, A = s["rho"], s["A"]
    # rigid translation: total mass; rigid rotations about the axes through node 0
    Mr = r.T @ M @ r
    assert np.allclose(np.diag(Mr)[:3], rho * A * L, rtol=1e-13)
    ip = np.r_[rho * (s["Iyy"] + s["Izz"]) * L,                     # about x' (torsion)
               rho * A * L**3 / 3 + rho * s["Izz"] * L,             # about y'
               rho * A * L**3 / 3 + rho * s["Iyy"] * L]             # about z'
    Rr = R @ Mr[3:, 3:] @ R.T
    assert np.allclose(np.diag(Rr), ip, rtol=1e-12)


def test_global_is_rotated_local():
    x, R = skew_element(0.9)
    s = SEC
    L = np.array([0.9])
    T = beam_transformation(R[None])
    Kl = beam_stiffness_local(L, s["E"], s["G"], s["A"], s["Iyy"], s["Izz"], s["J"],
                              s["ky"], s["kz"])
    K = beam_stiffness(x, s["E"], s["G"], s["A"], s["Iyy"], s["Izz"], s["J"], s["ky"],
                       s["kz"], UP)
    assert np.allclose(K, T.transpose(0, 2, 1) @ Kl @ T, rtol=0, atol=1e-12 * abs(K).max())
    Ml = beam_mass_local(L, s["rho"], s["A"], s["Iyy"], s["Izz"])
    M = beam_mass(x, s["rho"], s["A"], s["Iyy"], s["Izz"], UP)
    assert np.allclose(M, T.transpose(0, 2, 1) @ Ml @ T, rtol=0, atol=1e-14 * abs(M).max())
    # batched: two elements with different lengths and frames
    x2 = np.concatenate([x, x[:, ::-1] * 2.0])
    K2 = beam_stiffness(x2, s["E"], s["G"], s["A"], s["Iyy"], s["Izz"], s["J"], s["ky"],
                        s["kz"], np.stack([UP, [0.0, 0.0, 1.0]]))
    assert np.allclose(K2[0], K[0])
