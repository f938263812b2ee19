"""Two trains on two tracks (``track.count = 2``, ``[train2]``, ``mbs.train.Traffic``).

* A train that never reaches the flexible rail leaves the other's run unchanged.
* Mirror symmetry: track 2's rails are track 1's mirrored about the middle of the rails,
  and the second train runs the opposite way from the mirrored start. Both trains then
  load the same modal rows at every instant, so their contact forces are equal (to the
  contact Newton tolerance) although every wheel position, speed sign and rail index of
  train 2 goes through the two-track code path.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mbs_beams import ss_beam

from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError
from railvib_hpc.mbs import RailCoupling, SuspendedWheelset, simulate_vehicle
from railvib_hpc.mbs.case_vehicle import build_vehicle, mirror_x, passage, second_train_layout
from railvib_hpc.mbs.integrate import contact_tolerance
from railvib_hpc.mbs.train import RailVehicle, Traffic

ROOT = Path(__file__).resolve().parents[2]
TWO = {"track.count": 2, "geometry.ys0": 14.0}


def thesis_case(**changes) -> Case:
    return Case.from_file(ROOT / "jobs" / "thesis_baseline.toml").replace({**TWO, **changes})


def track_rails(case: Case, n_modes: int = 30):
    """Rails 0, 1 on a simply supported beam over the flexible rail [X1, X4]; rails 2, 3
    the same mirrored about the middle of the rails (X0 + X4 + rigid_length) / 2."""
    x1, x4 = case["geometry.x1"], case["geometry.x4"]
    omega, rail = ss_beam(x4 - x1, 6.4e6, 60.0, n_modes, 217)
    xs = rail.x_nodes + x1
    assert mirror_x(case, xs) == pytest.approx(xs[::-1], abs=1e-12)      # symmetric grid
    r = RailCoupling(xs, rail.phi_w, rail.phi_r)
    m = RailCoupling(xs, rail.phi_w[:, ::-1], -rail.phi_r[:, ::-1])
    return omega, (r, r, m, m)


def newton_bound(vehicle, f: np.ndarray) -> float:
    """How far two runs of the same equations may differ in contact force: each contact
    solve stops within ``contact_tolerance`` of the Hertz penetration delta, i.e. within
    1.5 tol / delta of the force (F ~ delta^1.5); ten steps' worth."""
    delta = (vehicle.static_wheel_loads().max() / vehicle.hertz_constant) ** (2 / 3)
    return 10 * 1.5 * contact_tolerance(vehicle) / delta * float(np.abs(f).max())


def test_a_train_that_never_arrives_changes_nothing():
    case = thesis_case(**{"train2.t_start": 100.0})
    omega, rails = track_rails(case)
    both = build_vehicle(case)
    one = both.trains[0]
    run = passage(case, both, rails[0].x_nodes[-1])
    t_end = 0.6
    a = simulate_vehicle(omega, 0.02, rails[:2], one, case["vehicle.x_start"],
                         case["vehicle.speed"], t_end, dt=2e-4)
    b = simulate_vehicle(omega, 0.02, rails, both, case["vehicle.x_start"], run["speeds"],
                         t_end, dt=2e-4)
    # the contact Newton solve of four wheels stops at another iterate than that of two
    bound = newton_bound(both, a.contact_force)
    assert np.max(np.abs(a.contact_force - b.contact_force[:, :2])) <= bound
    rel = bound / np.abs(a.contact_force).max()
    assert np.max(np.abs(a.q - b.q)) <= rel * np.abs(a.q).max()
    # the second train runs on rigid ground far away: the Hertz equilibrium the first one
    # had on the rigid entry rail at t = 0, all the time
    assert np.max(np.abs(b.contact_force[:, 2:] - a.contact_force[0])) <= bound


