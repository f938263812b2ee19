"""Richardson extrapolation against analytic sequences f(h) = f0 + C h^p."""

from __future__ import annotations

import math

import numpy as np
import pytest

from railvib_hpc.studies.richardson import extrapolate, mesh_sizes, observed_order


@pytest.mark.parametrize("p", [1.0, 1.7, 2.0, 3.2])
@pytest.mark.parametrize("h", [(1.0, 0.71, 0.5), (1.0, 0.8, 0.45), (2.0, 1.0, 0.5)])
def test_exact_order_and_limit_recovered_for_any_ratios(p, h):
    h = np.array(h)
    f = 2.5 - 0.7 * h**p
    est = extrapolate(f, h)
    assert est.observed_order == pytest.approx(p, rel=1e-9)
    assert est.basis == "observed" and not est.oscillatory
    assert est.extrapolated == pytest.approx(2.5, rel=1e-12)
    assert est.error == pytest.approx(abs(f[-1] - 2.5) / 2.5, rel=1e-9)


def test_uses_the_three_finest_of_more_levels():
    h = np.array([1.6, 1.2, 1.0, 0.7, 0.5])
    f = 10.0 + 3.0 * h**2.0
    f[0] = 123.0                      # a wild coarse level does not matter
    est = extrapolate(f, h)
    assert est.observed_order == pytest.approx(2.0, rel=1e-9)
    assert est.extrapolated == pytest.approx(10.0, rel=1e-12)


def test_observed_order_uniform_ratio_closed_form():
    r = 2.0
    f1, f2, f3 = 1.0 + 0.5**3, 1.0 + 1.0, 1.0 + 8.0   # h = 0.5, 1, 2 and p = 3
    assert observed_order(f1, f2, f3, r, r) == pytest.approx(3.0, rel=1e-12)


def test_two_levels_assume_the_formal_order():
    est = extrapolate([1.0, 1.1], [1.0, 0.5], formal_order=2.0)
    assert est.basis == "assumed" and est.order == 2.0 and est.observed_order is None
    assert est.extrapolated == pytest.approx((4 * 1.1 - 1.0) / 3)
    assert est.gci == pytest.approx(1.25 * (0.1 / 1.1) / 3)


def test_oscillating_sequence_is_flagged_and_conservative():
    est = extrapolate([1.0, 1.1, 1.05], [1.0, 0.7, 0.5])
    assert est.oscillatory and est.basis == "unreliable"
    assert est.error >= est.last_change
    assert est.error >= abs(1.0 - 1.05) / 1.05


def test_converged_sequences():
    est = extrapolate([3.0, 3.0, 3.0], [1.0, 0.7, 0.5])
    assert est.error == 0.0 and est.extrapolated == 3.0
    zero = extrapolate([0.0, 0.0], [1.0, 0.5])
    assert zero.error == 0.0


def test_mesh_sizes_and_bad_input():
    np.testing.assert_allclose(mesh_sizes([1000, 8000]), [0.1, 0.05])
    with pytest.raises(ValueError):
        mesh_sizes([0, 10])
    with pytest.raises(ValueError, match="decrease"):
        extrapolate([1.0, 2.0], [0.5, 1.0])
    with pytest.raises(ValueError, match="at least two"):
        extrapolate([1.0], [1.0])
    with pytest.raises(ValueError, match="exceed 1"):
        observed_order(1.0, 2.0, 3.0, 1.0, 2.0)
    assert observed_order(1.0, 1.0, 2.0, 1.5, 1.5) is None       # no change: no order
    assert math.isfinite(extrapolate([5.0, 4.0, 3.9], [1.0, 0.8, 0.6]).error)
