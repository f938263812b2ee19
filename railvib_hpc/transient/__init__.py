"""Full-order time integration of the finite-element model (``railvib transient``).

Layers (each imports only downward): :mod:`.scheme` (generalized-alpha coefficients, time
step, accuracy; numpy), :mod:`.rail` (wheel-rail coupling on the rail DOFs; numpy),
:mod:`.petsc` (effective matrix, MUMPS factor, products; PETSc), :mod:`.integrate` (the
stepping loop with prescribed loads or a vehicle), :mod:`.output` (fields, probes),
:mod:`.engines` (the engines' matrices, systems, steps and initial state), :mod:`.engine`
(the engine protocol; one module per engine, :mod:`.direct_engine`, :mod:`.explicit_engine`,
:mod:`.imex_engine`, declared in :data:`railvib_hpc.time_engines.ENGINES`),
:mod:`.run_setup` (the run as one typed object), :mod:`.stage` (the command and its time
loop; ``transient.h5`` and the checkpoints are written through
:mod:`railvib_hpc.io.formats.transient`).

Why not PETSc's ``TSALPHA2`` (available in 3.18, the same Chung-Hulbert scheme): its step is
one nonlinear solve of the whole model, so the exact Hertz contact would re-factor the
Jacobian whenever a wheel moves or the contact stiffness changes. Splitting every step into
``u = K_eff^-1 rhs`` plus the rail columns ``K_eff^-1 E_D`` (:class:`.integrate.DirectSolver`)
keeps one factorization for the whole passage and reduces the contact to a few unknowns; the
loop is short, and its state is plain vectors, which makes checkpoints exact.
"""

from .integrate import DirectSolver, RailColumns, State, VehicleDriver
from .petsc import TransientSystem
from .rail import RailDofs, WheelCoupling
from .scheme import GeneralizedAlpha, choose_time_step, coarse_step_warning
from .stage import run_transient_stage

__all__ = [
    "DirectSolver",
    "GeneralizedAlpha",
    "RailColumns",
    "RailDofs",
    "State",
    "TransientSystem",
    "VehicleDriver",
    "WheelCoupling",
    "choose_time_step",
    "coarse_step_warning",
    "run_transient_stage",
]
