"""Standing wheelset on a rail on discrete elastic supports; static correction; mode convergence.

Track: a UIC60-like Euler-Bernoulli rail, simply supported at the ends of
L = 12 m, on discrete pads (k = 1e8 N/m every 0.6 m), 240 Hermite elements.
Reference: the semi-analytic solution of the same beam from the exact Green's
function of the simply supported beam (no discretisation error).
"""

from __future__ import annotations

import numpy as np
import pytest
from mbs_beams import supported_beam_fe
from scipy.linalg import eigh

from railvib_hpc.constants import STANDARD_GRAVITY
from railvib_hpc.mbs import RailCoupling, SuspendedWheelset, simulate_vehicle
from railvib_hpc.mbs.static_correction import ContactResidual, residual_flexibility

L, N_EL, EI, RHO_A, K_PAD, A = 12.0, 240, 6.4e6, 60.0, 1e8, 0.6
X0 = 6.0                                # wheel between two supports (5.7 and 6.3 m)


def green(x, xi):
    """Deflection at x of a unit force at xi, simply supported EB beam of length L."""
    x, xi = np.broadcast_arrays(np.asarray(x, float), np.asarray(xi, float))
    lo, hi = np.minimum(x, xi), np.maximum(x, xi)
    b = L - hi
    return b * lo * (L * L - b * b - lo * lo) / (6.0 * EI * L)


def discrete_support_deflection(p: float, xp: float) -> float:
    """Deflection under a downward force P at xp (semi-analytic)."""
    xs = np.arange(0.5 * A, L, A)
    g = green(xs[:, None], xs[None, :])
    ws = np.linalg.solve(np.eye(xs.size) + K_PAD * g, green(xs, xp) * p)
    return float(green(xp, xp) * p - K_PAD * green(xp, xs) @ ws)


@pytest.fixture(scope="module")
def track():
    x, K, M, free = supported_beam_fe(L, N_EL, EI, RHO_A, K_PAD, A)
    lam, phi = eigh(K, M)
    full = np.zeros((x.size * 2, lam.size))
    full[free >= 0] = phi
    kinv = np.zeros((x.size * 2, x.size * 2))
    fi = np.flatnonzero(free >= 0)
    kinv[np.ix_(fi, fi)] = np.linalg.inv(K)
    return x, np.sqrt(lam), full, kinv


def rails_of(track, m):
    """Two identical independent rails with the lowest m modes (block-diagonal rows)."""
    x, omega, full, kinv = track
    pw, pr = full[0::2, :m].T, full[1::2, :m].T
    z = np.zeros_like(pw)
    rails = (RailCoupling(x, np.vstack([pw, z]), np.vstack([pr, z])),
             RailCoupling(x, np.vstack([z, pw]), np.vstack([z, pr])))
    nr = kinv.shape[0]
    x_rr = np.zeros((2 * nr, 2 * nr))
    x_rr[:nr, :nr] = x_rr[nr:, nr:] = kinv
    return np.concatenate([omega[:m], omega[:m]]), rails, x_rr


def standing(track, m, corrected):
    omega, rails, x_rr = rails_of(track, m)
    veh = SuspendedWheelset(k_suspension=0.0)      # wheel load exactly M g / 2
    g = residual_flexibility(x_rr, rails, omega) if corrected else None
    res = simulate_vehicle(omega, 0.03, rails, veh, X0, 0.0, 2e-3, dt=1e-4, residual=g)
    return res, 0.5 * veh.mass * veh.gravity


def test_fe_track_matches_the_semi_analytic_solution(track):
    x, _, _, kinv = track
    i = int(np.argmin(np.abs(x - X0)))
    exact = discrete_support_deflection(1.0, X0)
    # Hermite elements are exact for point loads at nodes: only round-off remains
    assert kinv[2 * i, 2 * i] == pytest.approx(exact, rel=1e-9)


def test_standing_wheel_rail_deflection_within_5_percent(track):
    exact = -discrete_support_deflection(0.5 * 1568.0 * STANDARD_GRAVITY, X0)
    # 20 of 481 modes (up to 1.47 kHz) give the static deflection within 5 % (2.2 %);
    # 10 modes (up to 444 Hz) do not (16 %)
    res, _ = standing(track, 20, corrected=False)
    assert res.rail_displacement[-1, 0] == pytest.approx(exact, rel=0.05)
    res, _ = standing(track, 10, corrected=False)
    assert res.rail_displacement[-1, 0] != pytest.approx(exact, rel=0.05)


def test_static_correction_is_exact_for_any_number_of_modes(track):
    exact = -discrete_support_deflection(1.0, X0)
    for m in (5, 20, 100):
        res, load = standing(track, m, corrected=True)
        assert res.rail_displacement[-1, 0] == pytest.approx(exact * load, rel=1e-9)
        np.testing.assert_allclose(res.contact_force[-1], load, rtol=1e-10)


def test_mode_count_convergence_of_the_static_deflection(track):
    """Uncorrected: the error falls monotonically with the modes kept (100/200/300/350)."""
    exact = -discrete_support_deflection(1.0, X0)
    errs = []
    for m in (100, 200, 300, 350):
        res, load = standing(track, m, corrected=False)
        errs.append(abs(res.rail_displacement[-1, 0] / load - exact) / abs(exact))
    assert all(a > b for a, b in zip(errs, errs[1:]))
    assert errs[-1] < 2e-3


def test_contact_residual_matrix_is_symmetric_and_matches_interpolation(track):
    omega, rails, x_rr = rails_of(track, 10)
    g = residual_flexibility(x_rr, rails, omega)
    xs = np.array([[3.03, 3.03, 7.71, 7.71]])
    cr = ContactResidual(g, rails, [0, 1, 0, 1], xs)
    c = cr.matrix(0)
    np.testing.assert_allclose(c, c.T, rtol=1e-12, atol=0)
    assert np.all(np.linalg.eigvalsh(c) > -1e-15)
    # independent rails: no cross flexibility between wheels on different rails
    assert c[0, 1] == 0.0 and c[2, 3] == 0.0
    # loads follow the Hermite shape functions: sum of w-loads equals the forces
    f = np.array([1.0, 2.0, 3.0, 4.0])
    loads = cr.loads(0, f)
    assert loads[0::2].sum() == pytest.approx(-f.sum(), rel=1e-12)