@pytest.mark.parametrize("vehicle", ["wheelset", "vehicle"])
def test_opposite_train_on_the_mirrored_track_feels_the_same_forces(vehicle):
    case = thesis_case(**{"vehicle.type": vehicle, "vehicle.x_start": 1.0,
                          "train2.direction": "opposite", "train2.t_start": 0.0})
    omega, rails = track_rails(case)
    both = build_vehicle(case)
    assert isinstance(both, Traffic) and both.wheel_rail.max() == 3
    run = passage(case, both, rails[0].x_nodes[-1])
    assert (run["speeds"] < 0).sum() == both.trains[1].n_wheels
    t_end = 0.5
    res = simulate_vehicle(omega, 0.02, rails, both, case["vehicle.x_start"], run["speeds"],
                           t_end, dt=2e-4)
    n1 = both.trains[0].n_wheels
    f1, f2 = res.contact_force[:, :n1], res.contact_force[:, n1:]
    x1, x2 = res.x[:, :n1], res.x[:, n1:]
    assert x2 == pytest.approx(mirror_x(case, x1), abs=1e-9)
    assert np.ptp(f1) > 1e-3 * np.abs(f1).max()                 # the track is felt
    assert np.max(np.abs(f1 - f2)) <= newton_bound(both, f1)


#: A heavier second vehicle of each type: keys that differ from [vehicle]'s defaults.
HEAVY = {"wheelset": {"wheelset_mass": 2400.0, "preload": 2.0e4, "k_suspension": 4.0e4},
         "vehicle": {"car_mass": 45000.0, "k_primary": 2.0e6, "bogie_mass": 3000.0}}


@pytest.mark.parametrize("vehicle", ["wheelset", "vehicle"])
def test_own_vehicles_swap_under_the_mirror(vehicle):
    """Train 2 with its own, heavier vehicle ([train2.vehicle]) on the mirrored track. By
    the mirror symmetry, swapping the two vehicles between the trains swaps their contact
    forces: what the heavy train feels on track 2 it feels on track 1, under the same
    light train on the other track. Both runs go through the two-track code path with two
    different vehicles."""
    from railvib_hpc.validation import ALL_KEYS

    heavy = HEAVY[vehicle]
    light = {k: ALL_KEYS[f"vehicle.{k}"].default for k in heavy}
    base = {"vehicle.type": vehicle, "vehicle.x_start": 1.0, "train2.direction": "opposite"}
    forces = []
    for first, second in ((light, heavy), (heavy, light)):
        case = thesis_case(**base, **{f"vehicle.{k}": v for k, v in first.items()},
                           **{f"train2.vehicle.{k}": v for k, v in second.items()})
        omega, rails = track_rails(case)
        both = build_vehicle(case)
        loads = [t.static_wheel_loads() for t in both.trains]
        run = passage(case, both, rails[0].x_nodes[-1])
        # 0.4 s: both trains on the flexible rail (a wheel reaching the rigid exit rail at
        # ~0.45 s kicks the contact iterates apart by 3e-4 N, within but near the bound)
        res = simulate_vehicle(omega, 0.02, rails, both, case["vehicle.x_start"],
                               run["speeds"], 0.4, dt=2e-4)
        n1 = both.trains[0].n_wheels
        forces.append((res.contact_force[:, :n1], res.contact_force[:, n1:], both, loads))
    (a1, a2, both, loads), (b1, b2, _, loads_b) = forces
    # the heavy vehicle's static wheel loads are its own (hand counts in the next test)
    assert loads[1].max() > 1.1 * loads[0].max()
    assert loads_b[0] == pytest.approx(loads[1], rel=1e-14)
    bound = newton_bound(both, a2)
    assert np.abs(a2).max() > 1.1 * np.abs(a1).max()          # the heavy train presses harder
    assert np.max(np.abs(a2 - b1)) <= bound and np.max(np.abs(a1 - b2)) <= bound


