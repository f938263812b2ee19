"""Coupling: Hermite/linear interpolation and force distribution by the same shape functions."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.mbs import RailCoupling, shape_functions

RNG = np.random.default_rng(7)
X_NODES = np.array([0.0, 0.45, 0.6, 1.3, 1.9, 2.0])


def _cubics(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Three cubics (rows) and their derivatives at x."""
    c = np.array([[1.0, -2.0, 0.5, 0.3], [0.0, 1.0, 0.0, -1.0], [2.0, 0.1, -3.0, 1.7]])
    p = c[:, :1] + c[:, 1:2] * x + c[:, 2:3] * x**2 + c[:, 3:4] * x**3
    dp = c[:, 1:2] + 2 * c[:, 2:3] * x + 3 * c[:, 3:4] * x**2
    return p, dp


def test_hermite_reproduces_cubics_exactly():
    p, dp = _cubics(X_NODES)
    rail = RailCoupling(X_NODES, p, -dp)  # dw/dx = -phi_r
    x = np.sort(RNG.uniform(0.0, 2.0, 50))
    expected, _ = _cubics(x)
    np.testing.assert_allclose(rail.modal_rows(x), expected, rtol=0, atol=1e-13)


def test_linear_reproduces_linear_functions_and_is_exact_at_nodes():
    lin = np.vstack([1.0 + 2.0 * X_NODES, -X_NODES])
    rail = RailCoupling(X_NODES, lin)
    x = RNG.uniform(0.0, 2.0, 30)
    np.testing.assert_allclose(rail.modal_rows(x), np.vstack([1.0 + 2.0 * x, -x]), atol=1e-14)
    p, _ = _cubics(X_NODES)
    np.testing.assert_allclose(RailCoupling(X_NODES, p).modal_rows(X_NODES), p, atol=1e-14)


@pytest.mark.parametrize("hermite", [True, False])
def test_force_distribution_is_transpose_of_interpolation(hermite):
    m = 12
    phi_w = RNG.standard_normal((m, X_NODES.size))
    phi_r = RNG.standard_normal((m, X_NODES.size)) if hermite else None
    rail = RailCoupling(X_NODES, phi_w, phi_r)
    q = RNG.standard_normal(m)
    x = np.array([0.0, 0.2, 0.6, 1.55, 2.0])
    forces = RNG.uniform(1.0, 5.0, x.size)
    # virtual work: Q . q == sum F w(x)
    assert rail.modal_force(x, forces) @ q == pytest.approx(forces @ rail.displacement(x, q),
                                                            rel=1e-13)
    # and Q = Psi^T f with the nodal force vector assembled explicitly
    elem, wts, _ = shape_functions(X_NODES, x, hermite)
    f_w = np.zeros(X_NODES.size)
    f_r = np.zeros(X_NODES.size)
    for e, w, f in zip(elem, wts, forces):
        if hermite:
            f_w[[e, e + 1]] += f * w[[0, 2]]
            f_r[[e, e + 1]] -= f * w[[1, 3]]  # moment conjugate to phi_r = -dw/dx
        else:
            f_w[[e, e + 1]] += f * w
    nodal = phi_w @ f_w + (phi_r @ f_r if hermite else 0.0)
    np.testing.assert_allclose(rail.modal_force(x, forces), nodal, rtol=1e-13)


def test_rigid_rail_outside_gives_no_coupling():
    rail = RailCoupling(X_NODES, RNG.standard_normal((4, 6)), RNG.standard_normal((4, 6)))
    rows = rail.modal_rows(np.array([-0.1, -1e-9, 2.0 + 1e-9, 5.0]))
    assert not rows.any()
    assert not rail.modal_force(-0.5, 1e5).any()


def test_partition_of_unity():
    x = RNG.uniform(0.0, 2.0, 20)
    _, wl, _ = shape_functions(X_NODES, x, hermite=False)
    _, wh, _ = shape_functions(X_NODES, x, hermite=True)
    np.testing.assert_allclose(wl.sum(axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(wh[:, 0] + wh[:, 2], 1.0, atol=1e-15)


def test_rejects_bad_input():
    with pytest.raises(ValueError):
        RailCoupling(np.array([0.0, 1.0, 1.0]), np.zeros((2, 3)))
    with pytest.raises(ValueError):
        RailCoupling(X_NODES, np.zeros((2, 5)))
