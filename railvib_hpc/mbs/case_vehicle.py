"""The case's vehicle, second train, irregularity and passage: ``[vehicle]`` -> multibody inputs.

Translates the ``[vehicle]``, ``[train2]``, ``[irregularity]`` and ``track.count`` keys of
a case into the objects the time integration runs: the vehicle (:mod:`.vehicles`,
:mod:`.train`) or the moving forces, the wheels' layout, speeds and rails, the passage's
start, end and duration, and the irregularity each wheel sees (:mod:`.irregularity`). Used
by the ``mbs`` stage (:mod:`.stage`) and by the full-order solution
(:mod:`railvib_hpc.transient`).
"""

from __future__ import annotations

import numpy as np

from ..config import Case
from ..constants import STANDARD_GRAVITY
from ..errors import UserError
from ..site import train2_vehicle
from .vehicles import Vehicle


class MBSInputError(UserError):
    """The modal input of the multibody simulation is missing or inconsistent."""


def two_trains(case: Case) -> bool:
    """Whether a second train runs on track 2 (``track.count = 2``, ``train2.enabled``)."""
    return case["track.count"] == 2 and bool(case["train2.enabled"])


def tracks_line(case: Case) -> str | None:
    """One line on the second track and its train (None with one track)."""
    if case["track.count"] != 2:
        return None
    t2 = case["train2"]
    own = t2["vehicle"]
    vehicle = (f", its own {case['vehicle.type']} ("
               + ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"
                           for k, v in own.items()) + ")") if own else ""
    second = ("track 2 unloaded" if not t2["enabled"] else
              f"train 2 runs the {t2['direction']} direction, {t2['t_start']:g} s later, at "
              f"{t2['speed'] or case['vehicle.speed']:g} m/s{vehicle}")
    return (f"2, {case['track.spacing']:g} m apart (track 2 further from the building); "
            f"{second}")


def mirror_x(case: Case, x: np.ndarray | float) -> np.ndarray | float:
    """``x`` mirrored about the middle of the rails (rigid entry rail start ``X0`` to rigid
    exit rail end ``X4 + rigid_length``): where an 'opposite' train is when [vehicle]'s
    would be at ``x``."""
    lo = case["geometry.x0"]
    hi = case["geometry.x4"] + case["track.rigid_length"]
    return lo + hi - x


def second_train_layout(case: Case, offsets: np.ndarray) -> tuple[np.ndarray, float]:
    """Wheel positions at t = 0 relative to ``vehicle.x_start`` and the velocity of the
    second train, whose own wheel offsets are ``offsets`` (<= 0, leading wheel first)."""
    x0, t0 = case["vehicle.x_start"], case["train2.t_start"]
    v2 = case["train2.speed"] or case["vehicle.speed"]
    offsets = np.asarray(offsets, dtype=float)
    if case["train2.direction"] == "same":
        return offsets - v2 * t0, v2
    return mirror_x(case, x0) - x0 - offsets + v2 * t0, -v2


def build_vehicle(case: Case) -> Vehicle | None:
    """The vehicle of ``[vehicle]`` (None for ``moving_force``); with a second train on
    track 2 (:func:`two_trains`) both as one :class:`~.train.Traffic`."""
    first = _build_train(case["vehicle"], case["vehicle.n_cars"])
    if first is None or not two_trains(case):
        return first
    from .train import Traffic

    second = _build_train(train2_vehicle(case), case["train2.n_cars"] or case["vehicle.n_cars"])
    pos2, v2 = second_train_layout(case, second.wheel_offsets)
    return Traffic([first, second], positions=[first.wheel_offsets, pos2],
                   speeds=[case["vehicle.speed"], v2], rail_shift=[0, 2])


