"""Four-axle rail vehicle and trains: matrices, nullspace, static loads, suspension frequencies.

The suspension frequencies with the wheelsets held fixed are checked against
closed forms: by symmetry the 9 car-body/bogie DOFs split into 2x2 problems
(bounce: car z + bogies in phase; pitch: car pitch + bogies in antiphase;
roll: car roll + bogie rolls in phase) and single-DOF modes (bogie pitch x2,
bogie rolls in antiphase). The two-stage series-spring estimate (bogie mass
neglected) ``omega^2 = k_eq / M_c`` (bounce) and ``k_eq l_c^2 / J_c``
(pitch), ``k_eq = 4 k_s 8 k_p / (4 k_s + 8 k_p)``, is then within 1 %.
"""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc import tolerances
from railvib_hpc.mbs.irregularity import Irregularity, RailProfile, WheelFlat
from railvib_hpc.mbs.train import RailVehicle, Train
from railvib_hpc.mbs.vehicles import static_equilibrium

VEH = RailVehicle()
WHEELSET_DOFS = np.arange(9, 17)


def _omega2(m: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Generalised eigenproblem ``K v = w^2 M v`` for a diagonal M (mass-scaled, symmetric)."""
    s = 1.0 / np.sqrt(np.diag(m))
    w2, v = np.linalg.eigh(s[:, None] * k * s[None, :])
    return w2, s[:, None] * v


def _pair(m1: float, m2: float, a: float, b: float, c: float) -> np.ndarray:
    """Eigenvalues w^2 of diag(m1, m2), [[a, b], [b, c]]."""
    p, q = a / m1, c / m2
    r = b * b / (m1 * m2)
    d = np.sqrt((p - q) ** 2 + 4 * r)
    return np.array([0.5 * (p + q - d), 0.5 * (p + q + d)])


def _rigid_modes(v: RailVehicle) -> np.ndarray:
    """(17, 5) zero-energy modes with free wheels: bounce, pitch, roll, bogie 0/1 pitch."""
    lc, lt = v.bogie_semi_spacing, v.semi_wheelbase
    n = np.zeros((17, 5))
    n[[0, 3, 6, 9, 11, 13, 15], 0] = 1.0
    n[1, 1] = n[4, 1] = n[7, 1] = 1.0
    n[3, 1], n[6, 1] = lc, -lc
    n[[9, 11, 13, 15], 1] = v.wheelset_positions
    n[[2, 5, 8, 10, 12, 14, 16], 2] = 1.0
    n[4, 3], n[9, 3], n[11, 3] = 1.0, lt, -lt
    n[7, 4], n[13, 4], n[15, 4] = 1.0, lt, -lt
    return n


def test_interface_and_layout():
    assert VEH.n_dof == 17 == len(VEH.dof_names) and VEH.n_wheels == 8
    m, c, k = VEH.mass_matrix(), VEH.damping_matrix(), VEH.stiffness_matrix()
    b = VEH.contact_matrix()
    assert m.shape == c.shape == k.shape == (17, 17) and b.shape == (17, 8)
    lc, lt = 9.5, 1.28
    np.testing.assert_allclose(VEH.wheel_offsets,
                               np.repeat([0.0, -2 * lt, -2 * lc, -2 * lc - 2 * lt], 2))
    np.testing.assert_array_equal(VEH.wheel_rail, [0, 1] * 4)
    # wheel heights: z +- roll * contact_span / 2 of the own wheelset only
    y = np.zeros(17)
    y[9 + 2 * 2], y[10 + 2 * 2] = 1e-3, 2e-3  # wheelset 2
    np.testing.assert_allclose(b.T @ y, [0, 0, 0, 0, 1e-3 + 1.5e-3, 1e-3 - 1.5e-3, 0, 0])
    assert VEH.hertz_constant == pytest.approx(8.6e10, rel=0.01)
    assert RailVehicle(k_hertz=1e11).hertz_constant == 1e11
    with pytest.raises(ValueError, match="car_length"):
        RailVehicle(car_length=20.0)
    with pytest.raises(ValueError, match="k_primary"):
        RailVehicle(k_primary=0.0)


def test_matrices_symmetric_psd_with_rigid_body_nullspace():
    m, c, k = VEH.mass_matrix(), VEH.damping_matrix(), VEH.stiffness_matrix()
    for a in (m, c, k):
        np.testing.assert_array_equal(a, a.T)
    assert np.all(np.diag(m) > 0) and np.count_nonzero(m - np.diag(np.diag(m))) == 0
    n = _rigid_modes(VEH)
    assert np.linalg.matrix_rank(n) == 5
    for a in (k, c):
        np.testing.assert_allclose(a @ n, 0.0, atol=1e-9 * np.abs(a).max())
    w2, vecs = _omega2(m, k)
    # exactly 5 zero-energy modes: zero to round-off, sqrt(n) u lambda_max (vs >= 180)
    zero = tolerances.zero_eigenvalue_bound(w2[-1], len(w2))
    assert np.all(np.abs(w2[:5]) <= zero) and w2[5] > 100.0
    # ... and they span the expected rigid modes (Davis-Kahan angle: round-off / gap)
    sines = tolerances.subspace_sines(n, vecs[:, :5], m)
    assert sines.max() <= tolerances.subspace_tolerance(w2[5], w2[-1], len(w2))
    w2c, _ = _omega2(m, c)
    zero_c = tolerances.zero_eigenvalue_bound(w2c[-1], len(w2c))
    assert np.all(w2c >= -zero_c) and np.sum(np.abs(w2c) <= zero_c) == 5
    # energy: quadratic form minus gravity work, broadcast over leading axes
    y = np.random.default_rng(0).normal(size=(3, 17)) * 1e-3
    e = VEH.energy(y, 2 * y)
    np.testing.assert_allclose(e[1], 0.5 * (2 * y[1]) @ m @ (2 * y[1]) + 0.5 * y[1] @ k @ y[1]
                               - y[1] @ VEH.external_force(), rtol=1e-12)
    assert VEH.energy(np.zeros(17), np.zeros(17)) == 0.0


def test_static_wheel_loads_lever_rule():
    g = VEH.gravity
    loads = VEH.static_wheel_loads()
    lever = (VEH.car_mass / 8 + VEH.bogie_mass / 4 + VEH.wheelset_mass / 2) * g
    np.testing.assert_allclose(loads, lever, rtol=1e-12)  # 54546.05 N
    assert loads.sum() == pytest.approx(VEH.total_mass * g, rel=1e-13)
    # a stiffer front bogie and a softer rear one do not change a symmetric car's loads
    other = RailVehicle(k_secondary=0.6e6, k_primary=0.9e6, car_mass=40_000.0)
    np.testing.assert_allclose(other.static_wheel_loads(),
                               (40_000.0 / 8 + other.bogie_mass / 4 + other.wheelset_mass / 2) * g,
                               rtol=1e-12)


def test_static_equilibrium_on_rigid_rail():
    y, f = static_equilibrium(VEH, np.zeros((8, 8)), np.zeros(8))
    np.testing.assert_allclose(f, VEH.static_wheel_loads(), rtol=1e-12)
    # equilibrium of the suspension (linear part, exact after every Newton step)
    np.testing.assert_allclose(VEH.stiffness_matrix() @ y,
                               VEH.external_force() + VEH.contact_matrix() @ f,
                               atol=1e-9 * f.max())
    # an uneven rail (one wheel 0.1 mm high): converges and still carries the weight
    r = np.zeros(8)
    r[3] = 1e-4
    _, f2 = static_equilibrium(VEH, np.zeros((8, 8)), r)
    assert f2.sum() == pytest.approx(VEH.total_mass * VEH.gravity, rel=1e-12)
    assert f2[3] > f[3] and np.all(f2 > 0)


def test_static_equilibrium_displacements_consistent_with_hertz():
    y, f = static_equilibrium(VEH, np.zeros((8, 8)), np.zeros(8))
    delta = -VEH.contact_matrix().T @ y
    np.testing.assert_allclose(VEH.hertz_constant * delta**1.5, f, rtol=1e-10)


def test_suspension_frequencies_with_wheelsets_fixed():
    v = VEH
    free = np.arange(9)
    m = v.mass_matrix()[np.ix_(free, free)]
    k = v.stiffness_matrix()[np.ix_(free, free)]
    w2, _ = _omega2(m, k)
    kp, ks, lc, lt = v.k_primary, v.k_secondary, v.bogie_semi_spacing, v.semi_wheelbase
    yp, ys = 0.5 * v.primary_span, 0.5 * v.secondary_span
    mb = 2 * v.bogie_mass
    bounce = _pair(v.car_mass, mb, 4 * ks, -4 * ks, 4 * ks + 8 * kp)
    pitch = _pair(v.car_pitch_inertia, mb, 4 * ks * lc**2, -4 * ks * lc, 4 * ks + 8 * kp)
    kr = 2 * ks * ys**2 + v.k_antiroll  # secondary roll stiffness per bogie, with the bar
    roll = _pair(v.car_roll_inertia, 2 * v.bogie_roll_inertia, 2 * kr, -2 * kr,
                 2 * kr + 8 * kp * yp**2)
    bogie_pitch = 4 * kp * lt**2 / v.bogie_pitch_inertia
    bogie_roll_anti = (kr + 4 * kp * yp**2) / v.bogie_roll_inertia
    expected = np.sort(np.concatenate([bounce, pitch, roll, [bogie_pitch] * 2,
                                       [bogie_roll_anti]]))
    # round-off of both (eigh and the closed-form roots): sqrt(n) u lambda_max / lambda
    rtol = tolerances.eigenvalue_rtol(tolerances.normwise_condition(expected, w2.max()), len(w2))
    assert np.all(np.abs(w2 / expected - 1) <= rtol)
    # two-stage series springs, bogie mass neglected
    keq = (4 * ks) * (8 * kp) / (4 * ks + 8 * kp)
    f_bounce, f_pitch = np.sqrt([bounce[0], pitch[0]]) / (2 * np.pi)
    est_bounce = np.sqrt(keq / v.car_mass) / (2 * np.pi)
    est_pitch = np.sqrt(keq * lc**2 / v.car_pitch_inertia) / (2 * np.pi)
    assert f_bounce == pytest.approx(est_bounce, rel=0.01)  # 1.074 vs 1.076 Hz
    assert f_pitch == pytest.approx(est_pitch, rel=0.01)  # 1.299 vs 1.303 Hz
    assert 0.8 < f_bounce < 1.5 and 0.8 < f_pitch < 1.5  # typical passenger-coach values


def test_train_of_two_cars():
    second = RailVehicle(car_mass=40_000.0, car_length=24.0, bogie_semi_spacing=8.0)
    tr = Train([VEH, second], gaps=0.5)
    assert tr.n_dof == 34 == len(tr.dof_names) and tr.n_wheels == 16
    assert tr.dof_names[0] == "car0.body.z" and tr.dof_names[17] == "car1.body.z"
    lt = 1.28
    car0 = [0.0, -2 * lt, -19.0, -19.0 - 2 * lt]
    # front overhangs 13.2 - 9.5 - 1.28 = 2.42 and 12 - 8 - 1.28 = 2.72
    lead1 = -(26.4 - 2.42 + 0.5 + 2.72)
    car1 = lead1 + np.array([0.0, -2 * lt, -16.0, -16.0 - 2 * lt])
    np.testing.assert_allclose(tr.wheel_offsets, np.repeat(np.concatenate([car0, car1]), 2))
    assert VEH.front_overhang == pytest.approx(2.42)
    assert second.front_overhang == pytest.approx(2.72)
    np.testing.assert_array_equal(tr.wheel_rail, [0, 1] * 8)
    np.testing.assert_allclose(tr.static_wheel_loads(),
                               np.concatenate([VEH.static_wheel_loads(),
                                               second.static_wheel_loads()]), rtol=1e-12)
    # identical cars, no gap: offsets continue by the car length
    same = Train([VEH, VEH])
    np.testing.assert_allclose(same.wheel_offsets[8:], VEH.wheel_offsets - 26.4)
    _, f = static_equilibrium(same, np.zeros((16, 16)), np.zeros(16))
    np.testing.assert_allclose(f, same.static_wheel_loads(), rtol=1e-12)
    with pytest.raises(ValueError, match="Hertz constant"):
        Train([VEH, RailVehicle(wheel_radius=0.42)])


def test_train_coupler():
    second = RailVehicle(car_mass=45_000.0)
    free = Train([VEH, second])
    coupled = Train([VEH, second], k_coupler=5e6, c_coupler=1e4)
    m = coupled.mass_matrix()
    for a in (coupled.stiffness_matrix(), coupled.damping_matrix()):
        np.testing.assert_array_equal(a, a.T)
    # zero-energy modes: 5 per car, the coupler removes one (relative end displacement)
    for tr, n_zero in ((free, 10), (coupled, 9)):
        w2, _ = _omega2(m, tr.stiffness_matrix())
        zero = tolerances.zero_eigenvalue_bound(w2[-1], len(w2))
        assert np.sum(np.abs(w2) <= zero) == n_zero and w2[n_zero] > 1.0
    # the coupler acts between car 0's rear end and car 1's front end only
    y = np.zeros(34)
    y[0], y[1] = 1e-3, 1e-4  # car 0 bounce and pitch: rear end at 1e-3 - 1e-4 * 13.2
    f = coupled.stiffness_matrix() @ y - free.stiffness_matrix() @ y
    d = 1e-3 - 1e-4 * 13.2
    np.testing.assert_allclose(f[[0, 1, 17, 18]], 5e6 * d * np.array([1, -13.2, -1, -13.2]),
                               rtol=1e-12)
    assert np.count_nonzero(f) == 4
    # statics: the coupler shares load between the cars, the total weight is carried
    loads = coupled.static_wheel_loads()
    assert loads.sum() == pytest.approx(coupled.total_mass * VEH.gravity, rel=1e-12)
    assert loads[6:8].sum() > free.static_wheel_loads()[6:8].sum()  # car 0 rear takes load
    _, fe = static_equilibrium(coupled, np.zeros((16, 16)), np.zeros(16))
    assert fe.sum() == pytest.approx(loads.sum(), rel=1e-12)


def test_irregularity_with_vehicle_layout():
    prof = RailProfile([-100.0, 100.0], [[0.0, 0.0], [1e-3, 1e-3]])
    flat = WheelFlat(0.5e-3, 0.05, wheels=[4], wheel_radius=VEH.wheel_radius)
    irr = Irregularity(prof, [flat], wheel_rail=VEH.wheel_rail)
    h = irr(30.0 + VEH.wheel_offsets)
    expected = np.tile([0.0, 1e-3], 4)
    expected[4] += flat.profile(30.0 + VEH.wheel_offsets[4])
    np.testing.assert_allclose(h, expected, atol=1e-18)


def test_anti_roll_bar_static_roll_stiffness():
    """Manchester Benchmark anti-roll bar (940 kN m/rad per bogie): a roll moment on the
    car body, wheelsets held, turns it by M / K with K the series/parallel combination of
    secondary springs + bar (per bogie) and primary springs."""
    moment = 10e3
    for k_bar in (0.0, 940e3):
        v = RailVehicle(k_antiroll=k_bar)
        free = np.arange(9)  # body and bogies; the wheelsets are held
        k = v.stiffness_matrix()[np.ix_(free, free)]
        f = np.zeros(9)
        f[2] = moment
        theta = np.linalg.solve(k, f)[2]
        ks_roll = 2 * v.k_secondary * (0.5 * v.secondary_span) ** 2 + k_bar
        kp_roll = 4 * v.k_primary * (0.5 * v.primary_span) ** 2
        expected = 2.0 / (1.0 / ks_roll + 1.0 / kp_roll)
        assert moment / theta == pytest.approx(expected, rel=1e-12)
        assert v.roll_stiffness() == pytest.approx(expected, rel=1e-12)
    # the bar stiffens the body roll from 1.46 to 2.63 MN m/rad (per bogie the secondary
    # springs give 2 x 0.43 MN/m x 1 m^2 = 0.86 MN m/rad, the primary 4 x 1.22 = 4.88)
    assert RailVehicle().roll_stiffness() == pytest.approx(
        2 / (1 / (0.86e6 + 0.94e6) + 1 / 4.88e6), rel=1e-12)
    assert RailVehicle().k_antiroll == 940e3
    # it acts on relative roll only: bounce and pitch are unchanged
    a, b = RailVehicle(k_antiroll=0.0).stiffness_matrix(), RailVehicle().stiffness_matrix()
    diff = np.abs(b - a)
    assert set(np.flatnonzero(diff.sum(axis=0))) == {2, 5, 8}


def test_every_vehicle_satisfies_the_vehicle_protocol():
    from railvib_hpc.mbs import SuspendedWheelset, Vehicle

    for veh in (SuspendedWheelset(), RailVehicle(), Train([RailVehicle(), RailVehicle()])):
        assert isinstance(veh, Vehicle), type(veh).__name__
        assert len(veh.wheel_rail) == len(veh.wheel_offsets) == veh.n_wheels
        assert veh.contact_matrix().shape == (veh.n_dof, veh.n_wheels)
    assert not isinstance(object(), Vehicle)
    # the integrators name what a non-vehicle lacks
    from railvib_hpc.mbs import simulate_vehicle

    with pytest.raises(TypeError, match=r"not a railvib_hpc\.mbs\.Vehicle: it lacks conicity"):
        simulate_vehicle(np.ones(2), 0.0, None, object(), 0.0, 1.0, 1.0)


def _dense_static_wheel_loads(vehicle) -> np.ndarray:
    """The dense saddle-point solve that :meth:`static_wheel_loads` replaced (reference)."""
    k, b, f = vehicle.stiffness_matrix(), vehicle.contact_matrix(), vehicle.external_force()
    nd, nw = b.shape
    a = np.block([[k, -b], [b.T, np.zeros((nw, nw))]])
    return np.linalg.solve(a, np.concatenate([f, np.zeros(nw)]))[nd:], np.linalg.cond(a)


@pytest.mark.parametrize("k_coupler", [0.0, 5e6])
def test_sparse_static_wheel_loads_match_the_dense_solve(k_coupler):
    """A three-car train of different cars (with and without couplers): the sparse solve
    gives the dense one's wheel loads to round-off. The saddle-point matrix's condition
    number (3e14-6e15: N/m against the constraint rows) says nothing of the loads: without
    couplers they are statically determinate (the lever rule, sums of a few terms), with
    them nearly so; measured 6e-16 and 7.5e-14, against 1e-12."""
    cars = [VEH, RailVehicle(car_mass=45_000.0), RailVehicle(car_mass=28_000.0,
                                                               k_primary=9e5)]
    train = Train(cars, gaps=[0.5, 0.0], k_coupler=k_coupler)
    dense, cond = _dense_static_wheel_loads(train)
    sparse = train.static_wheel_loads()
    off = np.abs(sparse - dense).max() / np.abs(dense).max()
    print(f"k_coupler {k_coupler:g}: sparse vs dense {off:.2e} (cond {cond:.2e})")
    assert off <= 1e-12
    assert sparse.sum() == pytest.approx(train.total_mass * VEH.gravity, rel=1e-12)


@pytest.mark.timeout(60)
def test_a_thousand_car_train_has_its_static_wheel_loads_at_once():
    """17,000 DOFs: the sparse solve's work grows with the train's length (the dense one
    took about 6 min and 5 GB); every car of identical cars carries the same loads."""
    train = Train([VEH] * 1000)
    loads = train.static_wheel_loads()
    np.testing.assert_allclose(loads, np.tile(VEH.static_wheel_loads(), 1000), rtol=1e-9)


@pytest.mark.timeout(120)
def test_a_thousand_car_train_is_refused_by_the_step_count_first(tmp_path, capsys):
    """``railvib transient`` with ``vehicle.n_cars = 1000`` (1.4e6 steps) is refused by the
    step-count pre-check in one line, before anything solves for the train (the hang was
    the reuse check's dense static solve, run before the pre-check)."""
    from pathlib import Path

    from railvib_hpc.cli import run

    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "out"
    code = run(["transient", str(root / "jobs" / "whole_train.toml"), "--out", str(out),
                "--set", "mesh.refinement=0.5", "--set", "output.dt=0.01",
                "--set", "vehicle.n_cars=1000"])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, err
    assert len(lines) == 1 and "steps of the automatic step" in lines[0] \
        and "more than the limit of 200,000" in lines[0], err
    assert not (out / "mesh.h5").exists()
