"""Energy balance of the O(N) engines with absorbing faces (issue 28, item 7).

The central differences (``transient.engine = "explicit"``) are a leapfrog with the lumped
mass; the IMEX step (Hughes-Liu, Newmark ``beta = 1/4, gamma = 1/2``) is a leapfrog of its
predictors with the mass ``m + beta dt^2 K_I``. Each conserves a discrete energy
``E_{n+1/2}`` exactly, and a step changes it by ``dt (f_n - D_n)^T v_n`` with the damping
force ``D_n`` the scheme actually applies (the half-step velocity, or ``v*`` and ``v_n``),
derived in :meth:`~railvib_hpc.transient.explicit.ExplicitSystem.scheme_energy` and
:meth:`~railvib_hpc.transient.imex.ImexSystem.scheme_energy`. So, step by step:

* a closed, undamped box keeps ``E_{n+1/2}`` to round-off (the physical energy
  ``1/2 v^T m v + 1/2 u^T K u`` oscillates, by far more);
* with absorbing faces (Lysmer-Kuhlemeyer dashpots, optionally Rayleigh damping) the energy
  lost equals the sum of :meth:`step_dissipation` to round-off, and most of the energy
  leaves. The work differs from ``dt v_n^T C v_n`` (the rate at the full step) by far more
  than round-off wherever the damping is explicit, and equals it where all of it is
  implicit (the IMEX engine's face dashpots) or at the full step (the explicit engine's,
  :class:`~railvib_hpc.transient.explicit.ExplicitSystem`'s ``dashpots``).

The round-off bound: each step's energy is a sum of products of the state, accumulated
once per step; its relative rounding error is a few ``eps`` times the ratio of the
largest term to the energy, here bounded by the stiffness contrast of the model's
``(omega_max dt)^2 <= 4`` (``u_n^T K u_{n+1}`` against ``1/2 v^T m v``), so the drift after
``n`` steps stays below ``ROUNDOFF n eps`` of the initial energy.

A 4 x 4 x 4 box of soil (1 m hexahedra, top free), a smooth initial velocity field
(global DOF numbers: the same on any number of ranks); the IMEX box has the top layer's
2 x 2 middle elements in concrete as its implicit partition (155 times stiffer than the
soil: ``m + beta dt^2 K_I`` far from ``m``), with the absorbing faces' springs and
dashpots implicit as the engine has them (``boundary=True`` of
:func:`~railvib_hpc.model.petsc.assemble_partition`).
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from wave_cases import box_mesh, soil_case

from railvib_hpc.schema import PART_ID

comm = MPI.COMM_WORLD
#: Multiple of ``n_steps * eps`` that bounds the energy drift (see the module notes);
#: measured drifts are 0.02-0.8 ``n eps`` (the concrete partition's the largest).
ROUNDOFF = 100.0
#: Faces: all fixed (closed) or all absorbing but the top.
CLOSED = {"bottom": ("ux", "uy", "uz"), "x_faces": ("ux", "uy", "uz"),
          "y_faces": ("ux", "uy", "uz")}
ABSORBING = [f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_min", "y_max", "base")]
#: Time simulated: the slowest waves cross the 4 m box about 15 times.
T_END = 0.3


def _run(engine: str, closed: bool, damping: str = "none"):
    """Step the box; returns the discrete energies ``e``, the cumulative damping work
    ``work`` (and ``naive``: ``dt v_n^T C v_n``), the physical energies, per step."""
    from railvib_hpc.model.boundary import dashpot_diagonal, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble, assemble_damping, assemble_partition
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.explicit import (
        ExplicitSolver,
        ExplicitSystem,
        initial_acceleration,
        lumped_diagonal,
        stability_limit,
    )
    from railvib_hpc.transient.imex import DAMPING_STABILITY_FACTOR, ImexSystem
    from railvib_hpc.transient.integrate import DirectSolver, State

    init_petsc([])
    mesh = box_mesh((4, 4, 4), (4.0, 4.0, 4.0))
    centre = mesh.points[mesh.hexes].mean(axis=1)
    top = (centre[:, 2] > 3.0) & np.all(np.abs(centre[:, :2] - 2.0) < 1.0, axis=1)
    if engine == "imex":
        mesh.hex_part[top] = PART_ID["slab"]
    extra = [] if closed else ABSORBING
    if damping == "rayleigh":
        extra += ["damping.model=rayleigh", "modal.damping_ratio=0.05", "damping.f1=5",
                  "damping.f2=80"]
    else:
        extra += ["damping.model=none"]
    from railvib_hpc.problem import Problem

    case = Problem.from_case(soil_case("modal.lumped_mass=true", *extra))
    dofmap = build_dofmap(mesh, comm.size, rules=CLOSED if closed else {},
                          node_sets=face_node_sets(mesh))
    K, M, _ = assemble(mesh, case, dofmap, comm)
    # the explicit engine takes the faces' dashpots apart, at the full step (as the stage)
    apart = engine == "explicit" and not closed
    dashpots = dashpot_diagonal(mesh, case, dofmap, comm.rank) if apart else None
    C = None if (closed or apart) and damping == "none" else assemble_damping(
        mesh, case, dofmap, comm, K, M, dashpots=not apart)[0]
    m = lumped_diagonal(M, comm)
    minus = K_I = C_I = None
    if engine == "imex":
        K_I, C_I = assemble_partition(mesh, case, dofmap, comm, ("slab",),
                                      boundary=True)
        minus = (K_I, C_I)
    # the allowed step of the engine (the damping left in C; the dashpots apart do not
    # limit it)
    lim = stability_limit(K, m, C, comm, minus=minus, damping_factor=(
        DAMPING_STABILITY_FACTOR if engine == "imex" else 1.0))
    dt = lim.dt_allowed
    if engine == "imex":
        system = ImexSystem(K, M, C, K_I, C_I, dt, comm)
        solver = DirectSolver(system)
    else:
        system = ExplicitSystem(K, M, C, dt, comm, dashpots=dashpots)
        solver = ExplicitSolver(system)
    r0, r1 = system.r0, system.r1
    n = r1 - r0
    st = State(0, np.zeros(n), np.zeros(n), np.zeros(n))
    nodes = np.flatnonzero(dofmap.index[:, 2] >= 0)
    dofs = dofmap.index[nodes, 2]
    x = mesh.points[nodes]
    own = (dofs >= r0) & (dofs < r1)
    st.v[dofs[own] - r0] = (np.sin(np.pi * x[own, 0] / 4) * np.sin(np.pi * x[own, 1] / 4)
                            * np.sin(np.pi * x[own, 2] / 8))
    if engine == "explicit":
        initial_acceleration(system, st, [])
    solver.start(st)
    steps = int(np.ceil(T_END / dt))
    energy = [system.scheme_energy(st.u, st.v, st.a)]
    physical = [system.energy(st.u, st.v)]
    work, naive = [0.0], [0.0]
    for _ in range(steps):
        previous = (st.v.copy(), st.a.copy())
        solver.step(st)
        energy.append(system.scheme_energy(st.u, st.v, st.a))
        physical.append(system.energy(st.u, st.v))
        work.append(work[-1] + system.step_dissipation(previous, (st.v, st.a)))
        # the continuous dissipation rate v^T C v at t_n, times dt (dashpots included)
        if C is not None or dashpots is not None:
            rate = 0.0 if C is None else system._damping_work(st.v, st.v)
            if dashpots is not None:
                rate += comm.allreduce(dt * float(st.v @ (dashpots * st.v)))
            naive.append(naive[-1] + rate)
    solver.destroy()
    system.destroy()
    for A in (K, M, C):
        if A is not None:
            A.destroy()
    return {"e": np.array(energy), "work": np.array(work), "physical": np.array(physical),
            "naive": np.array(naive), "steps": steps, "dt": dt}


def _tolerance(steps: int) -> float:
    return ROUNDOFF * steps * np.finfo(float).eps


@pytest.mark.mpi
@pytest.mark.parametrize("engine", ["explicit", "imex"])
def test_closed_undamped_box_keeps_the_scheme_energy(engine):
    """All faces fixed, no damping: ``E_{n+1/2}`` constant to round-off; the physical
    energy is not (so the check can tell the two apart)."""
    r = _run(engine, closed=True)
    e, phys, steps = r["e"], r["physical"], r["steps"]
    drift = np.abs(e / e[0] - 1).max()
    print(f"{engine}: {steps} steps, drift {drift:.2e} = {drift / (steps * 2.2e-16):.2f} n eps; "
          f"physical energy off by {np.abs(phys / e[0] - 1).max():.2e}")
    assert drift <= _tolerance(steps)
    assert np.abs(phys / e[0] - 1).max() > 1e3 * _tolerance(steps)


@pytest.mark.mpi
@pytest.mark.parametrize("engine", ["explicit", "imex"])
@pytest.mark.parametrize("damping", ["none", "rayleigh"])
def test_energy_leaving_equals_the_damping_work(engine, damping):
    """Absorbing faces (and Rayleigh damping): the discrete energy lost equals the work of
    the dashpots and dampers the scheme applied, step by step, to round-off; most of it
    has left."""
    r = _run(engine, closed=False, damping=damping)
    e, d, phys, steps = r["e"], r["work"], r["physical"], r["steps"]
    off = np.abs(e[0] - e - r["naive"]).max() / e[0]
    residual = np.abs(e[0] - e - d).max() / e[0]
    print(f"{engine} {damping}: {steps} "
          f"steps, residual {residual:.2e} = {residual / (steps * 2.2e-16):.2f} n eps; left "
          f"{e[-1] / e[0]:.2e} (physical {phys[-1] / phys[0]:.2e}); dt v^T C v misses by {off:.2e}")
    assert residual <= _tolerance(steps)
    assert phys[-1] < 0.02 * phys[0]
    if damping == "none":
        # all the damping is the faces' dashpots, at v_n (implicit in the IMEX engine, at
        # the full step in the explicit one): the rate v_n^T C v_n
        assert off <= _tolerance(steps)
    else:
        # explicit damping takes another velocity: the rate at v_n misses by far more
        assert off > 1e3 * _tolerance(steps)
