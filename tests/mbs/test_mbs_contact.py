"""Hertz contact law and Jenkins' constant (benchmarks.md section 1)."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.mbs import hertz_force, hertz_penetration, jenkins_hertz_constant


def test_jenkins_constant_and_static_penetration():
    kh = jenkins_hertz_constant(0.46)
    # reference values are given to 2 and 3 significant digits: half a unit of the last digit
    assert abs(kh - 8.6e10) <= 0.05e10
    assert abs(hertz_penetration(7.69e3, kh) - 20.0e-6) <= 0.05e-6
    assert hertz_force(hertz_penetration(7.69e3, kh), kh) == pytest.approx(7.69e3, rel=1e-14)


def test_separation_and_damping():
    kh, c = 8.6e10, 1e9
    d = np.array([-1e-6, 0.0, 1e-5, 1e-5, 1e-5])
    dd = np.array([0.0, 0.0, 0.0, 0.01, -10.0])
    f = hertz_force(d, kh, dd, c)
    assert f[0] == 0.0 and f[1] == 0.0
    assert f[2] == pytest.approx(kh * 1e-5**1.5)
    assert f[3] > f[2]  # loading: damping adds to the force (dissipative)
    assert f[4] == 0.0  # fast unloading: no tensile contact force
    with pytest.raises(ValueError):
        jenkins_hertz_constant(0.0)


@pytest.mark.parametrize("wheels", [2, 3])
def test_the_contact_newton_converges_far_above_the_static_penetration(wheels):
    """The penetrations of a rail grown without bound (5.5e4 m, measured in a run whose
    damping was negated): the correction stalls at the round-off of the penetration
    (1.9e-14 m), above the absolute tolerance (1e-10 of the static penetration, 2e-15 m);
    the relative floor (:data:`~railvib_hpc.mbs.integrate.NEWTON_ROUNDOFF`) accepts it,
    and the result solves ``delta = delta_hat - A h(delta)`` to that round-off; without
    the floor the iteration does not converge."""
    from railvib_hpc.errors import ContactNewtonError
    from railvib_hpc.mbs import integrate

    kh = 86050237886.62022
    delta_hat = np.linspace(54853.09965803, 54853.15587315, wheels)
    a = np.full((wheels, wheels), -2.22742912e-11) + 2.42663e-10 * np.eye(wheels)
    args = (delta_hat, a, np.full(wheels, -11107.97), kh, 0.0, 5e-4, 1.998587e-15, 50)
    delta, force = integrate.solve_contact(*args)
    residual = np.abs(delta + a @ force - delta_hat).max()
    assert residual <= 4 * integrate.NEWTON_ROUNDOFF * delta_hat.max()
    assert np.all(force > 0.0)
    floor = integrate.NEWTON_ROUNDOFF
    try:
        integrate.NEWTON_ROUNDOFF = 0.0
        with pytest.raises(ContactNewtonError):
            integrate.solve_contact(*args)
    finally:
        integrate.NEWTON_ROUNDOFF = floor


@pytest.mark.parametrize("wheels", [1, 3])
def test_a_contact_newton_that_does_not_converge_is_a_divergence_not_a_bug(wheels):
    """Too few iterations: :class:`~railvib_hpc.errors.ContactNewtonError`, a
    :class:`~railvib_hpc.errors.DivergenceError` (exit code 3, one line with the
    iterations, the last correction and the tolerance), picklable for the ranks."""
    import pickle

    from railvib_hpc.errors import ContactNewtonError, DivergenceError
    from railvib_hpc.mbs.integrate import solve_contact

    kh = jenkins_hertz_constant(0.46)
    static = hertz_penetration(7.69e3, kh)
    with pytest.raises(ContactNewtonError) as info:
        solve_contact(np.full(wheels, 10 * static), np.eye(wheels) * 1e-9, np.zeros(wheels),
                      kh, 0.0, 1e-4, 1e-10 * static, 1)
    exc = info.value
    assert isinstance(exc, DivergenceError) and exc.exit_code == 3
    text = str(exc)
    assert "\n" not in text and "did not converge in 1 iterations" in text
    assert "tolerance" in text and "last correction" in text
    assert str(pickle.loads(pickle.dumps(exc))) == text
