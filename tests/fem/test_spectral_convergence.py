"""Convergence of spectral hexahedra in ``h`` and in ``N``: the eigenfrequencies of an
elastic box on rollers (sliding on every face), whose modes are products of sines and
cosines (:func:`spectral_cases.roller_box_frequencies`: P at ``c_P |k|``, S at ``c_S |k|``,
``k = pi (l / L_x, m / L_y, n / L_z)``). The lumped GLL element's eigenvalue error is
``O(h^(2N))`` (the GLL rule keeps the consistent element's order: Maday & Ronquist 1990;
Cohen 2002, "Higher-Order Numerical Methods for Transient Wave Equations", ch. 8) and
falls exponentially in ``N`` at a fixed mesh."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import eigsh
from spectral_cases import (
    LAM,
    MU,
    RHO,
    assembled_stiffness,
    roller_box_frequencies,
    roller_free,
    spectral_box,
)

#: The box [m] (unequal edges: few degenerate modes).
LENGTHS = (1.0, 0.8, 0.6)
#: Modes compared (the lowest, 179-323 Hz; the first is the S mode l = m = 1, n = 0).
MODES = 12
C_P, C_S = np.sqrt((LAM + 2 * MU) / RHO), np.sqrt(MU / RHO)
#: Reduced systems up to this size are solved densely.
DENSE = 2500


def _frequencies(order: int, n: int) -> np.ndarray:
    """The lowest :data:`MODES` angular frequencies of ``n^3`` elements of order ``order``
    (the stiffness assembled from the tensor-construction element, which equals the
    kernel's: ``test_spectral_kernel.py``; the kernel's lumped mass)."""
    sm, op = spectral_box(order, (n, n, n), LENGTHS)
    K = assembled_stiffness(sm, LENGTHS, (n, n, n))
    free = roller_free(sm.points, LENGTHS).ravel()
    scale = sp.diags(1.0 / np.sqrt(np.repeat(op.mass, 3)[free]))
    A = (scale @ K[free][:, free] @ scale).tocsc()
    if A.shape[0] <= DENSE:
        w = np.linalg.eigvalsh(A.toarray())[:MODES]
    else:
        w = np.sort(eigsh(A, k=MODES, sigma=0.0, return_eigenvectors=False))
    return np.sqrt(w)


EXACT = roller_box_frequencies(LENGTHS, MODES, C_P, C_S)


@pytest.mark.slow
def test_the_analytic_spectrum_is_the_converged_one():
    """Order 6 on 2 x 2 x 2 elements: the 12 lowest frequencies within 1e-6 (measured
    8.0e-8)."""
    assert np.abs(_frequencies(6, 2) / EXACT - 1).max() < 1e-6


def _rate(order: int, sizes: tuple[int, ...]) -> float:
    errors = [abs(_frequencies(order, n)[0] / EXACT[0] - 1) for n in sizes]
    assert all(a > b for a, b in zip(errors, errors[1:])), errors
    return float(np.polyfit(np.log(1.0 / np.array(sizes)), np.log(errors), 1)[0])


def test_order_two_converges_at_h_to_the_fourth():
    """N = 2 on 2, 3, 4 elements per edge: slope 3.7-3.9 (2N = 4; measured 3.67 and 3.80
    between neighbours, the asymptotic rate from below)."""
    assert 3.5 < _rate(2, (2, 3, 4)) < 4.8


@pytest.mark.slow
def test_order_three_converges_at_h_to_the_sixth():
    """N = 3 on 2, 3, 4 elements per edge: slope ~5.8-5.9 (2N = 6)."""
    assert 5.4 < _rate(3, (2, 3, 4)) < 6.8


def test_error_falls_exponentially_in_the_order():
    """2 x 2 x 2 elements, N = 2..5: the largest error of the 12 modes falls by a factor
    of more than 7 per order (measured 2.8e-2, 5.7e-3, 1.7e-4, 6.4e-6), towards the
    analytic spectrum."""
    orders = np.arange(2, 6)
    errors = np.array([np.abs(_frequencies(int(n), 2) / EXACT - 1).max() for n in orders])
    assert np.all(np.diff(np.log(errors)) < 0)
    assert errors[-1] < 1e-5
    assert np.polyfit(orders, np.log(errors), 1)[0] < -2.0
