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


# ------------------------------------------------------------------ residual modes
@pytest.fixture(scope="module")
def beam_matrices():
    _, _, M, free = supported_beam_fe(L, N_EL, EI, RHO_A, K_PAD, A)
    return M, free


def deflated_mass(track, beam_matrices, m):
    """``X'^T M X'`` of the static fields of every rail DOF (both rails) with the m kept
    modes taken out on the full vectors (what ``static.h5`` and the stage form)."""
    from railvib_hpc.mbs.static_correction import kept_residual_mass, rail_dof_rows

    M, free = beam_matrices
    _, omega_all, full, kinv = track
    fi = np.flatnonzero(free >= 0)
    mfull = np.zeros_like(kinv)
    mfull[np.ix_(fi, fi)] = M
    phi = full                                     # every mode of the "file"
    xd = kinv - phi @ (phi.T @ mfull @ kinv)       # deflated by all modes: zero here
    one = xd.T @ mfull @ xd
    n = one.shape[0]
    mass_file = np.zeros((2 * n, 2 * n))
    mass_file[:n, :n] = mass_file[n:, n:] = one
    omega_file, rails_file, _ = rails_of(track, omega_all.size)
    keep = np.r_[np.arange(m), omega_all.size + np.arange(m)]
    rest = np.setdiff1d(np.arange(omega_file.size), keep)
    rows = rail_dof_rows(rails_file)
    return kept_residual_mass(mass_file, rows[rest], omega_file[rest])


def test_residual_modes_are_the_modes_left_out(track, beam_matrices):
    """Every DOF of this track is a rail DOF: the residual modes of m kept modes are exactly
    the other modes (frequencies to round-off, amplified by the condition number of K)."""
    from railvib_hpc.mbs.static_correction import residual_modes
    from railvib_hpc.tolerances import EPS

    _, omega_all, _, kinv = track
    cond = (omega_all[-1] / omega_all[0]) ** 2
    for m in (5, 20):
        omega, rails, x_rr = rails_of(track, m)
        res = residual_modes(x_rr, deflated_mass(track, beam_matrices, m), rails, omega)
        expect = np.sort(np.concatenate([omega_all[m:], omega_all[m:]]))
        assert res.omega.size == expect.size
        # relative error of the frequencies: eps * cond(K) * n from the static solve and
        # from the modes, in each of the two cancellations (flexibility and mass)
        np.testing.assert_allclose(res.omega, expect, rtol=4 * EPS * cond * kinv.shape[0])
        assert res.omega.min() >= omega.max()


def test_residual_modes_keep_the_static_flexibility(track, beam_matrices):
    from railvib_hpc.mbs.static_correction import rail_dof_rows, residual_modes

    omega, rails, x_rr = rails_of(track, 10)
    res = residual_modes(x_rr, deflated_mass(track, beam_matrices, 10), rails, omega)
    phi = rail_dof_rows(rails)
    total = (phi / omega[:, None] ** 2).T @ phi + (res.rows / res.omega**2) @ res.rows.T
    np.testing.assert_allclose(total, x_rr, rtol=0, atol=1e-9 * np.abs(x_rr).max())
    # the appended rails carry the residual modes' rows
    both = res.rails(rails)
    assert both[0].phi_w.shape == (omega.size + res.omega.size, rails[0].x_nodes.size)


def test_rolling_wheel_with_residual_modes_equals_all_modes(track, beam_matrices):
    """A wheelset rolling at 30 m/s over the discrete pads: 10 modes + residual modes give
    the same contact force as all 478 modes per rail (the same basis), where the massless,
    undamped residual flexibility does not."""
    from railvib_hpc.mbs.static_correction import residual_modes

    veh = SuspendedWheelset(k_suspension=0.0)
    run = dict(x0=4.0, speed=30.0, t_end=0.04, dt=2e-5)
    omega, rails, x_rr = rails_of(track, 10)
    res = residual_modes(x_rr, deflated_mass(track, beam_matrices, 10), rails, omega)
    aug = simulate_vehicle(np.concatenate([omega, res.omega]), 0.03, res.rails(rails), veh,
                           **run)
    m_all = track[1].size
    omega_all, rails_all, _ = rails_of(track, m_all)
    ref = simulate_vehicle(omega_all, 0.03, rails_all, veh, **run)
    scale = float(np.abs(ref.contact_force).max())
    np.testing.assert_allclose(aug.contact_force, ref.contact_force, rtol=0, atol=1e-6 * scale)
    massless = simulate_vehicle(omega, 0.03, rails, veh, residual=residual_flexibility(
        x_rr, rails, omega), **run)
    assert np.abs(massless.contact_force - ref.contact_force).max() > 1e-3 * scale
