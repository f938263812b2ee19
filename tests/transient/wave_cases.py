"""Wave-propagation models for the verification of the full-order solver (issue 12, step 3).

All run through the real path: distributed assembly (K, M, the damping matrix with the
absorbing faces' dashpots), the effective matrix factored once with MUMPS, the stepping
loop of :class:`railvib_hpc.transient.integrate.DirectSolver`.
"""

from __future__ import annotations

import math

import numpy as np

from railvib_hpc.config import load_case
from railvib_hpc.mesh.model import Mesh
from railvib_hpc.problem import Problem
from railvib_hpc.schema import PART_ID

#: Soil of the thesis model (benchmarks.md section 1).
E, NU, RHO = 200e6, 0.2, 1850.0
G = E / (2 * (1 + NU))
C_P = math.sqrt(E * (1 - NU) / (RHO * (1 + NU) * (1 - 2 * NU)))
C_S = math.sqrt(G / RHO)


def column_mesh(nz: int, height: float, width: float = 1.0) -> Mesh:
    """A 1 x 1 x nz column of subgrade hexes (z from 0 to ``height``), node set ``bottom``."""
    z = np.linspace(0.0, height, nz + 1)
    xy = np.array([[0, 0], [width, 0], [width, width], [0, width]], float)
    pts = np.concatenate([np.c_[xy, np.full(4, zk)] for zk in z])
    k = np.arange(nz)[:, None]
    hexes = np.hstack([4 * k + np.arange(4), 4 * (k + 1) + np.arange(4)])
    return Mesh(points=pts, hexes=hexes, hex_part=np.full(nz, PART_ID["subgrade"], np.int32),
                lines=np.zeros((0, 2), np.int64), line_part=np.zeros(0, np.int32),
                node_sets={"bottom": np.arange(4)})


def box_mesh(n: tuple[int, int, int], size: tuple[float, float, float],
             origin=(0.0, 0.0, 0.0)) -> Mesh:
    """Structured box of subgrade hexes with node sets ``bottom``, ``x_faces``, ``y_faces``."""
    from fem_tools import box_mesh as lattice

    pts, hexes = lattice(*n, *size)
    pts = pts + np.asarray(origin, float)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    sets = {"bottom": np.flatnonzero(np.isclose(pts[:, 2], lo[2])),
            "x_faces": np.flatnonzero(np.isclose(pts[:, 0], lo[0]) | np.isclose(pts[:, 0], hi[0])),
            "y_faces": np.flatnonzero(np.isclose(pts[:, 1], lo[1]) | np.isclose(pts[:, 1], hi[1]))}
    return Mesh(points=pts, hexes=hexes, hex_part=np.full(len(hexes), PART_ID["subgrade"],
                                                          np.int32),
                lines=np.zeros((0, 2), np.int64), line_part=np.zeros(0, np.int32),
                node_sets=sets)


def smooth_pulse(t, duration: float):
    """``sin^4(pi t / T)`` for ``0 <= t <= T``, else 0 (three continuous derivatives)."""
    t = np.asarray(t, dtype=float)
    return np.where((t >= 0) & (t <= duration), np.sin(np.pi * t / duration) ** 4, 0.0)


def zero_mean_pulse(t, duration: float):
    """``sin^3 cos(pi t / T)`` for ``0 <= t <= T`` (the derivative of sin^4: no net impulse,
    so no quasi-static part; content 20-50 Hz for T = 0.04 s)."""
    t = np.asarray(t, dtype=float)
    th = np.pi * t / duration
    return np.where((t >= 0) & (t <= duration), np.sin(th) ** 3 * np.cos(th), 0.0)


def soil_case(*overrides: str):
    """The default case (thesis soil) with overrides."""
    return load_case(None, list(overrides))