def test_own_vehicle_static_loads_and_moving_forces_are_its_own():
    """Static wheel loads against hand counts: a wheelset carries m g / 2 + preload per
    wheel (the preload is per side); a car (body + 2 bogies + 4 wheelsets) / 8 of its
    weight; a moving force train its own force and axles."""
    from railvib_hpc.mbs.case_vehicle import moving_loads, static_wheel_load

    g = 9.80665
    case = thesis_case(**{"train2.vehicle.wheelset_mass": 2400.0,
                          "train2.vehicle.preload": 2.0e4})
    loads = [t.static_wheel_loads() for t in build_vehicle(case).trains]
    assert loads[0] == pytest.approx(1568.0 * g / 2, rel=1e-12)
    assert loads[1] == pytest.approx(2400.0 * g / 2 + 2.0e4, rel=1e-12)
    assert static_wheel_load(case) == pytest.approx(2400.0 * g / 2 + 2.0e4, rel=1e-12)
    case = thesis_case(**{"vehicle.type": "vehicle", "train2.vehicle.car_mass": 45000.0,
                          "train2.vehicle.car_wheelset_mass": 2000.0})
    loads = [t.static_wheel_loads() for t in build_vehicle(case).trains]
    assert loads[0] == pytest.approx((32000 + 2 * 2615 + 4 * 1813) * g / 8, rel=1e-12)
    assert loads[1] == pytest.approx((45000 + 2 * 2615 + 4 * 2000) * g / 8, rel=1e-12)
    case = thesis_case(**{"vehicle.type": "moving_force", "vehicle.force": 5.0e4,
                          "train2.vehicle.force": 8.0e4,
                          "train2.vehicle.axle_offsets": [0.0, -2.5]})
    forces, offsets, rails, _ = moving_loads(case)
    assert forces.tolist() == [5.0e4] * 2 + [8.0e4] * 4
    assert rails.tolist() == [0, 1, 2, 3, 2, 3]
    far = mirror_x(case, case["vehicle.x_start"]) - case["vehicle.x_start"]
    assert offsets[2:].tolist() == pytest.approx([far, far, far + 2.5, far + 2.5])


def test_second_train_layout_same_direction_and_delay():
    case = thesis_case(**{"train2.direction": "same", "train2.t_start": 0.5,
                          "train2.speed": 20.0})
    pos, v = second_train_layout(case, np.array([0.0, -2.5]))
    assert v == 20.0 and pos.tolist() == pytest.approx([-10.0, -12.5])
    case = thesis_case(**{"train2.t_start": 0.5, "train2.speed": 20.0})   # opposite
    pos, v = second_train_layout(case, np.array([0.0, -2.5]))
    far = case["geometry.x4"] + case["track.rigid_length"]
    assert v == -20.0 and pos.tolist() == pytest.approx([far + 10.0, far + 12.5])
    # two cars in the second train, one in the first
    traffic = build_vehicle(thesis_case(**{"vehicle.type": "vehicle", "train2.n_cars": 2}))
    assert [t.n_wheels for t in traffic.trains] == [8, 16]
    assert isinstance(traffic.trains[0], RailVehicle)


@pytest.mark.parametrize("changes, key, words", [
    ({"track.count": 3}, "track.count", "must be 1 or 2"),
    ({"track.spacing": 2.0}, "track.spacing", "sleepers must not touch"),
    ({"geometry.ys0": 8.25}, "geometry.ys0", "beyond the embankment of the second track"),
    ({"track.count": 1, "train2.t_start": 2.0}, "train2.t_start",
     "applies to a second track (track.count = 2) only; here track.count = 1"),
    ({"track.count": 1, "train2.vehicle.car_mass": 4.0e4}, "train2.vehicle",
     "applies to a second track (track.count = 2) only"),
    ({"train2.vehicle.car_mass": 4.0e4}, "train2.vehicle.car_mass",
     "applies to vehicle.type = 'vehicle' only; here vehicle.type = 'wheelset'"),
    ({"train2.enabled": False, "train2.speed": 20.0}, "train2.speed",
     "applies to a second train (train2.enabled = True) only"),
    ({"train2.vehicle.speed": 20.0}, "train2.vehicle.speed", "are train2.speed, n_cars"),
    ({"train2.vehicle.type": "vehicle"}, "train2.vehicle.type", "the model type"),
    ({"train2.vehicle.car_mass": -1.0}, "train2.vehicle.car_mass", "must be > 0"),
    ({"vehicle.type": "vehicle", "train2.vehicle.bogie_spacing": 2.0},
     "train2.vehicle.wheelbase", "must be smaller than train2.vehicle.bogie_spacing = 2 m"),
])
def test_bad_tracks_get_one_clear_line(changes, key, words):
    with pytest.raises(CaseError) as info:
        thesis_case(**changes)
    text = str(info.value)
    assert key in text and words in text and "\n" not in text.strip()


def test_traffic_refuses_mixed_wheels():
    w = SuspendedWheelset()
    with pytest.raises(ValueError, match="different Hertz constant"):
        Traffic([w, SuspendedWheelset(wheel_radius=0.5)], [[0.0, 0.0], [0.0, 0.0]],
                [1.0, 1.0], [0, 2])