def _build_train(v: dict, n_cars: int) -> Vehicle | None:
    """One train of the vehicle keys ``v`` (``[vehicle]``'s, or the second train's) with
    ``n_cars`` cars (None for ``moving_force``)."""
    from .vehicles import SuspendedWheelset

    kh = v["k_hertz"] if v["k_hertz"] > 0 else None
    if v["type"] == "moving_force":
        return None
    if v["type"] == "wheelset":
        return SuspendedWheelset(
            mass=v["wheelset_mass"], roll_inertia=v["wheelset_roll_inertia"],
            wheel_radius=v["wheel_radius"], contact_span=v["contact_span"],
            suspension_span=v["suspension_span"], k_suspension=v["k_suspension"],
            c_suspension=v["c_suspension"], preload=v["preload"],
            contact_damping=v["contact_damping"], k_hertz=kh, k_lateral=v["k_lateral"],
            c_lateral=v["c_lateral"], conicity=v["conicity"])
    from .train import RailVehicle, Train

    car = RailVehicle(
        car_mass=v["car_mass"], car_pitch_inertia=v["car_pitch_inertia"],
        car_roll_inertia=v["car_roll_inertia"], bogie_mass=v["bogie_mass"],
        bogie_pitch_inertia=v["bogie_pitch_inertia"], bogie_roll_inertia=v["bogie_roll_inertia"],
        wheelset_mass=v["car_wheelset_mass"],
        wheelset_roll_inertia=v["car_wheelset_roll_inertia"],
        bogie_semi_spacing=0.5 * v["bogie_spacing"], semi_wheelbase=0.5 * v["wheelbase"],
        car_length=v["car_length"], wheel_radius=v["wheel_radius"],
        contact_span=v["contact_span"], primary_span=v["primary_span"],
        secondary_span=v["secondary_span"], k_primary=v["k_primary"], c_primary=v["c_primary"],
        k_secondary=v["k_secondary"], c_secondary=v["c_secondary"],
        k_antiroll=v["k_antiroll"], contact_damping=v["contact_damping"], k_hertz=kh)
    if n_cars == 1:
        return car
    return Train([car] * n_cars, k_coupler=v["coupler_stiffness"])


def build_irregularity(case: Case, wheel_rail: np.ndarray, x_range: tuple[float, float],
                       seed_shift: int = 0, flats: bool = True):
    """The rail irregularity and wheel flats of ``[irregularity]`` (None when smooth);
    a random profile draws with ``irregularity.seed + seed_shift``; ``flats = False``
    leaves the wheel flats out."""
    from .irregularity import Irregularity, RailProfile, WheelFlat

    irr = case["irregularity"]
    profile = None
    if irr["type"] == "file":
        profile = RailProfile.from_file(case.resolve(irr["file"]))
    elif irr["type"] in ("fra", "iso8608"):
        profile = RailProfile.from_psd(
            irr["type"], irr["track_class"], x_range, seed=irr["seed"] + seed_shift,
            wavelength_range=(irr["wavelength_min"], irr["wavelength_max"]))
    with_flats, flats = flats, ()
    if with_flats and irr["flat_depth"] > 0:
        wheels = [int(w) for w in irr["flat_wheels"]]
        bad = [w for w in wheels if w >= len(wheel_rail)]
        if bad:
            raise MBSInputError(f"irregularity.flat_wheels = {irr['flat_wheels']}: the vehicle "
                                f"has wheels 0..{len(wheel_rail) - 1}")
        flats = (WheelFlat(depth=irr["flat_depth"], length=irr["flat_length"], wheels=wheels,
                           wheel_radius=case["vehicle.wheel_radius"]),)
    if profile is None and not flats:
        return None
    return Irregularity(profile=profile, flats=flats, wheel_rail=wheel_rail)


