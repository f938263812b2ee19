"""Soil boxes with perfectly matched layers, stepped by the explicit engine (issue 29).

Everything runs through the package's path: the case keys (``boundary.<face> = "pml"``),
the distributed assembly, :class:`~railvib_hpc.transient.pml.PmlLayer` with its PETSc
gather, the stability limit and :class:`~railvib_hpc.transient.explicit.ExplicitSolver`.
A slab one element thick with ``u_y = 0`` everywhere is a plane-strain model (cheap
references for the oblique-incidence checks); a box is the 3-D case.
"""

from __future__ import annotations

import math

import numpy as np
from wave_cases import box_mesh, soil_case

from railvib_hpc.schema import PART_ID

#: The subgrade of :func:`wave_cases.soil_case` (benchmarks.md section 1).
E, NU, RHO = 200e6, 0.2, 1850.0
C_P = math.sqrt(E * (1 - NU) / (RHO * (1 + NU) * (1 - 2 * NU)))
C_S = math.sqrt(E / (2 * (1 + NU)) / RHO)
#: All five truncation faces.
FACES = ("x_min", "x_max", "y_min", "y_max", "base")


def ricker(t, f0: float):
    """Ricker wavelet of peak frequency ``f0`` centred at ``1.2 / f0`` (zero mean)."""
    a = (np.pi * f0 * (np.asarray(t, dtype=float) - 1.2 / f0)) ** 2
    return (1.0 - 2.0 * a) * np.exp(-a)


def slab_mesh(nx: int, nz: int, h: float, origin=(0.0, 0.0, 0.0), layers=None):
    """A plane-strain slab ``nx x 1 x nz`` of hexes of size ``h``; ``layers``: optional
    ``[(z_top_of_layer_from_base, part)]`` to give parts by depth."""
    mesh = box_mesh((nx, 1, nz), (nx * h, h, nz * h), origin)
    _set_layers(mesh, layers)
    return mesh


def _set_layers(mesh, layers) -> None:
    if not layers:
        return
    zc = mesh.points[mesh.hexes].mean(axis=1)[:, 2]
    lo = mesh.points[:, 2].min()
    for z_top, part in sorted(layers, reverse=True):
        mesh.hex_part[zc - lo < z_top] = PART_ID[part]


def _source_dofs(mesh, dofmap, source, plane_strain) -> tuple[np.ndarray, np.ndarray]:
    """The free DOFs of ``source``'s forces and their amplitudes (see :func:`run_box`)."""
    dofs, amps = [], []
    for point, comp, amp in ([source] if isinstance(source, tuple) else source):
        d2 = ((mesh.points - np.asarray(point)) ** 2).sum(axis=1)
        if plane_strain:
            near = mesh.points[np.argmin(d2)]
            nodes = np.flatnonzero(np.isclose(mesh.points[:, 0], near[0])
                                   & np.isclose(mesh.points[:, 2], near[2]))
        else:
            nodes = np.array([int(np.argmin(d2))])
        d = dofmap.index[nodes, comp]
        dofs.append(d[d >= 0])
        amps.append(np.full((d >= 0).sum(), float(amp)))
    return np.concatenate(dofs), np.concatenate(amps)


def _point_forces(mesh, dofmap, source, plane_strain, rows, dt, shape):
    """``prescribed(n)``: ``source``'s forces on this rank's rows times ``shape(n dt)``."""
    src_dofs, src_amp = _source_dofs(mesh, dofmap, source, plane_strain)
    mine = (src_dofs >= rows[0]) & (src_dofs < rows[1])
    own_src, own_amp = src_dofs[mine], src_amp[mine]

    def prescribed(n):
        return own_src, own_amp * float(shape(n * dt))

    return prescribed


