"""GLL points, weights and the 1-D Lagrange basis (:mod:`railvib_hpc.fem.gll`) against
tabulated values and closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.fem.gll import (
    MAX_ORDER,
    check_order,
    derivative_matrix,
    gll_points,
    hex_interpolation,
    interpolation_derivatives,
    interpolation_matrix,
)
from railvib_hpc.fem.reference import hex_shape_gradients, hex_shape_values

#: Lobatto integration, Abramowitz & Stegun (1964), "Handbook of Mathematical Functions",
#: Table 25.6 (``n`` points = order + 1; the non-negative abscissae and their weights, 12
#: digits). The same values are in Canuto et al. (2006), and Karniadakis & Sherwin (2005),
#: appendix B.
ABRAMOWITZ_STEGUN = {
    4: ([0.447213595500, 1.0], [0.833333333333, 0.166666666667]),
    5: ([0.0, 0.654653670708, 1.0], [0.711111111111, 0.544444444444, 0.1]),
    6: ([0.285231516481, 0.765055323929, 1.0],
        [0.554858377035, 0.378474956298, 0.066666666667]),
    7: ([0.0, 0.468848793471, 0.830223896279, 1.0],
        [0.487619047619, 0.431745381209, 0.276826047362, 0.047619047619]),
    8: ([0.209299217902, 0.591700181433, 0.871740148510, 1.0],
        [0.412458794659, 0.341122692484, 0.210704227144, 0.035714285714]),
    9: ([0.0, 0.363117463826, 0.677186279511, 0.899757995411, 1.0],
        [0.371519274376, 0.346428510973, 0.274538712500, 0.165495361561, 0.027777777778]),
}
#: The table's last digit.
TABLE_TOL = 1e-12


@pytest.mark.parametrize("points", sorted(ABRAMOWITZ_STEGUN))
def test_points_and_weights_match_the_table(points):
    x, w = gll_points(points - 1)
    ref_x, ref_w = ABRAMOWITZ_STEGUN[points]
    half = x >= -1e-15
    assert np.allclose(x[half], ref_x, atol=TABLE_TOL, rtol=0)
    assert np.allclose(w[half], ref_w, atol=TABLE_TOL, rtol=0)


def test_closed_forms_of_the_low_orders():
    """N = 1 trapezoid, N = 2 Simpson, N = 3 +-1/sqrt(5), N = 4 +-sqrt(3/7) with 49/90,
    32/45, N = 5 +-sqrt(1/3 -+ 2 sqrt(7) / 21) (Canuto et al. 2006, sec. 2.3)."""
    assert np.allclose(gll_points(1)[1], [1.0, 1.0])
    assert np.allclose(gll_points(2)[1], [1 / 3, 4 / 3, 1 / 3], rtol=1e-15)
    assert np.isclose(gll_points(3)[0][2], 1 / np.sqrt(5), rtol=1e-15)
    x, w = gll_points(4)
    assert np.isclose(x[3], np.sqrt(3 / 7), rtol=1e-15)
    assert np.allclose(w[1:4], [49 / 90, 32 / 45, 49 / 90], rtol=1e-14)
    x, _ = gll_points(5)
    assert np.allclose(x[3:5], [np.sqrt(1 / 3 - 2 * np.sqrt(7) / 21),
                                np.sqrt(1 / 3 + 2 * np.sqrt(7) / 21)], rtol=1e-14)


@pytest.mark.parametrize("order", range(1, MAX_ORDER + 1))
def test_the_rule_is_exact_to_degree_2n_minus_1_and_not_beyond(order):
    x, w = gll_points(order)
    for degree in range(2 * order):
        exact = 2.0 / (degree + 1) if degree % 2 == 0 else 0.0
        assert abs(w @ x**degree - exact) < 1e-14
    assert abs(w @ x ** (2 * order) - 2.0 / (2 * order + 1)) > 1e-6


@pytest.mark.parametrize("order", range(1, MAX_ORDER + 1))
def test_derivative_matrix_differentiates_degree_n_exactly(order):
    x, _ = gll_points(order)
    d = derivative_matrix(order)
    for degree in range(order + 1):
        slope = degree * x ** (degree - 1) if degree else np.zeros_like(x)
        assert np.abs(d @ x**degree - slope).max() < 1e-12
    assert np.allclose(interpolation_derivatives(order, x), d, atol=1e-12)


def test_derivative_matrix_closed_form_n1_n2():
    """Canuto et al. (2006), eq. 2.3.28 at N = 1, 2."""
    assert derivative_matrix(1).tolist() == [[-0.5, 0.5], [-0.5, 0.5]]
    assert np.allclose(derivative_matrix(2), [[-1.5, 2, -0.5], [-0.5, 0, 0.5], [0.5, -2, 1.5]])


@pytest.mark.parametrize("order", (1, 3, 6, 8))
def test_interpolation_reproduces_polynomials_at_any_point(order):
    x, _ = gll_points(order)
    xi = np.linspace(-1.0, 1.0, 37)
    L = interpolation_matrix(order, xi)
    dL = interpolation_derivatives(order, xi)
    c = np.random.default_rng(order).standard_normal(order + 1)
    p = np.polynomial.Polynomial(c)
    assert np.abs(L @ p(x) - p(xi)).max() < 1e-12
    assert np.abs(dL @ p(x) - p.deriv()(xi)).max() < 1e-10
    assert np.allclose(interpolation_matrix(order, x), np.eye(order + 1))


def test_order_one_is_the_trilinear_hexahedron():
    xi = np.random.default_rng(1).uniform(-1, 1, (20, 3))
    v, g = hex_interpolation(1, xi, derivatives=True)
    # lexicographic (i fastest) against the VTK corner order 0, 1, 3, 2, 4, 5, 7, 6
    vtk = [0, 1, 3, 2, 4, 5, 7, 6]
    assert np.allclose(v, hex_shape_values(xi)[:, vtk])
    assert np.allclose(g, hex_shape_gradients(xi)[:, vtk])


@pytest.mark.parametrize("order", (2, 5))
def test_hex_interpolation_is_a_partition_of_unity_with_exact_gradients(order):
    xi = np.random.default_rng(2).uniform(-1, 1, (15, 3))
    v, g = hex_interpolation(order, xi, derivatives=True)
    assert np.allclose(v.sum(axis=1), 1.0)
    assert np.abs(g.sum(axis=1)).max() < 1e-11
    x, _ = gll_points(order)
    n1 = order + 1
    a = np.arange(n1**3)
    nodes = np.stack([x[a % n1], x[(a // n1) % n1], x[a // n1**2]], axis=1)
    f = nodes[:, 0] ** order * nodes[:, 1] - nodes[:, 2] ** 2      # in Q_N
    assert np.allclose(v @ f, xi[:, 0] ** order * xi[:, 1] - xi[:, 2] ** 2)
    assert np.allclose(g[:, :, 0] @ f, order * xi[:, 0] ** (order - 1) * xi[:, 1])


@pytest.mark.parametrize("bad", (0, 9, 2.5, True, -1))
def test_an_order_out_of_range_is_refused_with_the_range(bad):
    with pytest.raises(ValueError, match=r"1\.\.8"):
        check_order(bad)