def passage_irregularity(case: Case, vehicle, run: dict):
    """The irregularity the wheels of a run see (None when smooth): :func:`build_irregularity`
    over the x range the wheels cover; with two trains each train sees its own (a random
    profile of track 2 draws with ``irregularity.seed + 1``; wheel flats are on train 1)."""
    x0 = run["x_start"] + run["offsets"]
    x1 = x0 + run["speeds"] * run["t_end"]
    x_range = (float(min(x0.min(), x1.min())) - 1.0, float(max(x0.max(), x1.max())) + 1.0)
    from .train import Traffic

    if not isinstance(vehicle, Traffic):
        return build_irregularity(case, run["wheel_rail"], x_range)
    parts = [build_irregularity(case, np.asarray(t.wheel_rail), x_range, seed_shift=k,
                                flats=k == 0)
             for k, t in enumerate(vehicle.trains)]
    if all(p is None for p in parts):
        return None
    start = vehicle.wheel_start

    def heights(x_wheels: np.ndarray) -> np.ndarray:
        return np.concatenate([np.zeros(b - a) if p is None else p(x_wheels[a:b])
                               for p, a, b in zip(parts, start[:-1], start[1:])])

    return heights


def moving_loads(case: Case) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Forces, offsets (relative to ``vehicle.x_start``), rails and velocities of the
    ``moving_force`` loads (one per rail and axle; with two trains, the second's on rails
    2 and 3)."""
    def axles(v: dict) -> tuple[float, np.ndarray, np.ndarray]:
        force = v["force"] if v["force"] > 0 else 0.5 * v["wheelset_mass"] * STANDARD_GRAVITY
        offs = np.repeat(np.asarray(v["axle_offsets"], dtype=float), 2)
        return force, offs, np.tile([0, 1], len(v["axle_offsets"]))

    force, offs, rails = axles(case["vehicle"])
    forces, speeds = np.full(offs.size, force), np.full(offs.size, case["vehicle.speed"])
    if two_trains(case):
        force2, offs2, rails2 = axles(train2_vehicle(case))
        pos2, v2 = second_train_layout(case, offs2)
        offs, rails = np.concatenate([offs, pos2]), np.concatenate([rails, rails2 + 2])
        forces = np.concatenate([forces, np.full(pos2.size, force2)])
        speeds = np.concatenate([speeds, np.full(pos2.size, v2)])
    return forces, offs, rails, speeds


def passage(case: Case, vehicle, flexible_end: float) -> dict:
    """The run of ``[vehicle]``: loads or wheel layout, start and end, simulated time.

    Parameters
    ----------
    case
        The case.
    vehicle
        :func:`build_vehicle`'s vehicle (None: moving forces).
    flexible_end
        x of the end of the flexible rail [m] (the rigid exit rail follows).

    Returns
    -------
    dict
        ``forces`` (moving forces, else None), ``offsets``, ``wheel_rail``, ``speeds``
        (velocity along x, n_wheels each), ``x_start``, ``x_end``, ``t_end`` [s].
    """
    x_end = case["vehicle.x_end"] or flexible_end + case["track.rigid_length"]
    x_start, speed = case["vehicle.x_start"], case["vehicle.speed"]
    forces = None
    if vehicle is None:
        forces, offsets, wheel_rail, speeds = moving_loads(case)
    else:
        offsets = np.asarray(vehicle.wheel_offsets, dtype=float)
        wheel_rail = np.asarray(vehicle.wheel_rail)
        speeds = np.asarray(getattr(vehicle, "wheel_speeds", np.full(offsets.size, speed)),
                            dtype=float)
    # every wheel runs to x_end (a train in the opposite direction: to its mirror image)
    x0 = x_start + offsets
    goal = np.where(speeds > 0, x_end, mirror_x(case, x_end))
    t_end = float(np.max((goal - x0) / speeds)) + case["vehicle.t_after"]
    return {"forces": forces, "offsets": np.asarray(offsets, dtype=float),
            "wheel_rail": np.asarray(wheel_rail, dtype=np.int64), "x_start": x_start,
            "x_end": x_end, "t_end": t_end, "speeds": speeds}


def static_wheel_load(case: Case) -> float:
    """The largest static wheel (or moving) load of the case's vehicle [N]."""
    vehicle = build_vehicle(case)
    if vehicle is None:
        return float(np.max(moving_loads(case)[0]))
    return float(np.max(vehicle.static_wheel_loads()))
