"""The time integration engines of the ``transient`` stage: their matrices, systems, steps
and initial state.

Built once per run by the engines (:mod:`.engine`, :mod:`.direct_engine`,
:mod:`.explicit_engine`, :mod:`.imex_engine`) from the model the run's setup
(:func:`~.run_setup.setup_run`) hands over: the mesh, the DOF map and the problem:

* :func:`assemble_matrices`: K, M and C (Rayleigh damping applied, not stored, for the
  explicit engines; the absorbing faces' dashpots on the diagonal for ``explicit``), with
  the supported track ends' fitted springs (:func:`fit_track_ends`);
* :func:`explicit_system` (the explicit engine) and :func:`imex_partition`
  (the IMEX engine): the conditionally stable engines' system or implicit partition, their step
  and the line on their stability limit (:func:`stable_step`);
* :func:`pml_layer`: the perfectly matched layers of the ``pml`` faces, and
  :func:`check_implicit_outside_layers`, which refuses implicit elements in them;
* :func:`initial_state`: the state at t = 0 (at rest; a vehicle in static equilibrium on
  the possibly deflected rail).

The direct engine's factor (:class:`~.petsc.TransientSystem`) and the IMEX system
(:class:`~.imex.ImexSystem`) are made by their engines from these.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import Case
from ..errors import UserError
from ..io.stage_protocol import StageContext
from ..log import Reporter
from ..problem import Problem
from .integrate import State, gather_values
from .rail import RailDofs


class TransientInputError(UserError):
    """A case the full-order solver cannot run (no rails for a vehicle, probes outside...)."""


def assemble_matrices(ctx: StageContext, mesh, dofmap, problem: Problem,
                      pml: tuple | None = None, *, lumped: bool = False,
                      diagonal_dashpots: bool = False) -> tuple:
    """K, M, C (None when nothing damps), the damping summary, with ``diagonal_dashpots``
    (the explicit engine) the absorbing faces' dashpots as this rank's diagonal (None
    otherwise; then they are in C), and the problem (with the supported track ends'
    fitted stiffness, :func:`fit_track_ends`) (collective). ``problem``: the run's, built
    once from the case by :func:`.run_setup.setup_run`; ``pml``: its
    :func:`~.pml.pml_geometry` (None without ``pml`` faces), whose hexahedra take the
    plain full formulation, the one their memory terms use; ``lumped``: the lumped mass
    on the diagonal alone and Rayleigh damping applied, not stored, where it can be (the
    conditionally stable engines, :class:`~.engine.EngineBase`)."""
    from ..model.boundary import dashpot_diagonal
    from ..model.petsc import assemble, assemble_damping, destroy_damping, rayleigh_operator

    case, comm = ctx.case, ctx.comm
    with ctx.rep.stage("transient: assembly"):
        # the explicit engines keep the lumped mass on the diagonal alone
        K, M, _ = assemble(mesh, problem, dofmap, comm,
                           mass="diagonal" if lumped else True,
                           full_hexes=None if pml is None else pml[1])
        problem = fit_track_ends(ctx, mesh, dofmap, problem, K, M)
        # the explicit engine takes diagonal dashpots at the full step, apart from C
        dashpots = dashpot_diagonal(mesh, problem, dofmap, comm.rank) \
            if diagonal_dashpots else None
        # (every rank must agree: a rank without face nodes has an all-zero diagonal)
        if diagonal_dashpots and comm.allreduce(dashpots is None, op=_MPI_LOR()):
            dashpots = None
        stored = dashpots is None
        C = None
        if lumped:
            # Rayleigh damping applied, not stored, where it can be (the explicit engines)
            from .explicit import lumped_diagonal

            C, cinfo = rayleigh_operator(mesh, problem, dofmap, comm, K,
                                         lumped_diagonal(M, comm), dashpots=stored)
        if C is None:
            C, cinfo = assemble_damping(mesh, problem, dofmap, comm, K, M, dashpots=stored)
        if case["damping.model"] == "none" and (cinfo["dashpot_nodes"] == 0 or not stored) \
                and cinfo["layer_elements"] == 0 and not case["damping.pads"]:
            destroy_damping(C)
            C = None
    return K, M, C, cinfo, dashpots, problem


#: PETSc options prefix of the static solve that fits the supported track ends' springs.
TRACK_ENDS_PREFIX = "railvib_tr_ends_"


def fit_track_ends(ctx: StageContext, mesh, dofmap, problem: Problem, K, M) -> Problem:
    """The problem with the supported track ends' springs, added to the assembled K
    (:func:`~railvib_hpc.model.petsc.fit_track_ends`, which the modal path shares; its
    line goes to the log). Rigid ends: ``problem`` unchanged."""
    from ..model.petsc import fit_track_ends as fit

    try:
        problem, line = fit(mesh, dofmap, problem, K, M, ctx.comm, TRACK_ENDS_PREFIX)
    except ValueError as exc:
        raise TransientInputError(str(exc)) from None
    if line:
        ctx.rep.info(line)
    return problem


def explicit_system(ctx: StageContext, mesh, dofmap, problem: Problem, rails: RailDofs,
                     vehicle,
                     matrices: tuple, dt_band: float, pml: tuple | None = None) -> tuple:
    """The explicit engine's system, its step and a line on its stability limit
    (``pml``: the setup's :func:`~.pml.pml_geometry`, None without ``pml`` faces).

    The limit is :data:`~.explicit.STEP_SAFETY` of the critical step of the model's largest
    natural frequency (:func:`~.explicit.stability_limit`) and, with a vehicle, of the
    linearised Hertz spring on the lightest rail node (:func:`~.explicit.contact_frequency`).
    ``transient.dt`` above it is refused, naming what sets it; the automatic step is the
    band's step ``dt_band`` or the limit, whichever is smaller, divided into ``output.dt``.
    """
    from .explicit import (
        STEP_SAFETY,
        ExplicitSystem,
        contact_frequency,
        critical_step,
        limiting_element,
        stability_limit,
    )

    case, comm = ctx.case, ctx.comm
    K, M, C, dashpots = matrices
    layer = pml_layer(ctx, mesh, dofmap, problem, K, pml)
    # (its step is set below; the diagonal dashpots, apart from C, do not limit it)
    system = ExplicitSystem(K, M, C, 0.0, comm, dashpots=dashpots, pml=layer)
    # (the layers' M_e2 is taken at the average displacement: it does not limit the step,
    # ExplicitSystem.effective_mass)
    lim = stability_limit(K, system.m, C, comm)
    critical = lim.dt_critical
    where = limiting_element(mesh, dofmap.index, lim.limiting_dof)
    if vehicle is not None:
        uz = rails.dofs[:, :, 0].ravel()
        own = uz[(uz >= system.r0) & (uz < system.r1)] - system.r0
        rail_mass = comm.allreduce(float(system.m[own].min(initial=np.inf)), op=_MPI_MIN())
        w_c = contact_frequency(vehicle.hertz_constant,
                                float(np.max(vehicle.static_wheel_loads())), rail_mass)
        if w_c > 0 and critical_step(w_c) < critical:
            critical = critical_step(w_c)
            where = (f"the wheel-rail contact (linearised Hertz spring on a {rail_mass:.3g} kg "
                     f"rail node, {w_c / (2 * math.pi):.4g} Hz)")
    try:
        dt, text = stable_step(case, lim, critical, where, dt_band, "explicit")
    except TransientInputError:
        system.destroy()
        raise
    system.dt = float(dt)
    system.allowed_step = STEP_SAFETY * critical
    return system, dt, text


def pml_layer(ctx: StageContext, mesh, dofmap, problem: Problem, K, pml: tuple | None):
    """The perfectly matched layers of the ``pml`` faces (None without), with their log
    lines (collective). ``pml``: the checked :func:`~.pml.pml_geometry` of the setup."""
    from .petsc import GhostGather
    from .pml import PmlLayer, pml_line, pml_warnings

    if pml is None:
        return None
    comm = ctx.comm
    rows, n_global = K.getOwnershipRange(), K.getSize()[0]
    layer = PmlLayer(mesh, problem, dofmap, comm.rank, *rows,
                     lambda dofs: GhostGather(comm, rows, n_global, dofs), geometry=pml)
    n_el = comm.allreduce(layer.n_elements)
    ctx.rep.info(f"  {pml_line(layer.faces, problem)}; {n_el} element computations on "
                 f"{comm.size} rank(s), {comm.allreduce(layer.nbytes) / 1e6:.3g} MB, "
                 f"{layer.kernel.kernel} kernel")
    for line in pml_warnings(layer.faces, problem):
        ctx.rep.info(line)
    return layer


def stable_step(case: Case, lim, critical: float, where: str, dt_band: float,
                 engine: str) -> tuple[float, str]:
    """The step of a conditionally stable engine and a line on its limit: ``transient.dt``
    (refused above :data:`~.explicit.STEP_SAFETY` of ``critical``, naming ``where`` the
    limit sits) or the automatic one, ``min(dt_band, allowed)`` divided into ``output.dt``.
    ``lim``: the :class:`~.explicit.StableStep` of the model (its largest mode, and whether
    damping that is not proportional to it lowers the limit).
    """
    from .explicit import STEP_SAFETY

    allowed = STEP_SAFETY * critical
    omega = lim.omega_max
    damped = (f"; the damping not proportional to that mode (absorbing faces' dashpots, "
              f"pads) lowers its step {lim.dt_mode:.4g} s" if lim.damping_limited else "")
    text = (f"stable up to {allowed:.4g} s ({STEP_SAFETY:g} x the critical step "
            f"{critical:.4g} s, set by {where}; omega_max = {omega:.4g} rad/s = "
            f"{omega / (2 * math.pi):.4g} Hz, damping ratio of that mode {lim.xi:.3g}{damped})")
    dt = case["transient.dt"]
    if dt > 0 and dt > allowed * (1 + 1e-9):
        raise TransientInputError(
            f"transient.dt = {dt:g} s: the {engine} engine is {text}; allowed: "
            f"0 < transient.dt <= {allowed:.4g} s, or 0 (automatic)")
    if dt <= 0:
        dt = min(dt_band, allowed)
        odt = case["output.dt"]
        if odt > 0:
            dt = odt / math.ceil(odt / dt * (1.0 - 1e-6))
    return float(dt), text


def check_implicit_outside_layers(case: Case, mesh, inside: np.ndarray) -> None:
    """Refuse implicit parts (``transient.implicit_parts``) with hexahedra in a perfectly
    matched layer (``inside``: the layers' mask): the layer's memory forces are explicit,
    and with its elements implicit the layer grew unstable (measured on the plane-strain
    slab, an implicit column through the base layer: the energy grew 1000 x in 1.5 s)."""
    from ..mesh.checks import present_parts
    from ..schema import PART_ID
    from .imex import implicit_part_names

    names = list(case["transient.implicit_parts"])
    parts = implicit_part_names(names, present_parts(mesh))
    hit = [p for p in parts if np.any(inside & (mesh.hex_part == PART_ID[p]))]
    if hit:
        raise TransientInputError(
            f"transient.implicit_parts = {names}: the part(s) {', '.join(hit)} have "
            f"hexahedra in a perfectly matched layer (boundary.layer_thickness = "
            f"{case['boundary.layer_thickness']:g} m); the layer's memory forces are "
            "explicit and with implicit elements in it the layer grows unstable; allowed: "
            "implicit parts outside the layers (leave them out of transient.implicit_parts, "
            "make the layer thinner, or give that face absorbing)")


def imex_partition(ctx: StageContext, mesh, dofmap, problem: Problem, K, M, C,
                    dt_band: float, pml: tuple | None = None) -> tuple:
    """The IMEX engine's implicit partition ``(K_I, C_I)``, its step, a line on the
    explicit part's stability limit (:func:`~.explicit.stability_limit` of ``K - K_I,
    C - C_I``; the implicit elements do not limit the step, :mod:`.imex`), the largest
    step it allows (:data:`~.explicit.STEP_SAFETY` of the critical one) and the
    perfectly matched layers (None without ``pml``, the setup's
    :func:`~.pml.pml_geometry`; their ``M_e2`` is implicit, not in the limit, their
    hexahedra take the full formulation in the partition as in K)."""
    from ..mesh.checks import present_parts
    from ..model.petsc import assemble_partition
    from ..schema import PART_ID
    from .explicit import STEP_SAFETY, limiting_element, lumped_diagonal, stability_limit
    from .imex import DAMPING_STABILITY_FACTOR, auto_implicit_hexes, implicit_part_names

    case, comm = ctx.case, ctx.comm
    parts = implicit_part_names(list(case["transient.implicit_parts"]), present_parts(mesh))
    extra = None
    if case["transient.implicit_elements"] == "auto":
        target = case["transient.dt"] if case["transient.dt"] > 0 else dt_band
        # (never a layer's element: its memory forces are explicit,
        # check_implicit_outside_layers)
        outside = ~np.isin(mesh.hex_part, [PART_ID[p] for p in parts])
        if pml is not None:
            outside &= ~pml[1]
        extra = auto_implicit_hexes(mesh, problem, target, STEP_SAFETY, outside)
    K_I, C_I = assemble_partition(mesh, problem, dofmap, comm, parts, extra, boundary=True,
                                  full_hexes=None if pml is None else pml[1])
    layer = None
    try:
        m = lumped_diagonal(M, comm)
        layer = pml_layer(ctx, mesh, dofmap, problem, K, pml)
        # (the layers' M_e2 is implicit, in K_eff: it does not limit the step)
        lim = stability_limit(K, m, C, comm, minus=(K_I, C_I),
                              damping_factor=DAMPING_STABILITY_FACTOR)
        where = limiting_element(mesh, dofmap.index, lim.limiting_dof)
        dt, text = stable_step(case, lim, lim.dt_critical, where, dt_band, "imex")
    except BaseException:
        for A in (K_I, C_I):
            if A is not None:
                A.destroy()
        if layer is not None:
            layer.destroy()
        raise
    auto = (f" and {int(extra.sum()):,} elements below the target step" if extra is not None
            else "")
    text = (f"implicit: {', '.join(parts) or 'none'}{auto}, the absorbing faces' springs and "
            f"dashpots{', the layers M_e1, M_e2' if layer is not None else ''}; explicit part "
            f"{text}")
    return (K_I, C_I), dt, text, layer, STEP_SAFETY * lim.dt_critical


def static_start(system, state: State, load: tuple, rep: Reporter) -> None:
    """``u_0 = K^-1 f_0``: the soil at rest in static equilibrium under the prescribed
    loads of t = 0 (``load``: their ``(dofs, values)``; the surface loads of ``load.start =
    'static'``), velocities zero, in ``state`` (collective).

    One solve with the engine's own static solver, the one a wheel resting on the flexible
    rail takes (``system.solve_matrix``: the explicit engines' MUMPS factor of K up to
    :data:`~.explicit.STATIC_FACTOR_MAX_DOFS`, CG + GAMG with the rigid-body near null
    space above; the direct engine's separate factor of K). Memory: that of the solver
    (the factor, or a few vectors and GAMG's hierarchy), freed after it; time: one solve.
    The acceleration then follows from the equation of motion at t = 0 (zero to the
    solve's residual without damping)."""
    from .integrate import add_sparse

    rhs = np.zeros((system.n_local, 1))
    add_sparse(rhs[:, 0], system.r0, *load)
    state.u[:] = system.solve_matrix(system.K, rhs)[:, 0]
    state.v[:] = 0.0
    how = system.static_method
    rep.info("  static start: the soil in equilibrium under the loads at t = 0 (K u0 = f0, "
             "v0 = 0)" + (f"; {how}" if how else ""))


def _MPI_MIN():
    from mpi4py import MPI

    return MPI.MIN


def _MPI_LOR():
    from mpi4py import MPI

    return MPI.LOR


def initial_state(run, comm, rep: Reporter) -> State:
    """At rest; a vehicle in static equilibrium on the (possibly deflected) rail; with
    ``run.static_start`` (``load.start = 'static'``) the soil in static equilibrium
    under the prescribed loads of t = 0 (:func:`static_start`). ``run``: the
    :class:`~.run_setup.TransientRun`; the acceleration at t = 0 is its engine's
    (:meth:`~.engine.Engine.initial_acceleration`)."""
    from ..mbs.vehicles import static_equilibrium

    system, engine = run.system, run.engine
    n_local = system.n_local
    state = State(0, np.zeros(n_local), np.zeros(n_local), np.zeros(n_local))
    vehicle, driver = run.vehicle, run.driver
    if vehicle is None:
        if run.prescribed is not None:
            load = run.prescribed(0)
            if run.static_start:
                static_start(system, state, load, rep)
            engine.initial_acceleration(state, [load])    # (starts the layers)
        return state
    dofs, coef, _ = driver.coupling.at(driver.x[0])
    r = driver.heights(0)
    nw = coef.shape[0]
    flat = dofs.ravel()
    if np.all(flat < 0):
        flex = np.zeros((nw, nw))
        xcols = None
    else:
        rep.info("  a wheel starts on the flexible rail: static equilibrium with K")
        # one solve per wheel, K x_j = E_D c_j (its Hermite weights on its DOFs), not one
        # per DOF: the flexibility c_i . x_j[D_i] and u_0 = -sum_j x_j F_j need no more
        # (8 x fewer solves than the columns of every DOF: the static start of the explicit
        # engines, CG + GAMG per column, took 185-523 s on 68k-178k DOFs before)
        rhs = np.zeros((n_local, nw))
        own = (dofs >= system.r0) & (dofs < system.r1)
        wheel = np.broadcast_to(np.arange(nw)[:, None], dofs.shape)
        np.add.at(rhs, (dofs[own] - system.r0, wheel[own]), coef[own])
        xcols = system.solve_matrix(system.K, rhs)
        if system.static_method:
            rep.info(f"  static start: {system.static_method}")
        w = np.zeros((nw, nw))
        for j in range(nw):
            at = gather_values(comm, xcols[:, j], system.r0, flat).reshape(dofs.shape)
            w[:, j] = (coef * at).sum(axis=1)
        flex = 0.5 * (w + w.T)
    y, force = static_equilibrium(vehicle, flex, r)
    if xcols is not None:
        state.u[:] = -(xcols @ force)
    if system.pml is not None:
        # the static deflection is the layers' rest state (PmlLayer.start)
        system.pml.start(state.u)
    state.y, state.y_dot = y, np.zeros(vehicle.n_dof)
    state.y_ddot = driver.newmark.acceleration(y, state.y_dot, force)
    state.force = force
    w = flex @ (-force) if xcols is not None else np.zeros(nw)
    state.penetration = w + r - vehicle.contact_matrix().T @ y
    return state
