"""Reduced multibody simulation: loads and vehicles rolling over a rail in modal coordinates.

Pure numpy, meant to run on rank 0. Modules:

* :mod:`.coupling` -- interpolation under a wheel / force distribution (Hermite or linear);
* :mod:`.contact` -- Hertz contact law and Jenkins' constant;
* :mod:`.propagator` -- exact modal step for piecewise-linear forces;
* :mod:`.vehicles` -- suspended wheelset and its static equilibrium;
* :mod:`.integrate` -- moving forces and the coupled wheelset-track time integration;
* :mod:`.results` -- result container and step-wise storage;
* :mod:`.modal_input` -- the rails' modal rows read from ``modes.h5``;
* :mod:`.static_correction` -- residual flexibility of the truncated modes at the wheels;
* :mod:`.irregularity` -- rail profiles (file, FRA/ISO 8608 spectra) and wheel flats;
* :mod:`.train` -- cars with two bogies and four wheelsets, trains;
* :mod:`.case_vehicle` -- the case's vehicle, second train, irregularity and passage;
* :mod:`.damping_model` -- the modal damping of the kept and residual modes;
* :mod:`.stage` -- the ``railvib mbs`` stage (modes.h5 -> mbs.h5 + plots).
"""

from .contact import hertz_force, hertz_penetration, jenkins_hertz_constant
from .coupling import RailCoupling, shape_functions
from .integrate import (
    PassageHistory,
    auto_time_step,
    coupled_energy,
    simulate_moving_force,
    simulate_vehicle,
    simulate_wheelset,
)
from .modal_input import RailModes, read_rail_modes
from .propagator import ModalPropagator, modal_propagator
from .vehicles import SuspendedWheelset, Vehicle, static_equilibrium

__all__ = [
    "ModalPropagator",
    "PassageHistory",
    "RailCoupling",
    "RailModes",
    "SuspendedWheelset",
    "Vehicle",
    "auto_time_step",
    "coupled_energy",
    "hertz_force",
    "hertz_penetration",
    "jenkins_hertz_constant",
    "modal_propagator",
    "read_rail_modes",
    "shape_functions",
    "simulate_moving_force",
    "simulate_vehicle",
    "simulate_wheelset",
    "static_equilibrium",
]
