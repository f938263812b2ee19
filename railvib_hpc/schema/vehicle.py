"""The loads: the ``[vehicle]``, ``[train2]``, ``[irregularity]`` and ``[load]`` sections.
"""

from __future__ import annotations

from typing import Any

from .conditions import (
    BARE_SOIL,
    CARS,
    MOVING_FORCES,
    ON_TRACK,
    PROFILE_FILE,
    RANDOM_PROFILE,
    SECOND_TRACK,
    SECOND_TRAIN,
    SECOND_TRAIN_CARS,
    WHEEL_FLATS,
    WHEELS,
    WHEELSET,
    WHEELSET_MASS,
)
from .param import _MANCHESTER, _T2, Param

#: The sections of this module, in the schema's order.
VEHICLE_SECTIONS: dict[str, dict[str, Any]] = {
    "vehicle": {
        "type": Param("wheelset", "str", "-",
                      "load model: constant moving forces, the thesis's suspended wheelset "
                      "(Table II), or cars with 2 bogies and 4 wheelsets each",
                      choices=("moving_force", "wheelset", "vehicle"),
                      source="thesis §4.4: suspended wheelset (SAMS)", applies=ON_TRACK),
        "speed": Param(30.0, "float", "m/s", "running speed", "pos",
                       source="thesis §4.4: 30 m/s (67 mph)", applies=ON_TRACK),
        "x_start": Param(0.0, "float", "m",
                         "position of the leading wheel at t = 0 (on the rigid entry rail; 0: "
                         "its start, the thesis's time origin)",
                         source="thesis §2.2 and §6.6: wheel starts at x = 0 on the rigid rail",
                         applies=ON_TRACK),
        "x_end": Param(0.0, "float", "m",
                       "the run ends when the last wheel reaches this position (0: the end of "
                       "the rigid exit rail)", "nonneg", applies=ON_TRACK),
        "t_after": Param(0.0, "float", "s",
                         "extra time simulated after the last wheel reaches x_end", "nonneg",
                         applies=ON_TRACK),
        "force": Param(0.0, "float", "N",
                       "moving_force: force per wheel (0: the wheelset's static wheel load, "
                       "mass * g / 2)", "nonneg", applies=MOVING_FORCES),
        "axle_offsets": Param([0.0], "floats", "m",
                              "moving_force: axle positions relative to the leading axle "
                              "(<= 0, one force per rail and axle)", applies=MOVING_FORCES),
        "wheelset_mass": Param(1568.0, "float", "kg", "wheelset mass (thesis Table II)", "pos",
                               source=f"{_T2}: mass 1568 kg", applies=WHEELSET_MASS),
        "wheelset_roll_inertia": Param(656.0, "float", "kg m^2",
                                       "wheelset roll inertia Ixx (thesis Table II)", "pos",
                                       source=f"{_T2}: Ixx 656 kg m^2", applies=WHEELSET),
        "wheel_radius": Param(0.46, "float", "m", "wheel rolling radius (Hertz constant)", "pos",
                              source="Jenkins et al. (1974) / benchmarks.md: R = 0.46 m",
                              applies=WHEELS),
        "contact_span": Param(1.5, "float", "m",
                              "lateral distance of the two wheel-rail contact points", "pos",
                              applies=WHEELS),
        "suspension_span": Param(2.0, "float", "m",
                                 "wheelset: lateral distance of the two suspension springs",
                                 "pos", applies=WHEELSET),
        "k_suspension": Param(25_000.0, "float", "N/m",
                              "wheelset: suspension stiffness per side (thesis Table II)",
                              "nonneg",
                              source=f"{_T2}: K_l1 = k_l2 = 25000 (read as vertical, per side)",
                              applies=WHEELSET),
        "c_suspension": Param(1_000.0, "float", "N s/m",
                              "wheelset: suspension damping per side (thesis Table II)",
                              "nonneg",
                              source=f"{_T2}: K_t1 = k_t2 = 1000 N.s/m (read as damping, per side; "
                                     "see docs/thesis.md for the other reading)", applies=WHEELSET),
        "preload": Param(0.0, "float", "N",
                         "wheelset: static downward force of the frame per side (share of a "
                         "car body; 0 in the thesis)", "nonneg", applies=WHEELSET),
        "k_lateral": Param(25_000.0, "float", "N/m",
                           "wheelset: lateral suspension stiffness (not in Table II: the vertical "
                           "value)", "nonneg", applies=WHEELSET),
        "c_lateral": Param(1_000.0, "float", "N s/m", "wheelset: lateral suspension damping",
                           "nonneg", applies=WHEELSET),
        "conicity": Param(0.025, "float", "-",
                          "wheelset: equivalent tread conicity (UIC 1:40); the contact normals "
                          "lean inwards and couple lateral motion and the rails' lateral modes",
                          "nonneg", source="UIC 1:40 tread inclination", applies=WHEELSET),
        "k_hertz": Param(0.0, "float", "N/m^1.5",
                         "Hertz constant K_H (0: Jenkins' formula from wheel_radius)", "nonneg",
                         applies=WHEELS),
        "contact_damping": Param(0.0, "float", "N s/m^2",
                                 "Hertz contact damping C in F = K_H d^1.5 - C d' |d| (the "
                                 "thesis's formula; it gives no value)", "nonneg",
                                 source="thesis §4.2 formula F = K_H d^1.5 + C d' |d|; C not "
                                        "given", applies=WHEELS),
        "supercritical": Param(False, "bool", "-",
                               "accept a train at or above the ground's Rayleigh speed "
                               "(the critical speed of a track on soft soil: the response "
                               "grows and forms a Mach cone; without this key such a speed "
                               "is refused)",
                               source="the critical speed of a track on soft soil (Krylov "
                                      "1995; Madshus & Kaynia 2000): refused unless "
                                      "accepted"),
        "drop_height": Param(0.0, "float", "m",
                             "initial condition: 0 starts the vehicle at rest in static "
                             "equilibrium; > 0 drops it: at t = 0 the track is at rest and "
                             "every body hangs rigidly lifted from its static equilibrium so "
                             "that the wheels are this far above the rail (the thesis's "
                             "wheelset is 'dropped from a small distance', unspecified)",
                             "nonneg",
                             source="thesis §2.2: 'dropped from a small distance'; not given",
                             applies=WHEELS),
        "n_cars": Param(1, "int", "-", "vehicle: number of coupled cars in the train", "pos",
                        applies=CARS),
        "car_mass": Param(32_000.0, "float", "kg", "vehicle: car body mass (defaults: Manchester "
                          "Benchmark passenger coach, Iwnicki 1998)", "pos", source=_MANCHESTER,
                          applies=CARS),
        "car_pitch_inertia": Param(1.97e6, "float", "kg m^2", "vehicle: car body pitch inertia",
                                   "pos", source=_MANCHESTER, applies=CARS),
        "car_roll_inertia": Param(5.68e4, "float", "kg m^2", "vehicle: car body roll inertia",
                                  "pos", source=_MANCHESTER, applies=CARS),
        "bogie_mass": Param(2_615.0, "float", "kg", "vehicle: bogie frame mass", "pos",
                            source=_MANCHESTER, applies=CARS),
        "bogie_pitch_inertia": Param(1_476.0, "float", "kg m^2", "vehicle: bogie pitch inertia",
                                     "pos", source=_MANCHESTER, applies=CARS),
        "bogie_roll_inertia": Param(1_722.0, "float", "kg m^2", "vehicle: bogie roll inertia",
                                    "pos", source=_MANCHESTER, applies=CARS),
        "car_wheelset_mass": Param(1_813.0, "float", "kg", "vehicle: wheelset mass", "pos",
                                   source=_MANCHESTER, applies=CARS),
        "car_wheelset_roll_inertia": Param(1_120.0, "float", "kg m^2",
                                           "vehicle: wheelset roll inertia", "pos",
                                           source=_MANCHESTER, applies=CARS),
        "k_primary": Param(1.22e6, "float", "N/m",
                           "vehicle: primary suspension stiffness per axle box", "nonneg",
                           source=f"{_MANCHESTER}: 1.22 MN/m per axle box (TTB-2D, "
                                  "github.com/DanielCanteroNTNU/TTB-2D "
                                  "TrainProp_Manchester_BenchMark.m, uses 1.20 MN/m)",
                           applies=CARS),
        "c_primary": Param(4.0e3, "float", "N s/m",
                           "vehicle: primary suspension damping per axle box", "nonneg",
                           source=_MANCHESTER, applies=CARS),
        "k_secondary": Param(4.3e5, "float", "N/m",
                             "vehicle: secondary suspension stiffness per side", "nonneg",
                             source=_MANCHESTER, applies=CARS),
        "c_secondary": Param(2.0e4, "float", "N s/m",
                             "vehicle: secondary suspension damping per side", "nonneg",
                             source=_MANCHESTER, applies=CARS),
        "k_antiroll": Param(940e3, "float", "N m/rad",
                            "vehicle: anti-roll bar stiffness per bogie (roll moment between "
                            "car body and bogie frame per radian of relative roll)", "nonneg",
                            source=f"{_MANCHESTER}: anti-roll bar 940 kN m/rad per bogie",
                            applies=CARS),
        "primary_span": Param(2.0, "float", "m",
                              "vehicle: lateral distance of the primary springs", "pos",
                              source=_MANCHESTER, applies=CARS),
        "secondary_span": Param(2.0, "float", "m",
                                "vehicle: lateral distance of the secondary springs", "pos",
                                source=_MANCHESTER, applies=CARS),
        "bogie_spacing": Param(19.0, "float", "m", "vehicle: distance between the bogie centres",
                               "pos", source=_MANCHESTER, applies=CARS),
        "wheelbase": Param(2.56, "float", "m", "vehicle: axle distance within a bogie", "pos",
                           source=_MANCHESTER, applies=CARS),
        "car_length": Param(26.4, "float", "m",
                            "vehicle: length over couplers (distance of successive cars)", "pos",
                            source="UIC-Z coach length over couplers (not in the benchmark)",
                            applies=CARS),
        "coupler_stiffness": Param(0.0, "float", "N/m",
                                   "vehicle: vertical stiffness coupling successive car ends",
                                   "nonneg", applies=CARS),
    },
    "train2": {
        "enabled": Param(True, "bool", "-",
                         "with track.count = 2: a second train runs on track 2 (false: the "
                         "track is there, unloaded)", applies=SECOND_TRACK),
        "direction": Param("opposite", "str", "-",
                           "the second train's direction: 'same' as [vehicle] (+x) or "
                           "'opposite' (-x, from the far end of the rigid exit rail)",
                           choices=("same", "opposite"), applies=SECOND_TRAIN),
        "t_start": Param(0.0, "float", "s",
                         "delay of the second train: it is where [vehicle]'s train would be "
                         "at t = 0 (mirrored for 'opposite') t_start later", "nonneg",
                         applies=SECOND_TRAIN),
        "speed": Param(0.0, "float", "m/s", "the second train's speed (0: vehicle.speed)",
                       "nonneg", applies=SECOND_TRAIN),
        "n_cars": Param(0, "int", "-",
                        "vehicle.type = 'vehicle': the second train's cars (0: vehicle.n_cars)",
                        "nonneg", applies=SECOND_TRAIN_CARS),
    },
    "irregularity": {
        "type": Param("none", "str", "-",
                      "vertical rail irregularity: none, a profile file, or a seeded random "
                      "profile from the FRA or ISO 8608 spectrum",
                      choices=("none", "file", "fra", "iso8608"), applies=WHEELS),
        "file": Param("", "str", "-",
                      "profile file: columns x z, or x z_rail0 z_rail1 [m] (relative to the case "
                      "file)", applies=PROFILE_FILE),
        "track_class": Param("6", "str", "-",
                             "FRA class 1..6 or ISO 8608 class A..H",
                             choices=("1", "2", "3", "4", "5", "6",
                                      "A", "B", "C", "D", "E", "F", "G", "H"),
                                      applies=RANDOM_PROFILE),
        "seed": Param(1, "int", "-", "random seed of the profile", "nonneg",
                      applies=RANDOM_PROFILE),
        "wavelength_min": Param(1.524, "float", "m",
                                "shortest wavelength of the random profile (the FRA spectra are "
                                "fitted to 1.524-304.8 m, i.e. 5-1000 ft)", "pos",
                                source="FRA spectra fitted to 5-1000 ft (Hamid et al., "
                                       "FRA/ORD-80/28, 1980; 1.524 m = 5 ft)",
                                applies=RANDOM_PROFILE),
        "wavelength_max": Param(30.0, "float", "m", "longest wavelength of the random profile",
                                "pos", applies=RANDOM_PROFILE),
        "flat_depth": Param(0.0, "float", "m", "wheel flat depth (0: no flat)", "nonneg",
                            applies=WHEELS),
        "flat_length": Param(0.05, "float", "m", "wheel flat length", "pos", applies=WHEEL_FLATS),
        "flat_wheels": Param([0.0], "floats", "-", "indices of the wheels with a flat",
                             applies=WHEEL_FLATS),
    },
    "load": {
        "force": Param(0.0, "float", "N",
                       "with track.count = 0: downward force of each point load moving over "
                       "the bare soil surface (0: no surface load; STEM's 'moving load on "
                       "soil', the verification against the steady state of a load moving "
                       "over an elastic half-space, railvib_hpc.fem.halfspace)", "nonneg",
                       source="a verification load, no default model: STEM's moving "
                              "load on soil, against Eason 1965 / de Barros & Luco 1994 "
                              "(docs/verification.md)",
                       applies=BARE_SOIL),
        "speed": Param(30.0, "float", "m/s",
                       "the surface load's speed along +x (at or above the ground's Rayleigh "
                       "speed only with vehicle.supercritical = true)", "pos",
                       source="vehicle.speed's default", applies=BARE_SOIL),
        "y": Param(0.0, "float", "m",
                   "lateral position of the load's path on the ground (the line y = load.y, "
                   "z = geometry.z1); it must cross the soil", applies=BARE_SOIL),
        "x_start": Param(0.0, "float", "m",
                         "position of the leading load at t = 0 (a load off the soil's ground "
                         "is off)", applies=BARE_SOIL),
        "x_end": Param(0.0, "float", "m",
                       "the run ends when the last load reaches this position (0: the soil's "
                       "end along x, geometry.x4 + domain.extra_length)", "nonneg",
                       applies=BARE_SOIL),
        "t_after": Param(0.0, "float", "s",
                         "extra time simulated after the last load reaches load.x_end",
                         "nonneg", applies=BARE_SOIL),
        "offsets": Param([0.0], "floats", "m",
                         "positions of the loads along x relative to the leading one "
                         "(<= 0; one load of load.force each)", applies=BARE_SOIL),
        "start": Param("ramp", "str", "-",
                       "how the loads start at t = 0: 'ramp' (the soil at rest, the forces "
                       "switched on over load.ramp_time while the loads move at load.speed; "
                       "0: a step, which radiates a pulse) or 'static' (the soil at rest in "
                       "static equilibrium under the full forces at their start positions, "
                       "K u0 = f0, velocities zero; the loads then run up to load.speed "
                       "over load.ramp_time, 0: at once, which radiates the moving field's "
                       "difference from the static one as a pulse; needs the box held "
                       "statically: a fixed, roller, caughey or pml face, or absorbing "
                       "faces with boundary.virtual_thickness > 0)",
                       choices=("ramp", "static"),
                       source="'ramp': the surface load's start before 'static' existed "
                              "(the results of earlier cases unchanged)", applies=BARE_SOIL),
        "ramp_time": Param(0.0, "float", "s",
                           "load.start = 'ramp': the forces grow as sin^2(pi t / (2 "
                           "ramp_time)) over this time, then stay (0: a step at t = 0, which "
                           "radiates a pulse); load.start = 'static': the loads' speed grows "
                           "so from 0 to load.speed (they cover load.speed x ramp_time / 2 in "
                           "it)", "nonneg", applies=BARE_SOIL),
        "half_width": Param(0.0, "float", "m",
                            "half-width a of each load's spreading along x, (1 + cos(pi s / "
                            "a)) / (2 a) over |s| <= a (0: a point load, the consistent load "
                            "of the element under it; a >= 2 element sizes keeps a point "
                            "load's grid pulses at speed / element size small)", "nonneg",
                            applies=BARE_SOIL),
        "frequency": Param(0.0, "float", "Hz",
                           "each load varies as cos(2 pi frequency t) after its switch-on (0: "
                           "constant): the moving harmonic load, which radiates Rayleigh "
                           "waves of wavelength (c_R -/+ speed) / frequency ahead of and "
                           "behind it (its plane-strain reference: "
                           "railvib_hpc.fem.halfspace_line); at most transient.f_max",
                           "nonneg", source="a verification load: the moving harmonic load "
                                            "in the moving frame of Sheng, Jones & Petyt "
                                            "1999 (docs/verification.md)",
                           applies=BARE_SOIL),
    },
}

#: [vehicle] keys the second train shares with the first: how the run goes (its own
#: speed, cars and delay are ``train2.speed``, ``n_cars``, ``t_start``), and the wheel-rail
#: contact law, which the integrators apply to every wheel alike (one Hertz constant,
#: contact damping and conicity; :class:`railvib_hpc.mbs.train.Traffic`). The model type
#: is shared for the same reason: a wheelset's contact normals lean with its conicity, a
#: car's (no lateral dynamics) do not.
TRAIN2_SHARED_VEHICLE_KEYS = ("type", "speed", "x_start", "x_end", "t_after", "drop_height",
                              "n_cars", "wheel_radius", "k_hertz", "contact_damping",
                              "conicity", "supercritical")
VEHICLE_SECTIONS["train2"]["vehicle"] = Param(
    {}, "vehicle", "-",
    "the second train's own vehicle, of [vehicle]'s type: a [train2.vehicle] table of the "
    "[vehicle] keys that differ (masses, inertias, suspension, spacings, axle_offsets, "
    "force); {} = [vehicle]'s vehicle",
    choices=tuple(k for k in VEHICLE_SECTIONS["vehicle"] if k not in TRAIN2_SHARED_VEHICLE_KEYS),
    applies=SECOND_TRAIN)
