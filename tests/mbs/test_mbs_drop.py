"""Wheelset drop (the thesis's unspecified start): Hertz impact against the energy solution.

A wheelset released at rest with its wheels ``h`` above a rigid rail falls, hits the rail
and compresses the Hertz springs until its kinetic energy is gone. Without damping, energy
conservation gives the deepest penetration ``d`` exactly:

    m g (h + d) + 1/2 (2 k_s) [(h + d_st)^2 - ...] = 2 * 2/5 K_H d^(5/2)

(the suspension term is included through the vehicle's own energy function), and the
peak contact force per wheel is ``K_H d^(3/2)``. For the thesis's wheelset (1568 kg,
K_H = 8.6e10 N/m^1.5) a drop of 0.01 mm gives about 24 kN and 0.1 mm about 48 kN,
against 7.7 kN static.
"""

from __future__ import annotations

import numpy as np
import pytest
from mbs_beams import two_beams
from scipy.optimize import brentq

from railvib_hpc.mbs import SuspendedWheelset, simulate_wheelset
from railvib_hpc.mbs.contact import hertz_energy, hertz_penetration
from railvib_hpc.mbs.integrate import drop_state, rigid_lift
from railvib_hpc.mbs.train import RailVehicle

OMEGA, RAILS = two_beams(5.0, 6.4e6, 60.0, 10)


def energy_peak_force(veh: SuspendedWheelset, y0: np.ndarray) -> float:
    """Peak wheel force of the undamped drop from rest at ``y0`` (bounce only) by energy."""
    e0 = float(veh.energy(y0, np.zeros_like(y0)))
    lift = rigid_lift(veh)

    def residual(z: float) -> float:
        y = z * lift
        pen = -(veh.contact_matrix().T @ y)
        return float(veh.energy(y, np.zeros_like(y))
                     + hertz_energy(pen, veh.hertz_constant).sum()) - e0

    z_min = brentq(residual, -1e-3, -1e-12, xtol=1e-16, rtol=1e-15)
    return veh.hertz_constant * (-z_min) ** 1.5


@pytest.mark.parametrize("h", [1e-5, 1e-4])
def test_drop_peak_force_equals_energy_solution(h):
    veh = SuspendedWheelset(c_suspension=0.0, c_lateral=0.0)
    y0 = drop_state(veh, h)
    # the wheels hang exactly h above the rail, the body at rest
    np.testing.assert_allclose(veh.contact_matrix().T @ y0, h, rtol=1e-12)
    expected = energy_peak_force(veh, y0)
    peaks = []
    for dt in (4e-6, 2e-6):
        # on the rigid entry rail (x < 0: no modal participation), standing still
        res = simulate_wheelset(OMEGA, 0.0, RAILS, veh, -1.0, 0.0, 8e-3, dt=dt,
                                drop_height=h)
        assert res.contact_force[0].max() == 0.0      # released without contact
        peaks.append(res.contact_force[:, 0].max())
    err = [abs(p - expected) / expected for p in peaks]
    assert err[1] < 2e-4, (peaks, expected)
    assert err[1] < err[0] or err[0] < 1e-6           # converges with dt
    # the numbers quoted in issue 13 / benchmarks: 24 kN at 0.01 mm, 48 kN at 0.1 mm
    assert expected == pytest.approx(23.6e3 if h == 1e-5 else 48.0e3, rel=0.01)


def test_drop_with_contact_damping_lowers_the_peak_and_rail_is_untouched():
    veh = SuspendedWheelset(contact_damping=2e9)
    plain = simulate_wheelset(OMEGA, 0.0, RAILS, veh.__class__(), -1.0, 0.0, 8e-3, dt=4e-6,
                              drop_height=1e-4)
    damped = simulate_wheelset(OMEGA, 0.0, RAILS, veh, -1.0, 0.0, 8e-3, dt=4e-6,
                               drop_height=1e-4)
    assert damped.contact_force.max() < plain.contact_force.max()
    assert not plain.q.any() and not damped.q.any()  # the rigid rail takes it all


def test_drop_of_a_four_axle_vehicle_lifts_every_body():
    car = RailVehicle()
    y0 = drop_state(car, 5e-5)
    static = drop_state(car, 0.0)
    # rigid lift: every wheel 0.05 mm clear, suspension deflections unchanged
    np.testing.assert_allclose(car.contact_matrix().T @ y0, 5e-5, rtol=1e-9)
    np.testing.assert_allclose(car.stiffness_matrix() @ (y0 - static), 0.0, atol=1e-6)
    # with zero drop the wheels just touch (zero penetration, no force at t = 0)
    pen = hertz_penetration(car.static_wheel_loads(), car.hertz_constant)
    assert pen.min() > 0
    np.testing.assert_allclose(car.contact_matrix().T @ static, 0.0, atol=1e-15)
