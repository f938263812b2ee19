"""The moving-load half-space model of the verification (issue 28, items 5 and 7).

A structured box of subgrade hexahedra, half of the half-space (``y >= 0``: the load's path
``y = 0`` is a symmetry plane, a roller), absorbing faces (Lysmer-Kuhlemeyer dashpots)
on the other four sides and the base; a point load ``P`` moving along ``x`` on the
surface (half of it on the half model), switched on smoothly
(:class:`railvib_hpc.transient.surface_load.MovingSurfaceLoad`), integrated with the
explicit engine at its allowed step (:func:`~railvib_hpc.transient.explicit.stability_limit`);
the vertical surface velocity at receivers ``y = d`` beside the path, against the steady
state of :mod:`railvib_hpc.fem.halfspace`.
"""

from __future__ import annotations

import math
import time

import numpy as np
from wave_cases import box_mesh, soil_case

from railvib_hpc.fem.halfspace import moving_load_velocity
from railvib_hpc.site import rayleigh_speed

#: Full load [N] (half of it on the half model).
FORCE = 1e5


def run_moving_load(comm, h: float, n: tuple[int, int, int], receivers: tuple[float, ...],
                    speed_ratio: float, x_start: float, x_receiver: float,
                    ramp_time: float, t_end: float, nu: float = 0.25,
                    virtual_thickness: float = 0.0, step_fraction: float = 1.0,
                    half_width: float = 0.0) -> dict:
    """Run the model and return the receivers' vertical velocities and the reference.

    Parameters
    ----------
    comm
        Communicator.
    h
        Element size [m] (cubes).
    n
        Elements along x, y (the half width) and z (the depth).
    receivers
        Distances of the receivers from the path [m], at ``x = x_receiver``.
    speed_ratio
        Load speed over the soil's Rayleigh speed.
    x_start, ramp_time, t_end
        The load's position at t = 0 [m], its switch-on [s], the run's end [s].
    nu
        Poisson's ratio of the soil (E and rho of the thesis subgrade).
    virtual_thickness
        ``boundary.virtual_thickness`` of the absorbing faces [m].
    engine
        'explicit' (the O(N) engine) or 'direct'.

    Returns
    -------
    dict
        ``t``, ``v`` (nt + 1, receivers; downward velocity), ``v_exact`` (steady state at
        the same times), ``speed``, ``c_r``, ``dt``, ``dofs``, ``seconds``.
    """
    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble, assemble_damping
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.problem import Problem
    from railvib_hpc.transient.explicit import (
        ExplicitSolver,
        ExplicitSystem,
        initial_acceleration,
        stability_limit,
    )
    from railvib_hpc.transient.integrate import State, gather_values
    from railvib_hpc.transient.surface_load import (
        MovingSurfaceLoad,
        SurfaceLoadPath,
        spreading,
    )

    init_petsc([])
    t0 = time.perf_counter()
    nx, ny, nz = n
    mesh = box_mesh(n, (nx * h, ny * h, nz * h), origin=(0.0, 0.0, -nz * h))
    faces = [f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_max", "base")]
    case = soil_case(f"materials.subgrade.nu={nu}", "damping.model=none",
                     "modal.lumped_mass=true", "boundary.y_min=roller", *faces,
                     f"boundary.virtual_thickness={virtual_thickness}")
    problem = Problem.from_case(case)
    mat = case["materials.subgrade"]
    mu = mat["E"] / (2 * (1 + nu))
    c_s = math.sqrt(mu / mat["rho"])
    c_r = rayleigh_speed(c_s, nu)
    speed = speed_ratio * c_r
    dofmap = build_dofmap(mesh, comm.size, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    K, M, _ = assemble(mesh, problem, dofmap, comm, mass="diagonal")
    C, _ = assemble_damping(mesh, problem, dofmap, comm, K, M)
    system = ExplicitSystem(K, M, C, 0.0, comm)
    dt = step_fraction * stability_limit(K, system.m, C, comm).dt_allowed
    system.dt = dt
    nt = int(math.ceil(t_end / dt))
    path = SurfaceLoadPath(forces=np.array([0.5 * FORCE]), offsets=np.zeros(1),
                           x_start=x_start, y=0.0, speed=speed, ramp_time=ramp_time,
                           half_width=half_width)
    load = MovingSurfaceLoad(mesh, dofmap.index, path, dt, nt)
    top = np.isclose(mesh.points[:, 2], 0.0)
    rec = [int(np.flatnonzero(top & np.isclose(mesh.points[:, 0], x_receiver)
                              & np.isclose(mesh.points[:, 1], d))[0]) for d in receivers]
    r_dofs = dofmap.index[rec, 2]
    solver = ExplicitSolver(system, load)
    n_local = system.r1 - system.r0
    st = State(0, np.zeros(n_local), np.zeros(n_local), np.zeros(n_local))
    initial_acceleration(system, st, [load(0)])
    solver.start(st)
    v = np.zeros((nt + 1, len(receivers)))
    for k in range(nt):
        solver.step(st)
        v[k + 1] = -gather_values(comm, st.v, system.r0, r_dofs)
    solver.destroy()
    system.destroy()
    for A in (K, M, C):
        A.destroy()
    t = np.arange(nt + 1) * dt
    xi = x_receiver - path.positions(t)[:, 0]
    offsets, share = spreading(half_width, 0.125 * h)
    v_exact = np.stack([moving_load_velocity(xi[:, None] - offsets[None, :], d, FORCE, mu, nu,
                                             c_s, speed) @ share for d in receivers], axis=1)
    return {"t": t, "v": v, "v_exact": v_exact, "speed": speed, "c_r": c_r, "c_s": c_s,
            "dt": dt, "dofs": dofmap.n_dofs, "seconds": time.perf_counter() - t0,
            "xi": xi, "receivers": receivers}
