"""Constant force crossing a simply supported beam: Fryba's dynamic amplification.

Reference (Fryba, undamped, benchmarks.md section 1): with ``alpha = v / (2 f1 L)`` the
maximum midspan deflection *during the passage* (0 <= t <= L/v) divided by the
static midspan deflection ``P L^3 / (48 EI)`` is 1.41 (alpha 0.3), 1.705 (0.5),
1.73 (0.62, the maximum of the curve) and 1.61 (0.9). The static reference is
the exact beam value; 30 modes reproduce it to 6e-6 relative (truncation
``sum_{odd n > 30} n^-4 / sum_{odd} n^-4``), far below the 2 % tolerance, as is
the time-sampling error of the maximum (3000 steps per passage).

Fryba's curve is the maximum during the passage. Measured here: the free
vibration after the force has left stays below it at alpha = 0.9 (same 1.613),
but exceeds it at alpha = 1.5 (1.167 after vs 1.024 during), so the two must
not be mixed for fast passages.
"""

from __future__ import annotations

import numpy as np
import pytest
from mbs_beams import ss_beam

from railvib_hpc.mbs import RailCoupling, simulate_moving_force

L, EI, RHO_A, P = 10.0, 2.0e9, 1.0e4, 1.0e5


def _amplification(alpha: float, rail_factory=None, t_factor: float = 1.0) -> tuple:
    omega, rail = ss_beam(L, EI, RHO_A, 30)
    if rail_factory is not None:
        rail = rail_factory(rail)
    speed = alpha * 2.0 * (omega[0] / (2.0 * np.pi)) * L
    t_pass = L / speed
    res = simulate_moving_force(omega, 0.0, rail, P, 0.0, speed, t_factor * t_pass,
                                dt=t_pass / 3000)
    w_mid = -rail.displacement(0.5 * L, res.q)[:, 0]
    during = res.t <= t_pass * (1 + 1e-12)
    w_static = P * L**3 / (48.0 * EI)
    return w_mid[during].max() / w_static, w_mid.max() / w_static, res


@pytest.mark.parametrize(("alpha", "expected"), [(0.3, 1.41), (0.5, 1.705), (0.62, 1.73),
                                                 (0.9, 1.61)])
def test_fryba_dynamic_amplification(alpha, expected):
    daf, _, res = _amplification(alpha)
    assert daf == pytest.approx(expected, rel=0.02)
    # the contact force history is the constant load, the track started at rest
    assert np.all(res.contact_force == P)
    assert res.n_loss_of_contact == 0


def test_fryba_linear_interpolation_without_rotations():
    daf, _, _ = _amplification(0.5, lambda r: RailCoupling(r.x_nodes, r.phi_w))
    assert daf == pytest.approx(1.705, rel=0.02)


def test_static_limit_and_free_vibration_after_passage():
    # slow passage: quasi-static, midspan deflection -> static value (dynamic part ~ alpha)
    daf, _, _ = _amplification(0.02)
    assert daf == pytest.approx(1.0, abs=0.05)
    # after the force has left, the beam vibrates freely: the modal energy stays constant
    _, _, res = _amplification(0.9, t_factor=1.5)
    omega, _ = ss_beam(L, EI, RHO_A, 30)
    energy = 0.5 * np.sum(res.q_dot**2 + (omega * res.q) ** 2, axis=1)
    t_pass = res.t[-1] / 1.5
    after = res.t > t_pass + res.dt
    assert np.ptp(energy[after]) <= 1e-10 * energy[after].max()