def serial_layer(mesh, faces: dict[str, str], *extra: str):
    """The :class:`~railvib_hpc.transient.pml.PmlLayer` of ``mesh`` with ``faces``
    (others fixed) on one rank, and its DOF count (the layer's unit tests)."""
    from mpi4py import MPI

    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.problem import Problem
    from railvib_hpc.transient.petsc import GhostGather
    from railvib_hpc.transient.pml import PmlLayer

    case = soil_case("modal.lumped_mass=true", "damping.model=none",
                     *(f"boundary.{f}={faces.get(f, 'fixed')}" for f in FACES), *extra)
    problem = Problem.from_case(case)
    dofmap = build_dofmap(mesh, 1, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    n = dofmap.n_dofs
    layer = PmlLayer(mesh, problem, dofmap, 0, 0, n,
                     lambda dofs: GhostGather(MPI.COMM_SELF, (0, n), n, dofs))
    return layer, n


def _energy(system, st, direct: bool) -> float:
    """``1/2 v^T M v + 1/2 u^T K u`` (the direct engine's system takes PETSc vectors)."""
    if not direct:
        return system.energy(st.u, st.v)
    u, v = system.vector(np.ascontiguousarray(st.u)), system.vector(np.ascontiguousarray(st.v))
    try:
        return system.energy(u, v)
    finally:
        u.destroy()
        v.destroy()


def _system(mesh, problem, dofmap, comm, matrices: tuple, layer, implicit, direct, courant):
    """The engine's system and its step (:func:`run_box`'s ``implicit``, ``direct``,
    ``courant``); ``matrices``: K, M and the layers' full-integration mask."""
    from railvib_hpc.transient.explicit import ExplicitSystem, stability_limit

    K, M, full = matrices
    if direct is not None:
        lim = None
    elif implicit is None:
        system = ExplicitSystem(K, M, None, 0.0, comm, pml=layer)
        lim = stability_limit(K, system.m, None, comm)
    else:
        from railvib_hpc.model.petsc import assemble_partition
        from railvib_hpc.transient.explicit import lumped_diagonal
        from railvib_hpc.transient.imex import DAMPING_STABILITY_FACTOR

        partition = assemble_partition(mesh, problem, dofmap, comm, (), extra_hexes=implicit,
                                       full_hexes=full)
        lim = stability_limit(K, lumped_diagonal(M, comm), None, comm, minus=partition,
                              damping_factor=DAMPING_STABILITY_FACTOR)
    ext = mesh.points[mesh.hexes]
    h_min = float((ext.max(axis=1) - ext.min(axis=1)).min())
    dt = direct if direct is not None else \
        lim.dt_allowed if courant is None else courant * h_min / C_P
    if direct is not None:
        from railvib_hpc.transient.petsc import TransientSystem
        from railvib_hpc.transient.scheme import GeneralizedAlpha

        system = TransientSystem(K, M, None, GeneralizedAlpha.newmark(dt), comm, pml=layer)
    elif implicit is None:
        system.dt = dt
    else:
        from railvib_hpc.transient.imex import ImexSystem

        system = ImexSystem(K, M, None, *partition, dt, comm, pml=layer)
    return system, dt


def run_box(mesh, faces: dict[str, str], thickness: float, source: tuple, receivers,
            t_end: float, f0: float, comm, plane_strain: bool = False,
            extra: tuple = (), courant: float | None = None, record_energy: bool = False,
            implicit: np.ndarray | None = None, direct: float | None = None,
            history=None, progress=None, load=None):
    """Step ``mesh`` with the given face types and a Ricker point force.

    Parameters
    ----------
    mesh
        The soil model (its ``x_faces``, ``y_faces`` and ``bottom`` node sets).
    faces
        ``{face: type}`` (faces not given: ``fixed``).
    thickness
        ``boundary.layer_thickness`` [m].
    source
        ``(point, component, amplitude)``: a force on the node nearest ``point`` (on
        every node of that x, z in a plane-strain slab); or a list of such forces, all
        with the same Ricker history.
    receivers
        (k, 3) points; the nearest nodes are recorded.
    t_end, f0
        Duration [s] and Ricker peak frequency [Hz].
    comm
        Communicator.
    plane_strain
        ``u_y = 0`` at every node.
    extra
        More case overrides (layers' materials, pml parameters).
    courant
        Fixed step as ``courant * h_min / c_P`` (default: the engine's allowed step).
    record_energy
        Also return ``1/2 v^T m v + 1/2 u^T K u`` per step.
    implicit
        A mask of hexahedra: step with the IMEX engine
        (:class:`~railvib_hpc.transient.imex.ImexSystem`), these elements implicit
        (default: the explicit engine).
    direct
        A step [s]: step with the direct engine instead
        (:class:`~railvib_hpc.transient.petsc.TransientSystem`, the trapezoidal rule, one
        LU factor; the layers implicit).
    history
        The forces' time history ``history(t)`` (default: the Ricker of peak frequency
        ``f0``; a history other than a Ricker must start at zero too).
    progress
        Called as ``progress(step, steps)`` after every step (a bench's progress line).
    load
        ``load(mesh, dofmap, dt, steps) -> prescribed``, ``prescribed(n) -> (dofs,
        values)``: the forces of every step (global DOFs, -1 for none) instead of
        ``source``'s Ricker (explicit engine only; e.g. a
        :class:`~railvib_hpc.transient.surface_load.MovingSurfaceLoad`).

    Returns
    -------
    dict
        ``t``, ``u`` and ``v`` (steps + 1, k, 3) at the receivers (every rank), ``dt``,
        ``dofs`` (global count), ``pml_elements``, ``time_per_step`` [s] and ``energy``.
    """
    import time

    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble
    from railvib_hpc.problem import Problem
    from railvib_hpc.transient.explicit import ExplicitSolver, initial_acceleration
    from railvib_hpc.transient.integrate import State
    from railvib_hpc.transient.petsc import GhostGather
    from railvib_hpc.transient.pml import PmlLayer, pml_faces, pml_geometry

    types = {f: faces.get(f, "fixed") for f in FACES}
    case = soil_case("modal.lumped_mass=true", "damping.model=none",
                     "transient.engine=explicit", f"boundary.layer_thickness={thickness}",
                     *(f"boundary.{f}={k}" for f, k in types.items()), *extra)
    problem = Problem.from_case(case)
    rules, sets = constraint_rules(problem), face_node_sets(mesh)
    if plane_strain:
        rules["all"] = ("uy",) if plane_strain is True else tuple(plane_strain)
    dofmap = build_dofmap(mesh, comm.size, rules=rules, node_sets=sets)
    full = pml_geometry(mesh, problem)[1] if pml_faces(problem) else None
    K, M, _ = assemble(mesh, problem, dofmap, comm,
                       mass="diagonal" if direct is None else True, full_hexes=full)
    rows, n_global = K.getOwnershipRange(), K.getSize()[0]
    layer = None
    if pml_faces(problem):
        layer = PmlLayer(mesh, problem, dofmap, comm.rank, *rows,
                         lambda dofs: GhostGather(comm, rows, n_global, dofs))
    system, dt = _system(mesh, problem, dofmap, comm, (K, M, full), layer, implicit, direct,
                         courant)
    r0, r1 = rows
    steps = int(math.ceil(t_end / dt))
    if load is None:
        prescribed = _point_forces(mesh, dofmap, source, plane_strain, rows, dt,
                                   history or (lambda t: ricker(t, f0)))
    else:
        prescribed = load(mesh, dofmap, dt, steps)
    rec = np.array([int(np.argmin(((mesh.points - p) ** 2).sum(axis=1))) for p in receivers])
    rdofs = dofmap.index[rec, :3]

    def sample(x):
        out = np.zeros(rdofs.shape)
        ok = (rdofs >= r0) & (rdofs < r1)
        out[ok] = x[rdofs[ok] - r0]
        return comm.allreduce(out)

    n = r1 - r0
    st = State(0, np.zeros(n), np.zeros(n), np.zeros(n))
    if implicit is None and direct is None:
        solver = ExplicitSolver(system, prescribed=prescribed)
        initial_acceleration(system, st, [prescribed(0)])
    else:
        from railvib_hpc.transient.integrate import DirectSolver

        # at rest with the load's first value zero (the Ricker's start): a_0 = 0
        solver = DirectSolver(system, prescribed)
        solver.start(st)
    u, v, energy = [sample(st.u)], [sample(st.v)], []
    t0 = time.perf_counter()
    for k in range(steps):
        solver.step(st)
        u.append(sample(st.u))
        v.append(sample(st.v))
        if record_energy:
            energy.append(_energy(system, st, direct is not None))
        if progress is not None:
            progress(k + 1, steps)
    elapsed = time.perf_counter() - t0
    out = {"t": np.arange(steps + 1) * dt, "u": np.array(u), "v": np.array(v), "dt": dt,
           "dofs": n_global, "time_per_step": elapsed / steps, "energy": np.array(energy),
           "pml_elements": 0 if layer is None else comm.allreduce(layer.n_elements)}
    if implicit is not None or direct is not None:
        solver.destroy()
    system.destroy()
    K.destroy()
    M.destroy()
    return out
