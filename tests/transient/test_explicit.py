"""The explicit central-difference engine (issue 28): stability, waves, energy, ranks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI
from wave_cases import C_P, C_S, RHO, box_mesh, column_mesh, smooth_pulse, soil_case

from railvib_hpc.problem import Problem
from railvib_hpc.transient.explicit import (
    STEP_SAFETY,
    ExplicitEngineError,
    critical_step,
    spectral_radius,
)

comm = MPI.COMM_WORLD


class ExplicitModel:
    """Assembled model with a lumped mass and the explicit solver on ``comm``."""

    def __init__(self, mesh, case, rules, node_sets=None):
        from railvib_hpc.model.dofmap import build_dofmap
        from railvib_hpc.model.petsc import assemble, assemble_damping
        from railvib_hpc.petsc_env import init_petsc

        init_petsc([])
        self.mesh = mesh
        self.dofmap = build_dofmap(mesh, comm.size, rules=rules, node_sets=node_sets)
        problem = Problem.from_case(case)
        self.K, self.M, _ = assemble(mesh, problem, self.dofmap, comm)
        self.C = None
        if any(case[f"boundary.{f}"] == "absorbing"
               for f in ("x_min", "x_max", "y_min", "y_max", "base")) \
                or case["damping.model"] != "none":
            self.C, _ = assemble_damping(mesh, problem, self.dofmap, comm, self.K, self.M)
        self.r0, self.r1 = self.K.getOwnershipRange()

    def system(self, dt):
        from railvib_hpc.transient.explicit import ExplicitSystem

        return ExplicitSystem(self.K, self.M, self.C, dt, comm)

    def state(self):
        from railvib_hpc.transient.integrate import State

        n = self.r1 - self.r0
        return State(0, np.zeros(n), np.zeros(n), np.zeros(n))

    def dofs(self, nodes, comp):
        return self.dofmap.index[np.asarray(nodes), comp]

    def value(self, local, dof):
        from railvib_hpc.transient.integrate import gather_values

        return float(gather_values(comm, local, self.r0, np.atleast_1d(dof))[0])

    def destroy(self):
        for A in (self.K, self.M, self.C):
            if A is not None:
                A.destroy()


def _column(kind: str, h: float, courant: float, height: float = 40.0, depth: float = 15.0,
            duration: float = 0.04):
    """The column pulse of ``wave_cases.column_pulse`` with the explicit engine."""
    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.transient.explicit import ExplicitSolver, stability_limit

    c = C_P if kind == "P" else C_S
    comp = 2 if kind == "P" else 0
    free = {"P": ("ux", "uy"), "S": ("uy", "uz")}[kind]
    mesh = column_mesh(int(round(height / h)), height)
    case = soil_case("boundary.base=absorbing", "damping.model=none", "modal.lumped_mass=true")
    model = ExplicitModel(mesh, case, {**constraint_rules(Problem.from_case(case)), "all": free},
                          face_node_sets(mesh))
    probe = model.system(1.0)
    # the Courant number asked for, within the stability limit (the column's 1 m width
    # carries P waves across it even where only ux is free)
    dt = min(courant * h / c, stability_limit(model.K, probe.m, model.C, comm).dt_allowed)
    probe.destroy()
    system = model.system(dt)
    top = np.flatnonzero(np.isclose(mesh.points[:, 2], height))
    top_dofs = model.dofs(top, comp)
    rec = model.dofs(np.flatnonzero(np.isclose(mesh.points[:, 2], height - depth))[:1], comp)
    amplitude = 1e3
    t_end = (depth + 0.5 * c * duration) / c + duration
    nt = int(math.ceil(t_end / dt))

    def load(n):
        return top_dofs, np.full(top.size, amplitude / top.size) * smooth_pulse(n * dt, duration)

    solver = ExplicitSolver(system, load)
    st = model.state()
    v = [0.0]
    for _ in range(nt):
        solver.step(st)
        v.append(model.value(st.v, rec[0]))
    t = np.arange(nt + 1) * dt
    exact = amplitude / (RHO * c) * smooth_pulse(t - depth / c, duration)
    system.destroy()
    model.destroy()
    return np.array(v), exact


def _rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def test_critical_step_is_two_over_omega_and_damping_lowers_it():
    assert critical_step(500.0) == pytest.approx(2.0 / 500.0, rel=1e-12)
    assert spectral_radius(500.0, 0.0, 1.001 * 2.0 / 500.0) > 1.0
    steps = [critical_step(500.0, xi) for xi in (0.0, 0.05, 0.2, 1.0)]
    assert all(a > b for a, b in zip(steps, steps[1:]))
    for xi, h in zip((0.05, 0.2, 1.0), steps[1:]):
        assert spectral_radius(500.0, xi, 0.999 * h) <= 1.0 + 1e-12
        assert spectral_radius(500.0, xi, 1.01 * h) > 1.0


@pytest.mark.mpi
def test_stability_limit_is_the_largest_natural_frequency():
    """Against the dense eigenproblem of the same K and lumped mass (a 3 x 3 x 3 box)."""
    from scipy.linalg import eigh

    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble
    from railvib_hpc.transient.explicit import lumped_diagonal, stability_limit

    mesh = box_mesh((3, 3, 3), (3.0, 3.0, 3.0))
    case = soil_case("modal.lumped_mass=true", "damping.model=none")
    rules = {"bottom": ("ux", "uy", "uz")}
    model = ExplicitModel(mesh, case, rules)
    m = lumped_diagonal(model.M, comm)
    lim = stability_limit(model.K, m, None, comm)
    # the reference: the same model on this rank alone, dense
    K1, M1, _ = assemble(mesh, Problem.from_case(case), build_dofmap(mesh, 1, rules=rules),
                         MPI.COMM_SELF)
    lam = eigh(K1.convert("dense").getDenseArray(), M1.convert("dense").getDenseArray(),
               eigvals_only=True)
    K1.destroy()
    M1.destroy()
    assert lim.omega_max == pytest.approx(math.sqrt(lam.max()), rel=1e-6)
    assert lim.dt_critical == pytest.approx(2.0 / math.sqrt(lam.max()), rel=1e-6)
    assert lim.dt_allowed == pytest.approx(STEP_SAFETY * lim.dt_critical)
    model.destroy()


def test_a_consistent_mass_is_refused():
    from railvib_hpc.transient.explicit import lumped_diagonal

    mesh = box_mesh((2, 2, 2), (2.0, 2.0, 2.0))
    model = ExplicitModel(mesh, soil_case("damping.model=none"), {"bottom": ("ux", "uy", "uz")})
    with pytest.raises(ExplicitEngineError, match=r"modal\.lumped_mass = true"):
        lumped_diagonal(model.M, comm)
    model.destroy()


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["P", "S"])
def test_explicit_pulse_travels_at_the_wave_speed(kind):
    """The column pulse against the exact travelling pulse: second order in h and dt
    together (Courant 0.9 within the stability limit), within 0.5 % at 0.25 m (P) and
    0.125 m (S; the same 68 elements per wavelength of the 0.04 s pulse)."""
    hs = np.array([1.0, 0.5, 0.25]) / (1 if kind == "P" else 2)
    errors = [_rel(*_column(kind, h, 0.9)) for h in hs]
    rate = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert 1.7 < rate < 2.3, (errors, rate)
    assert errors[-1] < 0.005, errors


@pytest.mark.mpi
def test_undamped_closed_box_keeps_its_energy():
    """All faces fixed, no damping, 1000 steps at half the critical step: the scheme's
    discrete energy is conserved to round-off and the physical energy does not drift."""
    from railvib_hpc.transient.explicit import ExplicitSolver, stability_limit

    closed = {"bottom": ("ux", "uy", "uz"), "x_faces": ("ux", "uy", "uz"),
              "y_faces": ("ux", "uy", "uz")}
    from railvib_hpc.model.boundary import face_node_sets

    mesh = box_mesh((4, 4, 4), (4.0, 4.0, 4.0))
    model = ExplicitModel(mesh, soil_case("damping.model=none", "modal.lumped_mass=true"),
                          closed, face_node_sets(mesh))
    probe = model.system(1.0)
    dt = 0.5 * stability_limit(model.K, probe.m, None, comm).dt_critical
    probe.destroy()
    system = model.system(dt)
    st = model.state()
    nodes = np.flatnonzero(model.dofmap.index[:, 2] >= 0)
    dofs = model.dofmap.index[nodes, 2]
    x = mesh.points[nodes]
    own = (dofs >= model.r0) & (dofs < model.r1)
    st.v[dofs[own] - model.r0] = (np.sin(np.pi * x[own, 0] / 4) * np.sin(np.pi * x[own, 1] / 4)
                                  * np.sin(np.pi * x[own, 2] / 8))
    solver = ExplicitSolver(system)

    def shadow() -> float:
        """``1/2 v_{n+1/2}^T m v_{n+1/2} + 1/2 u_n^T K u_{n+1}``: what the scheme conserves."""
        vh = st.v + 0.5 * dt * st.a
        u1 = st.u + dt * vh
        return comm.allreduce(0.5 * float(vh @ (system.m * vh))
                              + 0.5 * float(st.u @ system.times(system.K, u1)))

    e0, h0 = system.energy(st.u, st.v), shadow()
    energies, shadows = [], []
    for _ in range(1000):
        solver.step(st)
        energies.append(system.energy(st.u, st.v))
        shadows.append(shadow())
    energies = np.array(energies)
    # the scheme's own energy to round-off; the physical one oscillates at O((omega dt)^2)
    # of the highest modes the start excites, without drift
    assert np.abs(np.array(shadows) / h0 - 1).max() < 1e-10
    assert np.abs(energies / e0 - 1).max() < 0.1
    assert abs(energies[-100:].mean() - energies[:100].mean()) < 2e-3 * e0
    system.destroy()
    model.destroy()


def _dense(A) -> np.ndarray:
    """``A`` (on ``MPI.COMM_SELF``) as a dense array."""
    return A.convert("dense").getDenseArray().copy()


def _central_difference_map(K: np.ndarray, C: np.ndarray, m: np.ndarray, h: float,
                            d: np.ndarray | None = None) -> np.ndarray:
    """The dense one-step map of ``(u, v, a)`` of the module's scheme, the damping C at the
    half-step velocity and the diagonal ``d`` at the full step (written out independently
    of the engine)."""
    n = m.size
    d = np.zeros(n) if d is None else d
    eye, zero = np.eye(n), np.zeros((n, n))
    u1 = np.hstack([eye, h * eye, 0.5 * h * h * eye])
    vh = np.hstack([zero, eye, 0.5 * h * eye])
    a1 = -(K @ u1 + C @ vh + d[:, None] * vh) / (m + 0.5 * h * d)[:, None]
    return np.vstack([u1, vh + 0.5 * h * a1, a1])


@pytest.mark.mpi
@pytest.mark.parametrize("damping", ["none", "rayleigh"])
def test_the_limit_with_absorbing_faces_is_that_of_the_whole_damped_map(damping):
    """A 4 x 4 x 3 box, all faces but the top absorbing (Lysmer-Kuhlemeyer dashpots, whose
    ratio c / m at a face node is far above that of the stiffest mode). The dense one-step
    map is stable at the allowed step and unstable 2 % above the critical one, on 1 and 2
    ranks; the largest mode's own damping ratio would allow a step on which the map grows.
    """
    from railvib_hpc.model.boundary import face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble, assemble_damping
    from railvib_hpc.transient.explicit import lumped_diagonal, stability_limit

    faces = [f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_min", "y_max", "base")]
    extra = (["damping.model=rayleigh", "modal.damping_ratio=0.05", "damping.f1=5",
              "damping.f2=80"] if damping == "rayleigh" else ["damping.model=none"])
    case = soil_case("modal.lumped_mass=true", *faces, *extra)
    mesh = box_mesh((4, 4, 3), (4.0, 4.0, 3.0))
    model = ExplicitModel(mesh, case, {}, face_node_sets(mesh))
    lim = stability_limit(model.K, lumped_diagonal(model.M, comm), model.C, comm)
    problem = Problem.from_case(case)
    dofmap = build_dofmap(mesh, 1, rules={}, node_sets=face_node_sets(mesh))
    K1, M1, _ = assemble(mesh, problem, dofmap, MPI.COMM_SELF)
    C1 = assemble_damping(mesh, problem, dofmap, MPI.COMM_SELF, K1, M1)[0]
    K, C, m = _dense(K1), _dense(C1), np.diag(_dense(M1)).copy()
    for A in (K1, M1, C1):
        A.destroy()

    def rho(h: float) -> float:
        return float(np.abs(np.linalg.eigvals(_central_difference_map(K, C, m, h))).max())

    print(f"{damping}: critical {lim.dt_critical:.4e} s, largest mode's own {lim.dt_mode:.4e} s"
          f" (xi {lim.xi:.3g}); rho at the allowed step {rho(lim.dt_allowed):.12f}, 2 % above"
          f" the critical {rho(1.02 * lim.dt_critical):.6f}, at the mode's allowed "
          f"{rho(STEP_SAFETY * lim.dt_mode):.6f}")
    assert lim.damping_limited
    assert rho(lim.dt_allowed) <= 1.0 + 1e-9
    assert rho(1.02 * lim.dt_critical) > 1.0 + 1e-6
    assert rho(STEP_SAFETY * lim.dt_mode) > 1.0 + 1e-6
    model.destroy()


@pytest.mark.mpi
def test_proportional_damping_keeps_the_largest_modes_limit():
    """Rayleigh damping alone (fixed faces): the largest mode is an eigenvector of the
    damping too, so the limit is :func:`critical_step` of that mode and its ratio, found in
    the first check."""
    from railvib_hpc.transient.explicit import lumped_diagonal, stability_limit

    case = soil_case("modal.lumped_mass=true", "damping.model=rayleigh",
                     "modal.damping_ratio=0.05", "damping.f1=5", "damping.f2=80")
    mesh = box_mesh((3, 3, 3), (3.0, 3.0, 3.0))
    model = ExplicitModel(mesh, case, {"bottom": ("ux", "uy", "uz")})
    lim = stability_limit(model.K, lumped_diagonal(model.M, comm), model.C, comm)
    assert lim.xi > 0.0
    assert not lim.damping_limited
    assert lim.dt_critical == pytest.approx(critical_step(lim.omega_max, lim.xi), rel=1e-5)
    model.destroy()


@pytest.mark.mpi
@pytest.mark.parametrize("damping", ["none", "rayleigh"])
def test_dashpots_at_the_full_step_do_not_limit_it(damping):
    """The same box, the dashpots taken apart as a diagonal at the full-step velocity (what
    the stage does, :func:`~railvib_hpc.model.boundary.dashpot_diagonal`): the limit is that
    of K and the Rayleigh damping alone, the dense map is stable at its allowed step and
    unstable 2 % above the critical one, and 200 engine steps of a pulse match the dense
    recursion to round-off on 1 and 2 ranks."""
    from railvib_hpc.model.boundary import dashpot_diagonal, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble, assemble_damping
    from railvib_hpc.transient.explicit import (
        ExplicitSolver,
        ExplicitSystem,
        lumped_diagonal,
        stability_limit,
    )
    from railvib_hpc.transient.integrate import State, gather_values

    faces = [f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_min", "y_max", "base")]
    extra = (["damping.model=rayleigh", "modal.damping_ratio=0.05", "damping.f1=5",
              "damping.f2=80"] if damping == "rayleigh" else ["damping.model=none"])
    case = soil_case("modal.lumped_mass=true", *faces, *extra)
    problem = Problem.from_case(case)
    mesh = box_mesh((4, 4, 3), (4.0, 4.0, 3.0))
    sets = face_node_sets(mesh)
    dofmap = build_dofmap(mesh, comm.size, rules={}, node_sets=sets)
    K, M, _ = assemble(mesh, problem, dofmap, comm, mass="diagonal")
    C = (assemble_damping(mesh, problem, dofmap, comm, K, M, dashpots=False)[0]
         if damping == "rayleigh" else None)
    d_local = dashpot_diagonal(mesh, problem, dofmap, comm.rank)
    assert d_local is not None and d_local.max() > 0
    lim = stability_limit(K, lumped_diagonal(M, comm), C, comm)
    # the dense reference, on this rank alone
    dofmap1 = build_dofmap(mesh, 1, rules={}, node_sets=sets)
    K1, M1, _ = assemble(mesh, problem, dofmap1, MPI.COMM_SELF)
    Kd, m = _dense(K1), np.diag(_dense(M1)).copy()
    if C is not None:
        C1 = assemble_damping(mesh, problem, dofmap1, MPI.COMM_SELF, K1, M1, dashpots=False)[0]
        Cd = _dense(C1)
        C1.destroy()
    else:
        Cd = np.zeros_like(Kd)
    d = dashpot_diagonal(mesh, problem, dofmap1, 0)
    for A in (K1, M1):
        A.destroy()

    def rho(h: float) -> float:
        return float(np.abs(np.linalg.eigvals(_central_difference_map(Kd, Cd, m, h, d))).max())

    print(f"{damping}: critical {lim.dt_critical:.4e} s (dashpots apart); rho at the allowed "
          f"{rho(lim.dt_allowed):.12f}, 2 % above the critical {rho(1.02 * lim.dt_critical):.6f}")
    assert not lim.damping_limited
    assert rho(lim.dt_allowed) <= 1.0 + 1e-9
    assert rho(1.02 * lim.dt_critical) > 1.0 + 1e-6
    # the engine against the dense recursion: a pulse on the top's middle node
    dt = lim.dt_allowed
    system = ExplicitSystem(K, M, C, dt, comm, dashpots=d_local)
    top = int(np.argmin(np.linalg.norm(mesh.points - [2.0, 2.0, 3.0], axis=1)))
    dof = int(dofmap.index[top, 2])

    def load(n):
        return np.array([dof]), np.array([-1e4 * float(smooth_pulse(n * dt, 20 * dt))])

    solver = ExplicitSolver(system, load)
    nl = system.n_local
    st = State(0, np.zeros(nl), np.zeros(nl), np.zeros(nl))
    T = _central_difference_map(Kd, Cd, m, dt, d)
    n = m.size
    dof1 = int(dofmap1.index[top, 2])
    x = np.zeros(3 * n)
    m_eff = m + 0.5 * dt * d
    for k in range(200):
        solver.step(st)
        a_f = np.zeros(n)
        a_f[dof1] = load(k + 1)[1][0] / m_eff[dof1]
        x = T @ x + np.concatenate([np.zeros(n), 0.5 * dt * a_f, a_f])
    # global DOF numbers differ between the two maps only in their order: compare by node
    nodes = np.flatnonzero(dofmap.index[:, 2] >= 0)
    got = gather_values(comm, st.u, system.r0, dofmap.index[nodes, 2])
    want = x[:n][dofmap1.index[nodes, 2]]
    assert np.abs(want).max() > 0
    assert np.abs(got - want).max() <= 1e-10 * np.abs(want).max()
    system.destroy()
    for A in (K, M, C):
        if A is not None:
            A.destroy()