class Model:
    """Assembled model + effective matrix + solver on ``comm`` (collective)."""

    def __init__(self, mesh: Mesh, case, rules, comm, dt: float, rho_inf: float = 1.0,
                 node_sets=None):
        from railvib_hpc.model.dofmap import build_dofmap
        from railvib_hpc.model.petsc import assemble, assemble_damping
        from railvib_hpc.petsc_env import init_petsc

        init_petsc([])
        from railvib_hpc.transient.petsc import TransientSystem
        from railvib_hpc.transient.scheme import GeneralizedAlpha

        self.mesh, self.comm = mesh, comm
        self.dofmap = build_dofmap(mesh, comm.size, rules=rules, node_sets=node_sets)
        problem = Problem.from_case(case)
        self.K, self.M, _ = assemble(mesh, problem, self.dofmap, comm)
        self.C = None
        if case["damping.model"] != "none" or any(
                case[f"boundary.{f}"] in ("absorbing", "caughey")
                for f in ("x_min", "x_max", "y_min", "y_max", "base")):
            self.C, _ = assemble_damping(mesh, problem, self.dofmap, comm, self.K, self.M)
        self.scheme = GeneralizedAlpha.from_radius(dt, rho_inf)
        self.system = TransientSystem(self.K, self.M, self.C, self.scheme, comm)
        self.r0, self.r1 = self.system.r0, self.system.r1

    def state(self):
        from railvib_hpc.transient.integrate import State

        n = self.system.n_local
        return State(0, np.zeros(n), np.zeros(n), np.zeros(n))

    def solver(self, prescribed=None):
        from railvib_hpc.transient.integrate import DirectSolver

        return DirectSolver(self.system, prescribed)

    def dofs(self, nodes, comp: int) -> np.ndarray:
        return self.dofmap.index[np.asarray(nodes), comp]

    def values(self, local: np.ndarray, dofs: np.ndarray) -> np.ndarray:
        """Global values at ``dofs`` on every rank."""
        from railvib_hpc.transient.integrate import gather_values

        return gather_values(self.comm, local, self.r0, dofs)

    def energy(self, st) -> float:
        u, v = self.system.vector(st.u.copy()), self.system.vector(st.v.copy())
        e = self.system.energy(u, v)
        u.destroy()
        v.destroy()
        return e

    def dissipation_power(self, v_local: np.ndarray) -> float:
        """``v^T C v`` (collective)."""
        v = self.system.vector(np.ascontiguousarray(v_local))
        p = self.system.quadratic(self.C, v)
        v.destroy()
        return p

    def destroy(self) -> None:
        self.system.destroy()
        for A in (self.K, self.M, self.C):
            if A is not None:
                A.destroy()


def column_pulse(kind: str, h: float, courant: float, comm, height: float = 40.0,
                 duration: float = 0.04, depth: float = 15.0, t_end: float | None = None,
                 energy: bool = False, base: tuple[str, ...] = ("boundary.base=absorbing",),
                 shape=smooth_pulse) -> dict:
    """A force pulse on the top of a 1-D soil column with an absorbing base.

    Parameters
    ----------
    kind
        ``"P"`` (vertical load, only ``uz`` free) or ``"S"`` (horizontal load, only ``ux``).
    h
        Element size [m]; ``dt = courant h / c``.
    courant
        Courant number ``c dt / h``.
    comm
        Communicator.
    height, duration, depth
        Column height, pulse duration, receiver depth below the top [m, s, m].
    t_end
        End time (default: the pulse has passed the receiver).
    energy
        Record the energy every step.
    base
        Overrides of the base condition (default: Lysmer-Kuhlemeyer dashpots).
    shape
        The pulse ``shape(t, duration)``.

    Returns
    -------
    dict
        ``t``, ``v`` (receiver velocity), ``v_exact`` (the same pulse in a half-space),
        ``energy``, ``c``.
    """
    c = C_P if kind == "P" else C_S
    comp = 2 if kind == "P" else 0
    free = {"P": ("ux", "uy"), "S": ("uy", "uz")}[kind]
    nz = int(round(height / h))
    mesh = column_mesh(nz, height)
    case = soil_case(*base, "damping.model=none")
    dt = courant * h / c
    from railvib_hpc.model.boundary import constraint_rules, face_node_sets

    model = Model(mesh, case, {**constraint_rules(Problem.from_case(case)), "all": free}, comm, dt,
                  node_sets=face_node_sets(mesh))
    top = np.flatnonzero(np.isclose(mesh.points[:, 2], height))
    top_dofs = model.dofs(top, comp)
    rec_node = np.flatnonzero(np.isclose(mesh.points[:, 2], height - depth))[:1]
    rec_dof = model.dofs(rec_node, comp)
    amplitude = 1e3                                        # N on the 1 m^2 top
    t_end = t_end if t_end is not None else (depth + 0.5 * c * duration) / c + duration
    nt = int(math.ceil(t_end / dt))

    def load(n):
        return top_dofs, np.full(top.size, amplitude / top.size) * shape(n * dt, duration)

    solver = model.solver(load)
    st = model.state()
    v, e = [0.0], [0.0]
    for _ in range(nt):
        solver.step(st)
        v.append(float(model.values(st.v, rec_dof)[0]))
        if energy:
            e.append(model.energy(st))
    t = np.arange(nt + 1) * dt
    out = {"t": t, "v": np.array(v), "c": c, "dt": dt, "nt": nt,
           "v_exact": amplitude / (RHO * c) * shape(t - depth / c, duration),
           "energy": np.array(e), "rho_c_area": RHO * c}
    solver.destroy()
    model.destroy()
    return out
